"""Hand motion from labeled markers: ``solve_hand``.

Per frame, the pose that brings the attached markers onto the observed ones
(Eq. 2-4 of DexterCap, with a robust loss and the anatomical priors of
:class:`handcap.solve.lm.Priors`), warm-started from the previous frames:

1. A rigid start for every frame: Kabsch alignment of the markers on the palm
   (all markers when fewer than three palm markers are seen).
2. Key frames 0.1 s apart, solved one after the other, each starting from the
   finger pose of the one before.
3. The frames between, solved together by batched Levenberg-Marquardt, each
   starting from the key frames' angles joined linearly.
4. Frames that end far worse than the rest (a poor local minimum) are solved
   again from the previous frame's pose; short excursions into another pose
   and back (jerk spikes) likewise, keeping the more likely pose
   (:mod:`handcap.solve.continuity`).
5. An angle that no visible marker depends on (its segment and every segment
   beyond it unseen) keeps its value from the previous frame, as in the paper,
   once markers have constrained it; an angle no marker has constrained yet
   (a fingertip marker missing from the start, or from the whole take) is set
   by the anatomical priors instead: DIP follows PIP, PIP follows MCP, and a
   weak pull to the relaxed hand. A frame with no marker at all keeps the
   whole previous pose.
6. Two labels swapped for a stretch of frames, or three gone round a cycle
   (markers off the fitted hand there, and the hand fitting them exchanged),
   are solved exchanged, with a warning that names them
   (:mod:`handcap.solve.swaps`; ``mend_swaps``).

Methods: ``lm`` (the above, default) and ``adam`` (the paper's optimiser,
:mod:`handcap.solve.adam`), kept as the baseline.

A motion whose MRE exceeds :data:`MRE_WARNING` carries a warning (issue 14:
never a silent wrong result), as does one whose shape values sit at their
bounds, besides the attachment's own warnings (checks of
:mod:`handcap.quality.plausibility`).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
from tqdm import tqdm

from handcap.core.errors import HandcapError
from handcap.core.markers import MarkerSequence
from handcap.core.motion import HandMotion
from handcap.core.rotations import axis_angle_from_matrix
from handcap.hand import OpenHand
from handcap.quality.filters import lowpass, smooth_rotations
from handcap.quality.plausibility import MRE_LIMIT, attach, lost_frame_warnings, residual_warnings, shape_warnings
from handcap.solve.continuity import mend_excursions
from handcap.solve.kernel import FrameKernel
from handcap.solve.lm import Poses, Priors, frame_costs, held_angles, levenberg_marquardt, unconstrained_angles
from handcap.solve.markers import MarkerModel
from handcap.solve.rigid_start import rigid_start
from handcap.solve.swaps import CONTEXT, exchanged, find_swaps, swap_warnings

METHODS = ("lm", "adam")
#: A fit whose mean marker error exceeds this (metres) is implausible for a calibrated attachment: warned.
MRE_WARNING = MRE_LIMIT


def observed_markers(markers: MarkerSequence, names) -> tuple[np.ndarray, list[str]]:
    """Positions (T, M, 3) of the named markers in ``markers`` (NaN columns for absent names).

    Parameters
    ----------
    markers : MarkerSequence
        Metres; names matched as :meth:`MarkerSequence.index` does (``Subject:`` prefixes allowed).
    names : sequence of str (M,)
        The markers wanted, in output order.

    Returns
    -------
    positions : ndarray (T, M, 3)
        Metres, NaN where missing or absent.
    absent : list of str
        The names found nowhere in the file (or matching several prefixed markers).
    """
    out = np.full((markers.n_frames, len(names), 3), np.nan)
    absent = []
    for i, name in enumerate(names):
        try:
            out[:, i] = markers.positions[:, markers.index(name)]
        except HandcapError:
            absent.append(name)
    return out, absent


def solve_hand(markers: MarkerSequence, attachment, hand=None, *, method: str = "lm", priors: Priors | None = None,
               robust_scale: float = 0.005, iterations: int = 8, first_iterations: int = 60,
               filter_cutoff: float | None = None, filter_order: int = 2, mend_swaps: bool = True,
               progress: bool | None = None) -> HandMotion:
    """Solve hand motion from labeled markers.

    Parameters
    ----------
    markers : MarkerSequence
        Labeled markers, metres; names are matched to the attachment's
        (a ``Subject:`` prefix is ignored). Markers of the attachment absent
        from the file are treated as never seen; other markers are ignored.
    attachment : MarkerAttachment
    hand : HandModel, optional
        The attachment's model (OpenHand of its side by default).
    method : {"lm", "adam"}
    priors : Priors, optional
    robust_scale : float
        Scale of the Cauchy loss on marker residuals, metres (lm).
    iterations, first_iterations : int
        Levenberg-Marquardt iterations per frame (twice as many for key
        frames), and for the first frame.
    filter_cutoff : float, optional
        Low-pass the solved translation, orientation and angles at this
        frequency (Hz, zero-phase Butterworth, :mod:`handcap.quality.filters`);
        joints, ``marker_fit`` and residuals then describe the smoothed motion.
    filter_order : int
        Order of that filter.
    mend_swaps : bool
        Two labels the hand finds swapped in some frames (or three gone round a cycle) are solved exchanged there,
        with a warning (:mod:`.swaps`).
    progress : bool, optional
        Progress bar (default: on a terminal only).

    Returns
    -------
    HandMotion
        ``phi``, ``hand_pose``, ``global_orient``, ``transl``, ``joints`` (T, 21, 3),
        ``marker_fit`` (T, M, 3) for every attached marker (also those missing
        in the input) and ``marker_residuals`` (T, M) metres (NaN where missing).
        ``warnings``: the attachment's, and those of an MRE above
        :data:`MRE_WARNING` or shape values at their bounds (these also issued
        as :class:`handcap.HandcapWarning`).

    Raises
    ------
    HandcapError
        Unknown method, no marker of the attachment in ``markers``, or an
        attachment made for another mesh (triangle numbers beyond its faces).
    """
    if method not in METHODS:
        raise HandcapError(f"unknown solve method {method!r}; choose one of {', '.join(METHODS)}")
    hand = _hand_for(attachment) if hand is None else hand
    if len(attachment) and (attachment.triangles.min() < 0 or attachment.triangles.max() >= len(hand.faces)):
        raise HandcapError(f"the attachment's triangle numbers run to {attachment.triangles.max()}, but the "
                           f"{hand.name} mesh has {len(hand.faces)} faces: calibrate the attachment for this model")
    priors = Priors() if priors is None else priors
    names = list(attachment.marker_names)
    target, absent = observed_markers(markers, names)
    if len(absent) == len(names):
        raise HandcapError(f"none of the attachment's markers ({', '.join(names[:6])}...) is in the input; "
                           f"the input has {', '.join(markers.names[:6])}...")
    observed = ~np.isnan(target[..., 0])
    if not observed.any():
        raise HandcapError("the input has no visible marker of the attachment in any frame")
    model = MarkerModel(hand, attachment)

    def run(target, observed, progress=progress):  # the poses (frames before any marker seen: the first seen)
        if method == "adam":
            from handcap.solve.adam import solve_adam  # imports torch: only for the baseline solver
            poses = solve_adam(model, target, observed, priors, progress=progress)
        else:
            poses = solve_lm(model, target, observed, priors, robust_scale, markers.rate, iterations,
                             first_iterations, progress, neighbours=True)
        first = int(np.argmax(observed.any(axis=1)))
        poses.transl[:first], poses.rot[:first], poses.phi[:first] = (poses.transl[first], poses.rot[first],
                                                                       poses.phi[first])
        return poses

    def fit(poses):  # (T, M, 3) metres
        return model.positions(poses.transl, poses.rot, poses.phi)

    poses = run(target, observed)
    swaps, untried = find_swaps(target, observed, fit(poses), lambda t, o: fit(run(t, o, False))) if mend_swaps \
        else ([], 0)
    if swaps:  # each stretch solved again with its labels exchanged, with the frames beside it, and put in its place
        target, observed = exchanged(target, observed, swaps)
        for swap in swaps:
            lo, hi = max(0, swap.first - CONTEXT), min(len(target), swap.last + 1 + CONTEXT)
            part = run(target[lo:hi], observed[lo:hi], False)
            for mine, theirs in ((poses.transl, part.transl), (poses.rot, part.rot), (poses.phi, part.phi)):
                mine[swap.first:swap.last + 1] = theirs[swap.first - lo:swap.last + 1 - lo]
    if filter_cutoff is not None:
        poses = smoothed_poses(poses, markers.rate, filter_cutoff, filter_order)
    motion = motion_from_poses(hand, model, poses, target, observed, markers.rate, names)
    found = swap_warnings(swaps, names, markers.rate, untried) + \
        residual_warnings(motion.marker_residuals, names=names, what="solve MRE", limit=MRE_WARNING) + \
        shape_warnings(motion.betas) + lost_frame_warnings(observed.sum(axis=1))
    return attach(motion.with_warnings(*attachment.warnings), found)


def smoothed_poses(poses: Poses, rate, cutoff, order) -> Poses:
    """Poses low-passed: translation and angles by a zero-phase Butterworth filter, orientation without flips.

    Parameters
    ----------
    poses : Poses
        ``transl`` (T, 3) metres, ``rot`` (T, 3, 3), ``phi`` (T, 27) radians.
    rate : float
        Frames per second.
    cutoff : float
        Hz.
    order : int
        Butterworth order.

    Returns
    -------
    Poses
    """
    from scipy.spatial.transform import Rotation

    orient = smooth_rotations(axis_angle_from_matrix(poses.rot), rate, cutoff, order)
    return Poses(lowpass(poses.transl, rate, cutoff, order), Rotation.from_rotvec(orient).as_matrix(),
                 lowpass(poses.phi, rate, cutoff, order))


def _hand_for(attachment):
    if attachment.model != "openhand":
        raise HandcapError(f"the attachment was made for the {attachment.model} model: pass hand=ManoHand.load(...)")
    return OpenHand(attachment.side)


def solve_lm(model, target, observed, priors, scale, rate, iterations, first_iterations, progress, *,
             neighbours: bool = False) -> Poses:
    """Levenberg-Marquardt over a take: key frames first (0.1 s apart), then every frame from its neighbours.

    Parameters
    ----------
    model : MarkerModel
    target : ndarray (T, M, 3)
        Observed marker positions, metres (anything where not ``observed``).
    observed : ndarray (T, M) bool
    priors : Priors
    scale : float
        Robust (Cauchy) scale of the marker residuals, metres.
    rate : float
        Frames per second.
    iterations, first_iterations : int
        Gauss-Newton iterations per frame, and for the first key frame.
    progress : bool or None
        Progress bar (None: only on a terminal).
    neighbours : bool
        Step 6: every frame solved again pulled towards its neighbours (:func:`_pull_to_neighbours`); the
        motion's solve (:func:`solve_hand`) asks for it, the calibration's rounds do not.

    Returns
    -------
    Poses
        Translation (T, 3) metres, rotation (T, 3, 3) and the 27 angles (T, 27) radians.
    """
    n = len(target)
    rest = priors.rest_phi()
    rot0, trans0, rigid_ok = rigid_start(model, target, observed, rest)
    held = held_angles(model, observed)
    solved = Poses(trans0.copy(), rot0.copy(), np.tile(rest, (n, 1)))
    hidden = None if progress is None else not progress
    bar = tqdm(total=n, desc="solve", unit="frame", disable=hidden, leave=False)
    # 1. Key frames, 0.1 s apart, one after the other, each starting from the one before.
    stride = max(1, int(round(KEY_SECONDS * rate)))
    keys = np.unique(np.r_[np.arange(0, n, stride), n - 1])
    previous = None
    kernel = FrameKernel(model, priors)
    for k in keys:
        init = solved.take(slice(k, k + 1)).copy()
        if previous is not None:
            init.phi[:] = previous.phi
            if not rigid_ok[k]:
                init.rot[:], init.transl[:] = previous.rot, previous.transl
        result = _solve_frames(kernel, model, target, observed, init, priors, scale, held, np.array([k]),
                               first_iterations if previous is None else 2 * iterations)
        solved.put(slice(k, k + 1), result)
        previous = result
        bar.update(1)
    # 2. The frames between, all at once, starting from the key frames' angles joined linearly.
    between = np.setdiff1d(np.arange(n), keys)
    if len(between):
        solved.phi[between] = _interpolate(keys, solved.phi[keys], between)
        lost = between[~rigid_ok[between]]
        nearest = keys[np.clip(np.searchsorted(keys, lost) - 1, 0, len(keys) - 1)]
        solved.rot[lost], solved.transl[lost] = solved.rot[nearest], solved.transl[nearest]
        for chunk in np.array_split(between, max(1, int(np.ceil(len(between) / CHUNK)))):
            solved.put(chunk, _solve_frames(kernel, model, target, observed, solved.take(chunk), priors, scale, held,
                                            chunk, iterations))
            bar.update(len(chunk))
    bar.close()
    # 3. Frames ending far worse than the rest start again from the frame before.
    cost = _costs(model, solved, target, observed, held, priors, scale)
    _retry_outliers(kernel, model, target, observed, solved, cost, priors, scale, iterations, held)
    # 4. Angles nothing constrains keep the previous frame's value (the paper's rule).
    _forward_fill(solved.phi, held, rest)
    # 5. Short excursions into another pose, and back, are solved again from the frames around them.
    def pulled(t, init, phi, weight):
        if not (kernel.available and observed[t].any()):
            return levenberg_marquardt(model, target[t:t + 1], observed[t:t + 1], init,
                                       priors if phi is None else replace(priors, rest=phi, rest_weight=weight),
                                       scale=scale, iterations=2 * iterations, held=held[t:t + 1])[0]
        transl, rot, angles, _, _ = kernel.solve(init.transl[0], init.rot[0], init.phi[0], target[t], observed[t],
                                                 scale=scale, iterations=2 * iterations, held=held[t], rest=phi,
                                                 rest_weight=None if phi is None else weight)
        return Poses(transl[None], rot[None], angles[None])

    if mend_excursions(solved, lambda p: _skeleton_and_markers(model, p),
                       lambda f, p: _costs(model, p, target[f], observed[f], held[f], priors, scale), pulled, rate):
        _forward_fill(solved.phi, held, rest)
    # 6. Every frame again, its angles pulled towards the mean of the frames either side.
    if neighbours:
        _pull_to_neighbours(kernel, model, target, observed, held, priors, scale, iterations, solved)
        _forward_fill(solved.phi, held, rest)  # held angles follow their frame before as it now is
    return solved


#: Step 6 of :func:`solve_lm`: passes over the take, and the pull's strength (see :func:`_pull_to_neighbours`).
NEIGHBOUR_PASSES = 2
NEIGHBOUR_PULL = 0.5


def _pull_to_neighbours(kernel, model, target, observed, held, priors, scale, iterations, solved: Poses) -> None:
    """Solve every frame with 3 markers or more again (in place), from its pose, with its angles pulled towards
    the mean of the frames either side, :data:`NEIGHBOUR_PASSES` times.

    Each frame was fitted to its own markers; where they leave an angle loose (a sparse glove, a marker sitting
    millimetres off its calibrated spot) its noise is the hand's jitter. The pull's weight is the take's own:
    :data:`NEIGHBOUR_PULL` times the ratio of the typical marker residual (the root of the median frame cost per
    seen marker) to the median RMS distance of the angles from their neighbours' mean, so that in a typical frame
    the pull weighs half what the markers do. It shares its target with the weak pull to a relaxed hand (weights
    added in quadrature), as the live solver's pull towards its prediction does (``handcap.stream.solver``).
    Measured with ``benchmarks/smoothing.py`` (2026-12-01): on 13 synthetic takes the joints came closer to
    the truth in every one (median 0.13-1.15 -> 0.11-0.97 mm, p99 lower in each), the fitted markers a little
    further from the measured ones (less of their noise followed); on the real glove 6 -> 0 jerk spikes, MSNR 7.3
    -> 9.5 dB, mean marker residual 1.340 -> 1.346 mm.
    """
    frames = np.flatnonzero(observed[1:-1].sum(axis=1) >= 3) + 1
    if not len(frames):
        return
    markers = max(float(observed.sum(axis=1).mean()), 1.0)
    for _ in range(NEIGHBOUR_PASSES):
        middle = (solved.phi[frames - 1] + solved.phi[frames + 1]) / 2
        bend = np.sqrt(np.mean((solved.phi[frames] - middle) ** 2, axis=1))
        cost = _costs(model, solved, target, observed, held, priors, scale)
        weight = NEIGHBOUR_PULL * np.sqrt(np.median(cost) / markers) / max(float(np.median(bend)), 1e-6)
        pulled = priors.pulled(middle, weight)
        for part in np.array_split(np.arange(len(frames)), max(1, int(np.ceil(len(frames) / CHUNK)))):
            chunk = frames[part]
            solved.put(chunk, _solve_frames(kernel, model, target, observed, solved.take(chunk), priors, scale, held,
                                            chunk, iterations, pull=(pulled.rest[part], pulled.rest_weight)))


def _skeleton_and_markers(model, poses: Poses) -> np.ndarray:
    """The 16 joints and the attached markers of ``poses``, (T, 16 + M, 3) metres: where a hand can jump while
    its markers hardly move (another pose that fits them as well), and where it is seen."""
    return np.concatenate([model.kinematics(poses.transl, poses.rot, poses.phi)[1],
                           model.positions(poses.transl, poses.rot, poses.phi)], axis=1)


KEY_SECONDS = 0.1  # spacing of the key frames solved one after the other
CHUNK = 32  # frames per batched solve: small enough that the work arrays stay in cache


def _solve_frames(kernel: FrameKernel, model, target, observed, init: Poses, priors, scale, held, frames,
                  iterations, pull=None) -> Poses:
    """Levenberg-Marquardt on ``frames`` (F,) of the take from ``init`` (F frames), each frame on its own.

    Compiled one frame at a time where the kernel is available (numba, a model without pose correctives): the
    same iterations as :func:`~handcap.solve.lm.levenberg_marquardt`, in double precision, without its numpy
    overhead (whole solves on the 2-core VM: joints-19 600 frames 1.05 -> 0.20 s, dense-patches 300 frames
    0.71 -> 0.40-0.58 s, glove-13 400 frames 0.89 -> 0.18 s; the angles moved by at most 0.0006 deg). Frames
    without a single observed marker, and every frame without the kernel, go to the batch code, which keeps a
    blind frame at its start. ``pull``: each frame's target of the weak pull (F, 27) radians and its weight,
    metres per radian, instead of the priors'.
    """
    out = init.copy()
    frames = np.asarray(frames)
    compiled = observed[frames].any(axis=1) & kernel.available
    for i in np.flatnonzero(compiled):
        t = frames[i]
        own = {} if pull is None else {"rest": pull[0][i], "rest_weight": pull[1]}
        transl, rot, phi, _, _ = kernel.solve(init.transl[i], init.rot[i], init.phi[i], target[t], observed[t],
                                              scale=scale, iterations=iterations, held=held[t], **own)
        out.transl[i], out.rot[i], out.phi[i] = transl, rot, phi
    rest = np.flatnonzero(~compiled)
    if len(rest) and pull is not None:  # each frame its own target of the pull
        for i in rest:
            t = frames[i:i + 1]
            result, _ = levenberg_marquardt(model, target[t], observed[t], init.take(slice(i, i + 1)),
                                            replace(priors, rest=pull[0][i], rest_weight=pull[1]), scale=scale,
                                            iterations=iterations, held=held[t])
            out.put(slice(i, i + 1), result)
    elif len(rest):
        result, _ = levenberg_marquardt(model, target[frames[rest]], observed[frames[rest]], init.take(rest), priors,
                                        scale=scale, iterations=iterations, held=held[frames[rest]])
        out.put(rest, result)
    return out


def _interpolate(keys, values, at):
    """Values (len(at), 27) joined linearly between key frames."""
    return np.stack([np.interp(at, keys, values[:, d]) for d in range(values.shape[1])], axis=1)


def _costs(model, poses, target, observed, held, priors, scale):
    free = unconstrained_angles(model, observed) & ~held
    return frame_costs(model, poses, target, observed, held, priors, scale, free)[0]


def _forward_fill(phi, held, rest) -> None:
    """Held angles take the value of the frame before (the relaxed pose before any)."""
    for t in range(len(phi)):
        prev = phi[t - 1] if t > 0 else rest
        phi[t, held[t]] = prev[held[t]]


def _retry_outliers(kernel, model, target, observed, poses: Poses, cost, priors, scale, iterations,
                    held) -> None:
    """Solve again, from the previous frame's pose, frames that ended far worse than the rest (in place), one after
    the other (a retried frame is the next one's start); compiled where the kernel is available (a take whose
    labels are wrong in many frames: 0.5 s of a 1 s solve in the batch code)."""
    per_marker = cost / np.maximum(observed.sum(axis=1), 1)
    bad = np.flatnonzero(per_marker > max(9.0 * np.median(per_marker), 0.5 * 0.003**2))
    for t in bad[bad > 0]:
        init = poses.take(slice(t, t + 1)).copy()
        init.phi[:] = poses.phi[t - 1]
        retry = _solve_frames(kernel, model, target, observed, init, priors, scale, held, np.array([t]),
                              3 * iterations)
        if _costs(model, retry, target[t:t + 1], observed[t:t + 1], held[t:t + 1], priors, scale)[0] < cost[t]:
            poses.put(slice(t, t + 1), retry)


def motion_from_poses(hand, model, poses: Poses, target, observed, rate, names) -> HandMotion:
    """The hand motion of solved poses, with the model's markers and their residuals.

    Parameters
    ----------
    hand : HandModel
    model : MarkerModel
        Or any model with its interface (``betas``, ``positions``).
    poses : Poses
    target : ndarray (T, M, 3)
        Observed markers, metres (anything where not ``observed``).
    observed : ndarray (T, M) bool
    rate : float
        Frames per second.
    names : sequence of str (M,)

    Returns
    -------
    HandMotion
        ``marker_fit`` (T, M, 3) and ``marker_residuals`` (T, M) metres, NaN where not observed.
    """
    orient = axis_angle_from_matrix(poses.rot)
    hand_pose = hand.hand_pose_from_phi(poses.phi)
    joints = hand.forward(model.betas, orient, hand_pose, poses.transl, vertices=False).joints
    fit = model.positions(poses.transl, poses.rot, poses.phi)
    residuals = np.where(observed, np.linalg.norm(fit - np.nan_to_num(target), axis=-1), np.nan)
    return HandMotion(model.betas, orient, hand_pose, poses.transl, rate, hand.side, poses.phi, hand.name,
                      joints, tuple(names), fit, residuals)
