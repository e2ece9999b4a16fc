"""Solving one frame at a time for live streams: Levenberg-Marquardt warm-started from the frame before.

The batch solver (:func:`handcap.solve.solve_hand`) sees the whole take; a live stream sees one frame and
must answer before the next. :class:`FrameSolver` keeps the last pose, starts the next frame's fit from it and
runs a Gauss-Newton iteration (:data:`ITERATIONS`); it starts afresh (rigid start, many iterations) on the
first frame, and whenever a frame's median marker residual says the hand was lost. The iterations,
warm-started or fresh, run compiled (:mod:`handcap.solve.kernel`, numba) where they can: the same steps,
about 20 times faster on one frame than the batch code, which is the fallback.

Where the markers leave two poses about equally good (a sparse glove whose markers sit a few millimetres off the
calibrated hand), a frame solved on its own can jump to the other pose and back. The batch solver mends such
excursions from the frames on both sides (:mod:`handcap.solve.continuity`); a live frame has only those before it.
So each warm-started frame is solved with the angles pulled towards where the two frames before carry them (half
their last change, :func:`handcap.solve.continuity.predicted`), and once more from its markers alone, after the
result is sent (:meth:`FrameSolver.idle`): only the later frames' weight needs that. The pull's weight is the
stream's own: :data:`SMOOTHING` times the ratio of the median marker residual (RMS over the markers) to the median
distance of the markers-alone solve's angles from that prediction (RMS over the angles), over the last
:data:`WINDOW` frames, so that in a typical frame the pull weighs a fraction of what the markers do. A stream whose
markers sit millimetres off the calibrated hand is so pulled harder than one whose markers fit to a few tenths
(measured: 0.04-0.06 m/rad on the real glove, 0.006-0.008 on synthetic takes). The pull shares its target with the
priors' weak pull to a relaxed hand (weights added in quadrature), which keeps the directions no marker constrains
(a thumb seen by two markers turns about their line) from drifting along with the prediction.

Measured with ``benchmarks/smoothing.py`` (2026-12-01): on the real Qualisys glove (6,000 frames at 100 Hz, 13
markers, calibrated on its first 1,500) the joints' jerk spikes fell from 121 to 0 and the motion signal-to-noise
ratio rose from 3.2 to 13.2 dB (the batch solver: 6 spikes, 7.3 dB); the RMS marker residual rose from 1.67 to
1.79 mm, and a frame takes 0.23 ms instead of 0.09. On eleven synthetic takes with truth (glove-13 and joints-19,
grasps and random motion, 30-120 Hz; five chose :data:`SMOOTHING` and the damping, six only checked them) the
joints came closer to the truth in every one, median and p99 (medians 0.32-0.68 -> 0.29-0.62 mm; p99 4.65 -> 2.36
mm, 5.43 -> 2.74 mm, 22.6 -> 18.6 mm ...).

Two labels swapped (a labeller confusing two fingertips that pass close) bend the hand to reach them, and the robust
loss hides it in the frame's residual. The batch solver finds such stretches from the whole take
(:mod:`handcap.solve.swaps`); a live frame is judged on its own, with the batch verdict: where a marker lies over
``MRE_LIMIT`` from the warm-started hand, the frame is solved again with its label exchanged with another marker off
the hand or seen nearest to it, or moved round a cycle of three with two such markers (the likeliest
:data:`SWAP_TRIES`), and where the hand then fits them within the limit, :data:`~handcap.solve.swaps.CLOSER` times
closer, and the others as well, the labels are read exchanged from that frame on (:attr:`FrameSolver.order`) until
the same verdict exchanges them back; each change is kept (:attr:`FrameSolver.swaps`) and named in a warning at the
stream's end. Only frames solved from the frame before are judged (a fresh start has no hand to judge by), and an
exchange is dropped (:attr:`FrameSolver.dropped`) where the hand is lost or where its markers fit the hand neither
way. ``benchmarks/swaps.py`` section 3 (2026-12-02): on the thirteen synthetic takes the 8 swaps ``synth`` made were
found at their first frame and exchanged back at the frame after their last, none elsewhere, none on the real glove;
p99 joint error 4.80 -> 2.71 mm (joints-19 grasp, 30 Hz), 12.1 -> 7.3 mm (glove-13 grasp, 30 Hz), 4.10 -> 2.06 mm;
the frame's p99 time on the real glove 0.44 -> 0.85 ms; made-up cycles of three fingertips read round the cycle from
their first frame and back after their last in 7 of 12 takes (pairs alone: 0).
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass

import numpy as np

from handcap.core.errors import HandcapError
from handcap.quality.fit_checks import residual_warnings
from handcap.quality.limits import MM, MRE_LIMIT
from handcap.hand.anatomy import TIP_PARENTS
from handcap.hand.kinematics import attached_points
from handcap.solve.lm import Poses, Priors, held_angles, levenberg_marquardt
from handcap.solve.markers import MarkerModel
from handcap.solve.rigid_start import rigid_start
from handcap.solve.continuity import predicted
from handcap.solve.kernel import FrameKernel
from handcap.solve.swaps import MAX_FAR, exchange_candidates, exchange_columns, exchange_name, verdict

#: Gauss-Newton iterations per streamed frame (from the frame before). One suffices: the frame before is close,
#: and more fit the markers' noise. Measured on 20 s of synthetic random motion, 22 markers (joints vs truth,
#: median / p99): at 120 Hz 0.32 / 1.89 mm with one iteration, 0.32 / 2.21 mm with four; at 30 Hz 0.35 / 2.40 and
#: 0.32 / 2.37 mm; each iteration costs about 0.7 ms.
ITERATIONS = 1
#: Steps tried per iteration at most: a step that raised the cost is tried again, more damped, until one is taken.
#: With the rejected step counted as the frame's one iteration, the hand froze while its markers moved, then jumped:
#: on the real glove recording 245 of 6,000 frames (p99 marker RMS 6.8 mm); with 4 tries 27 (4.7 mm), and on
#: synthetic takes the joints as close to the truth or closer (p99 23.3 -> 19.3 mm on a 60 Hz glove-13 take).
TRIES = 4
#: Iterations of a fresh start.
FIRST_ITERATIONS = 60
#: Median marker residual (metres) above which the next frame starts afresh.
LOST = 0.01
#: Scale of the robust (Cauchy) marker loss, metres.
SCALE = 0.005
#: The pull towards the predicted angles, as a fraction of the markers' weight in a typical frame (0: none). Chosen
#: on synthetic takes (0.25, 0.5, 1: 0.5 gave the lowest p99 joint error in 3 of 5 and within 0.2 mm in the others).
SMOOTHING = 0.5
#: Frames over which the pull's weight takes its medians.
WINDOW = 256
#: Frames of both medians before the pull starts.
WARMUP = 10
#: Exchanges of labels (pairs, cycles of three) tried in one frame at most (the likeliest first; each costs a solve
#: of the frame).
SWAP_TRIES = 2


@dataclass(frozen=True)
class LiveSwap:
    """Two labels found exchanged from ``frame`` on, or three moved round a cycle (``c`` not -1: ``a`` read from
    ``b``'s label, ``b`` from ``c``'s, ``c`` from ``a``'s), the attachment's order (``back``: as given again): their
    markers lay ``given`` metres from the hand as labelled (their mean) and ``exchanged`` metres exchanged."""

    frame: int
    a: int
    b: int
    given: float
    exchanged: float
    back: bool = False
    c: int = -1


class FrameSolver:
    """Solve streamed frames of one hand's labelled markers.

    Parameters
    ----------
    attachment : MarkerAttachment
    hand : HandModel
        The attachment's model.
    iterations : int
        Per frame, warm-started.
    compiled : bool
        Run the iterations compiled where numba and the model allow (:class:`FrameKernel`);
        False: always the batch code.
    smoothing : float
        The pull towards the predicted angles (see the module docstring; default :data:`SMOOTHING`, 0: each
        frame from its markers alone).
    mend_swaps : bool
        Two labels the hand finds swapped are solved exchanged from that frame on (see the module docstring).

    Attributes
    ----------
    compiled : bool
        Whether the compiled iterations are used.
    order : ndarray (M,) int
        The column of the given markers each of the attachment's markers is read from (the labels exchanged so
        far; ``arange(M)`` while none is).
    swaps : list of LiveSwap
        Every change of ``order``, in the order found.
    dropped : list of int
        Frames after which exchanges were dropped (their labels read as given again): the hand was lost (a fresh
        start has no hand to judge them by), or an exchanged marker lay off the hand and exchanging it back did not
        fit either (the labeller's labels changed otherwise). A swap still there is found again.
    """

    def __init__(self, attachment, hand, *, iterations: int = ITERATIONS, compiled: bool = True,
                 smoothing: float = SMOOTHING, mend_swaps: bool = True):
        if not (np.isfinite(smoothing) and smoothing >= 0):
            raise HandcapError(f"smoothing must be 0 or more, got {smoothing}")
        self.hand, self.names = hand, list(attachment.marker_names)
        self.model = MarkerModel(hand, attachment)
        self.priors = Priors()
        self.rest = self.priors.rest_phi()
        self.iterations = iterations
        self.pose = self.kin = None  # the last pose and its kinematics (the next frame's start)
        self.restarts = 0  # frames after which the next started afresh
        self.smoothing = float(smoothing)
        self.recent: list = []  # the angles of the last two frames solved in a row (the prediction's)
        self.residuals, self.surprises = deque(maxlen=WINDOW), deque(maxlen=WINDOW)  # metres, radians
        self.pending = None  # the work :meth:`idle` does
        self.weight = None  # the pull's, metres per radian (None until WARMUP frames were measured)
        self.mend_swaps, self.frames = mend_swaps, 0
        self.error_sum, self.errors = 0.0, 0  # every solved frame's marker distances, summed (metres) and counted
        self.order, self.swaps, self.dropped = np.arange(len(self.names)), [], []
        # the joints of the take's shape at rest, once (forward() would rebuild them every frame)
        _, rest_joints, rest_tips = hand.rest(np.asarray(self.model.betas, dtype=np.float64))
        self.rest_joints, self.rest_tips = np.asarray(rest_joints), np.asarray(rest_tips)
        self.kernel = FrameKernel(self.model, self.priors, self.rest_tips) if compiled else None
        self.compiled = bool(self.kernel is not None and self.kernel.available)
        if self.compiled:  # compiled (or loaded from numba's cache) now, not on the stream's first frame
            m = self.model.n_markers
            self.kernel.solve(np.zeros(3), np.eye(3), self.rest, np.zeros((m, 3)), np.ones(m, bool), scale=SCALE,
                              iterations=1)

    def solve(self, positions, measured=None) -> tuple[np.ndarray, np.ndarray, float]:
        """One frame.

        Parameters
        ----------
        positions : ndarray (M, 3)
            The attachment's markers in its order, metres, NaN where not seen.
        measured : ndarray (M,) bool, optional
            Which of ``positions`` were measured (the others predicted, by the occlusion filler): only measured
            markers are exchanged as swapped labels. Default: every marker given.

        Returns
        -------
        joints : ndarray (21, 3)
            Metres; NaN when no marker was seen.
        phi : ndarray (27,)
            Radians.
        rms : float
            RMS residual of the seen markers, metres (NaN when none).
        """
        self.idle()
        self.frames += 1
        if self.pose is None and (self.order != np.arange(len(self.order))).any():
            # the hand was lost: the exchanges judged by it are stale; the labels are read as given again
            self.order = np.arange(len(self.order))
            self.dropped.append(self.frames - 1)
        target = np.asarray(positions, dtype=np.float64).reshape(len(self.names), 3)[self.order][None]
        observed = np.isfinite(target).all(axis=2)
        if observed.sum() < 3:
            self.recent = []
            return np.full((21, 3), np.nan), np.full(27, np.nan), float("nan")
        target = np.nan_to_num(target)
        if self.pose is None:
            rot, trans, _ = rigid_start(self.model, target, observed, self.rest)
            init, iterations, kin = Poses(trans.copy(), rot.copy(), self.rest[None].copy()), FIRST_ITERATIONS, None
            self.recent = []
        else:  # from the frame before, whose kinematics the last solve returned
            init, iterations, kin = self.pose, self.iterations, self.kin
        prediction = predicted(*self.recent) if self.smoothing > 0 and len(self.recent) == 2 else None
        pull = (prediction, self.weight) if prediction is not None and self.weight is not None else ()
        result = self._iterate(init, kin, target, observed, iterations, *pull)
        if self.mend_swaps and self.pose is not None:
            measured = observed[0] if measured is None else observed[0] & np.asarray(measured, bool)[self.order]
            result, target = self._swapped(result, init, kin, target, observed, measured, iterations, pull)
        if pull:
            self.pending = (init, kin, target, observed, iterations, prediction)  # the solve from the markers alone
        elif prediction is not None:
            self._measure(result, prediction)
        out = self._finish(*result)
        self.recent = [] if self.pose is None else [*self.recent[-1:], out[1]]
        return out

    def _swapped(self, result, init, kin, target, observed, measured, iterations, pull):
        """The frame's result and markers, with labels exchanged where the hand then fits them within
        ``MRE_LIMIT``, :data:`~handcap.solve.swaps.CLOSER` times closer than as given, and the other markers about
        as well (:mod:`handcap.solve.swaps`' verdict, on one frame). The exchanges tried
        (:func:`~handcap.solve.swaps.exchange_candidates`): a marker off the hand with each other marker off it, or
        seen nearest to it, and cycles of three with two markers off it, whose positions lie near where the hand
        puts the others' (the likeliest first, :data:`SWAP_TRIES` at most)."""
        seen = observed[0]
        residual = np.zeros(len(seen))
        residual[seen] = result[3]
        far = measured & (residual > MRE_LIMIT)  # a marker the filler predicted is no evidence of a swap
        if not far.any() or far.sum() > MAX_FAR or np.median(result[3]) > MRE_LIMIT / 2:
            return result, target
        pose = result[0]
        fit = self.model.positions(pose.transl, pose.rot, pose.phi)[0]
        candidates = {candidate for a in np.flatnonzero(far)
                      for candidate in exchange_candidates(target[0], fit, residual, far, measured, a)}
        for _, _, a, b, c in sorted(candidates)[:SWAP_TRIES]:
            markers, sources = exchange_columns(a, b, c)
            swapped = target.copy()
            swapped[0, markers] = target[0, sources]
            trial = self._iterate(init, kin, swapped, observed, iterations, *pull)
            distance = np.zeros(len(seen))
            distance[seen] = trial[3]
            moved = np.zeros(len(seen), dtype=bool)
            moved[markers] = True
            ok, given, fit_exchanged = verdict(distance[None], observed, residual[None], observed, moved)
            if ok:
                self.order[markers] = self.order[sources]
                self.swaps.append(LiveSwap(self.frames - 1, a, b, given, fit_exchanged,
                                           bool((self.order[markers] == markers).all()), c))
                return trial, swapped
        stale = far & (self.order != np.arange(len(self.order)))
        if stale.any():  # an exchange that no longer fits, nor does exchanging it back: labels as given from now on
            for m in np.flatnonzero(stale):
                while self.order[m] != m:  # the cycle of exchanges m is in, undone
                    k = self.order[m]
                    self.order[m], self.order[k] = self.order[k], k
            self.dropped.append(self.frames - 1)
        return result, target

    def fit_warnings(self) -> list[str]:
        """The solve's mean marker error over every frame solved so far, one line where it is above
        :data:`~handcap.quality.limits.MRE_LIMIT` (as ``handcap solve`` warns: wrong labels, another subject's
        attachment, another unit), none otherwise.

        Returns
        -------
        list of str
        """
        mre = self.error_sum / self.errors if self.errors else 0.0
        return residual_warnings(np.array([[mre]]), what="live solve MRE") if self.errors else []

    def swap_warnings(self, rate: float) -> list[str]:
        """One line for the labels exchanged so far (at most five changes named), none when none was.

        Parameters
        ----------
        rate : float
            Frames per second of the stream.

        Returns
        -------
        list of str
        """
        if not self.swaps:
            return []
        told = "; ".join(f"{self.named(s)} {'back ' if s.back else ''}at frame {s.frame} "
                         f"({s.frame / rate:.2f} s: "
                         f"{MM * s.given:.1f} mm from the hand as labelled, {MM * s.exchanged:.1f} mm exchanged)"
                         for s in self.swaps[:5])
        more = f"; and {len(self.swaps) - 5} more" if len(self.swaps) > 5 else ""
        dropped = "" if not self.dropped else (f"; read as given again where they no longer fitted the hand, "
                                                f"after frame(s) "
                                                f"{', '.join(str(t) for t in self.dropped[:5])}"
                                                f"{' ...' if len(self.dropped) > 5 else ''}")
        held = [f"{self.names[m]} from {self.names[c]}" for m, c in enumerate(self.order) if m != c]
        now = f"; at the end {', '.join(held)}'s label" if held else "; none exchanged at the end"
        return [f"live solve: labels exchanged {len(self.swaps)} time(s) where the hand fitted them swapped: "
                f"{told}{more}{dropped}{now}"]

    def named(self, swap: LiveSwap) -> str:
        """The labels of an exchange: 'a and b', or 'a, b and c round a cycle'.

        Parameters
        ----------
        swap : LiveSwap
            One of :attr:`swaps`.
        """
        return exchange_name(self.names, swap.a, swap.b, swap.c)

    def idle(self) -> None:
        """The last frame's solve from its markers alone, which only the pull's weight in later frames needs: call
        it once the frame's result is sent, so that its cost falls between frames. Without it, the next
        :meth:`solve` does it first (same results)."""
        if self.pending is not None:
            init, kin, target, observed, iterations, prediction = self.pending
            self.pending = None
            self._measure(self._iterate(init, kin, target, observed, iterations), prediction)

    def _measure(self, alone, prediction) -> None:
        """Keep a frame's RMS marker residual and its angles' RMS distance from ``prediction``, solved from its
        markers ``alone`` (the result of :meth:`_iterate`), and the pull's weight from their medians."""
        self.residuals.append(np.sqrt(np.mean(alone[3] ** 2)))
        self.surprises.append(np.sqrt(np.mean((alone[0].phi[0] - prediction) ** 2)))
        if len(self.surprises) >= WARMUP:
            self.weight = self.smoothing * np.median(self.residuals) / max(float(np.median(self.surprises)), 1e-6)

    def _iterate(self, init, kin, target, observed, iterations, prediction=None, weight=0.0):
        """Iterations from ``init`` (with its kinematics ``kin``, or None); with ``prediction`` (27,) radians, the
        angles pulled towards it at ``weight`` metres per radian besides the priors' pull to a relaxed hand.
        Returns the pose, its kinematics (None when compiled), joints (21, 3) and the seen markers' residuals."""
        priors = self.priors if prediction is None else self.priors.pulled(prediction, weight)
        if self.compiled:
            pulled = {} if prediction is None else {"rest": priors.rest, "rest_weight": priors.rest_weight}
            transl, rot, phi, joints, norms = self.kernel.solve(init.transl[0], init.rot[0], init.phi[0], target[0],
                                                                observed[0], scale=SCALE, iterations=iterations,
                                                                tries=TRIES * iterations, **pulled)
            return Poses(transl[None], rot[None], phi[None]), None, joints, norms[observed[0]]
        pose, _, parts = levenberg_marquardt(self.model, target, observed, init, priors, scale=SCALE,
                                             iterations=iterations, held=held_angles(self.model, observed),
                                             return_parts=True, start_kin=kin, tries=TRIES * iterations)
        kin, norms = parts[0], parts[2]  # of the final pose: no second forward pass
        world_rot, world_pos = kin[0], kin[1]  # the translation included
        tips = attached_points(world_rot, world_pos, self.rest_joints[None], self.rest_tips[None], TIP_PARENTS)
        joints = np.concatenate([world_pos, tips], axis=-2)[0]
        return pose, kin, joints, norms[0][observed[0]]

    def _finish(self, pose, kin, joints, distance):
        """Keep the pose for the next frame unless the hand was lost; the frame's joints, angles and RMS."""
        rms = float(np.sqrt(np.mean(distance ** 2)))
        self.error_sum, self.errors = self.error_sum + float(distance.sum()), self.errors + len(distance)
        # Lost when most markers are off, not when a few are (a mislabelled or swapped marker is an outlier
        # that the robust loss already discounts): the next frame then starts afresh.
        lost = float(np.median(distance)) > LOST
        self.restarts += lost
        self.pose, self.kin = (None, None) if lost else (pose, kin)
        return np.asarray(joints), pose.phi[0].copy(), rms
