"""Solving one frame at a time for live streams: Levenberg-Marquardt warm-started from the frame before.

The batch solver (:func:`handcap.solve.solve_hand`) sees the whole take; a live stream sees one frame and
must answer before the next. :class:`FrameSolver` keeps the last pose, starts the next frame's fit from it and
runs a Gauss-Newton iteration (:data:`ITERATIONS`); it starts afresh (rigid start, many iterations) on the
first frame, and whenever a frame's median marker residual says the hand was lost. The iterations,
warm-started or fresh, run compiled (:mod:`handcap.solve.kernel`, numba) where they can: the same steps,
about 20 times faster on one frame than the batch code, which is the fallback.
"""

from __future__ import annotations

import numpy as np

from handcap.hand.anatomy import TIP_PARENTS
from handcap.hand.kinematics import attached_points
from handcap.solve.lm import Poses, Priors, held_angles, levenberg_marquardt
from handcap.solve.markers import MarkerModel
from handcap.solve.rigid_start import rigid_start
from handcap.solve.kernel import FrameKernel

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

    Attributes
    ----------
    compiled : bool
        Whether the compiled iterations are used.
    """

    def __init__(self, attachment, hand, *, iterations: int = ITERATIONS, compiled: bool = True):
        self.hand, self.names = hand, list(attachment.marker_names)
        self.model = MarkerModel(hand, attachment)
        self.priors = Priors()
        self.rest = self.priors.rest_phi()
        self.iterations = iterations
        self.pose = self.kin = None  # the last pose and its kinematics (the next frame's start)
        self.restarts = 0  # frames after which the next started afresh
        # the joints of the take's shape at rest, once (forward() would rebuild them every frame)
        _, rest_joints, rest_tips = hand.rest(np.asarray(self.model.betas, dtype=np.float64))
        self.rest_joints, self.rest_tips = np.asarray(rest_joints), np.asarray(rest_tips)
        self.kernel = FrameKernel(self.model, self.priors, self.rest_tips) if compiled else None
        self.compiled = bool(self.kernel is not None and self.kernel.available)
        if self.compiled:  # compiled (or loaded from numba's cache) now, not on the stream's first frame
            m = self.model.n_markers
            self.kernel.solve(np.zeros(3), np.eye(3), self.rest, np.zeros((m, 3)), np.ones(m, bool), scale=SCALE,
                              iterations=1)

    def solve(self, positions) -> tuple[np.ndarray, np.ndarray, float]:
        """One frame.

        Parameters
        ----------
        positions : ndarray (M, 3)
            The attachment's markers in its order, metres, NaN where not seen.

        Returns
        -------
        joints : ndarray (21, 3)
            Metres; NaN when no marker was seen.
        phi : ndarray (27,)
            Radians.
        rms : float
            RMS residual of the seen markers, metres (NaN when none).
        """
        target = np.asarray(positions, dtype=np.float64).reshape(1, len(self.names), 3)
        observed = np.isfinite(target).all(axis=2)
        if observed.sum() < 3:
            return np.full((21, 3), np.nan), np.full(27, np.nan), float("nan")
        target = np.nan_to_num(target)
        if self.pose is None:
            rot, trans, _ = rigid_start(self.model, target, observed, self.rest)
            init, iterations, kin = Poses(trans.copy(), rot.copy(), self.rest[None].copy()), FIRST_ITERATIONS, None
        else:  # from the frame before, whose kinematics the last solve returned
            init, iterations, kin = self.pose, self.iterations, self.kin
        if self.compiled:
            transl, rot, phi, joints, norms = self.kernel.solve(init.transl[0], init.rot[0], init.phi[0], target[0],
                                                                observed[0], scale=SCALE, iterations=iterations,
                                                                tries=TRIES * iterations)
            return self._finish(Poses(transl[None], rot[None], phi[None]), None, joints, norms[observed[0]])
        pose, _, parts = levenberg_marquardt(self.model, target, observed, init, self.priors, scale=SCALE,
                                             iterations=iterations, held=held_angles(self.model, observed),
                                             return_parts=True, start_kin=kin, tries=TRIES * iterations)
        kin, norms = parts[0], parts[2]  # of the final pose: no second forward pass
        world_rot, world_pos = kin[0], kin[1]  # the translation included
        tips = attached_points(world_rot, world_pos, self.rest_joints[None], self.rest_tips[None], TIP_PARENTS)
        joints = np.concatenate([world_pos, tips], axis=-2)[0]
        return self._finish(pose, kin, joints, norms[0][observed[0]])

    def _finish(self, pose, kin, joints, distance):
        """Keep the pose for the next frame unless the hand was lost; the frame's joints, angles and RMS."""
        rms = float(np.sqrt(np.mean(distance ** 2)))
        # Lost when most markers are off, not when a few are (a mislabelled or swapped marker is an outlier
        # that the robust loss already discounts): the next frame then starts afresh.
        lost = float(np.median(distance)) > LOST
        self.restarts += lost
        self.pose, self.kin = (None, None) if lost else (pose, kin)
        return np.asarray(joints), pose.phi[0].copy(), rms
