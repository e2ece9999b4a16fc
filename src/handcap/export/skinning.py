"""What a skinned export (glTF, USD) needs of a hand motion: the rest mesh and joints of the take's shape, the
four strongest skinning weights per vertex, and every frame's joint rotations relative to their parents.

Both formats skin linearly (the model's linear blend skinning, without a model's pose correctives) and animate
the same numbers, so they come from one place.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from handcap.core.motion import HandMotion
from handcap.export.bvh import filled_frames
from handcap.hand.anatomy import PARENTS


@dataclass(frozen=True)
class SkinnedTake:
    """A hand motion ready for a skinned export.

    Attributes
    ----------
    times : ndarray (T,)
        Seconds.
    local_quats : ndarray (T, 16, 4)
        Each joint's rotation relative to its parent (the wrist's to the world), quaternions ``x y z w``, kept
        on one side from frame to frame (q and -q are one rotation) so that they interpolate well.
    wrist : ndarray (T, 3)
        The wrist's world position, metres.
    rest_vertices : ndarray (V, 3)
    rest_joints : ndarray (16, 3)
        The rest (flat) hand of the take's shape, metres.
    faces : ndarray (F, 3) int
    joint_index : ndarray (V, 4) int
    joint_weight : ndarray (V, 4)
        The four strongest skinning weights of each vertex, renormalised (a joint given no weight is joint 0).
    joints : ndarray (T, 21, 3)
        The model's joints of every frame (forward kinematics), metres: what a reader's skinning should match.
    warnings : list of str
        Frames without a pose took the nearest frame's.
    """

    times: np.ndarray
    local_quats: np.ndarray
    wrist: np.ndarray
    rest_vertices: np.ndarray
    rest_joints: np.ndarray
    faces: np.ndarray
    joint_index: np.ndarray
    joint_weight: np.ndarray
    joints: np.ndarray
    warnings: list


def skinned_take(motion: HandMotion, hand) -> SkinnedTake:
    """The numbers of :class:`SkinnedTake` for ``motion``.

    Parameters
    ----------
    motion : HandMotion
    hand : HandModel
        The model the motion was solved with (rest mesh, weights, joints).

    Raises
    ------
    HandcapError
        A motion without a frame with a pose.
    """
    global_orient, hand_pose, transl, warnings = filled_frames(motion)
    out = hand.forward(motion.betas, global_orient, hand_pose, transl, vertices=False)
    world = np.asarray(out.rotations)
    local = world.copy()
    local[:, 1:] = np.einsum("tnji,tnjk->tnik", world[:, PARENTS[1:]], world[:, 1:])
    quats = Rotation.from_matrix(local.reshape(-1, 3, 3)).as_quat().reshape(len(local), 16, 4)  # x y z w
    quats[1:] *= np.cumprod(np.where(np.sum(quats[1:] * quats[:-1], axis=-1) < 0, -1.0, 1.0), axis=0)[..., None]
    rest_vertices, rest_joints, _ = (np.asarray(a) for a in hand.rest(np.asarray(motion.betas, dtype=np.float64)))
    weights = np.asarray(hand.weights, dtype=np.float64)
    top = np.argsort(-weights, axis=1)[:, :4]
    strength = np.take_along_axis(weights, top, axis=1)
    strength /= strength.sum(axis=1, keepdims=True)
    top = np.where(strength > 0, top, 0)
    joints = np.asarray(out.joints)
    return SkinnedTake(np.arange(motion.n_frames, dtype=np.float64) / motion.rate, quats, joints[:, 0],
                       rest_vertices, rest_joints, np.asarray(hand.faces), top, strength, joints, warnings)
