"""Hand keypoints as points carried rigidly by the hand model's segments, for the marker solver.

:class:`KeypointModel` gives the 21 keypoints (:data:`~handcap.markerless.keypoints.KEYPOINT_NAMES`)
the interface of :class:`handcap.solve.markers.MarkerModel`, so the batched
Levenberg-Marquardt solve of markers (:func:`handcap.solve.motion.solve_lm`:
rigid start, key frames, robust loss, anatomical priors and joint limits) fits
the hand to 3D keypoints unchanged. Each keypoint is its model joint (see
:mod:`~handcap.markerless.keypoints`) carried by the joint's parent segment: a
joint centre does not move when its own joint turns, so its position depends
only on the angles above it, and the wrist and the five finger bases ride on
the palm (the six rigid points of the paper's Umeyama step). A fingertip rides
on its distal segment.
"""

from __future__ import annotations

import numpy as np

from handcap.hand.anatomy import PARENTS, TIP_PARENTS
from handcap.markerless.keypoints import MODEL_JOINT
from handcap.solve.markers import MarkerModel
from handcap.solve.rotation_math import DESCENDANTS

#: Segment carrying each of the model's 21 joints: the wrist the palm, a joint its parent, a tip its distal segment.
CARRIER = np.r_[0, PARENTS[1:], TIP_PARENTS]


class KeypointModel(MarkerModel):
    """The 21 hand keypoints as rigid points of a hand model (a :class:`~handcap.solve.markers.MarkerModel`).

    Parameters
    ----------
    hand : HandModel
    betas : ndarray (10,), optional
        Shape values (zeros: the average hand).
    """

    def __init__(self, hand, betas=None):  # the marker model's own setup needs an attachment: not called
        self.hand = hand
        self.attachment = None
        self.betas = np.zeros(10) if betas is None else np.asarray(betas, dtype=np.float64).reshape(10)
        _, rest_joints, rest_tips = hand.rest(self.betas)
        self.rest_joints = np.asarray(rest_joints, dtype=np.float64)
        every = np.concatenate([self.rest_joints, np.asarray(rest_tips, dtype=np.float64)])
        self.rest_markers = every[MODEL_JOINT]  # (21, 3) in keypoint order
        self.carrier = CARRIER[MODEL_JOINT]
        self.marker_weights = np.eye(16)[self.carrier]
        self._weights_below = self.marker_weights @ DESCENDANTS.T
        self.frames = np.asarray(hand.frames)
        self.frame_sign = np.sign(np.linalg.det(self.frames))
        self.has_correctives = False

    def positions(self, transl, rot, phi, *, kin=None) -> np.ndarray:
        """Keypoint positions (T, 21, 3), metres.

        Parameters
        ----------
        transl : ndarray (T, 3)
            Translation, metres.
        rot : ndarray (T, 3, 3)
            Global orientation.
        phi : ndarray (T, 27)
            Anatomical angles, radians.
        kin : tuple, optional
            :meth:`kinematics` of the same pose.

        Returns
        -------
        ndarray (T, 21, 3)
            Metres, in keypoint order.
        """
        world_rot, world_pos, _ = kin if kin is not None else self.kinematics(transl, rot, phi)
        c = self.carrier
        local = self.rest_markers - self.rest_joints[c]
        return np.einsum("tmij,mj->tmi", world_rot[:, c], local) + world_pos[:, c]
