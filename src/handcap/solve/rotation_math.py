"""Rotation and Jacobian helpers of the marker model: how the anatomical angles turn the hand's joints.

The hand's 27 anatomical angles ``phi`` are intrinsic z-y'-x'' Euler angles
(bend, spread, twist) in each joint's anatomical frame ``C``. This module
owns their batched maths, with no model state: the joint rotations they give
(:func:`local_rotations`), the world axis each angle turns about, which is
its column of the Jacobian (:func:`dof_axes`), which segments a joint's
rotation carries (:func:`descendants`), and the cross products these
columns are built from (:func:`cross`, :func:`cross0`).
:class:`~handcap.solve.markers.MarkerModel` is their user.
"""

from __future__ import annotations

import numpy as np

from handcap.hand.anatomy import PARENTS, PHI_AXIS, PHI_JOINT


def descendants() -> np.ndarray:
    """Which segments move with each joint of the hand's kinematic tree.

    Returns
    -------
    ndarray (16, 16)
        Entry [j, k] is 1 when segment k moves with joint j (k = j included), else 0; no unit.
    """
    out = np.eye(16)
    for k in range(1, 16):
        j = PARENTS[k]
        while j >= 0:
            out[j, k] = 1.0
            j = PARENTS[j]
    return out


#: :func:`descendants`, computed once: (16, 16), no unit.
DESCENDANTS = descendants()


def cross(a, b) -> np.ndarray:
    """``a x b`` over the last axis (3); a few times faster than ``np.cross`` on small batches.

    Parameters
    ----------
    a, b : ndarray (..., 3)
        Any unit; broadcast together.

    Returns
    -------
    ndarray (..., 3)
        In the product of the two units.
    """
    a0, a1, a2 = a[..., 0], a[..., 1], a[..., 2]
    b0, b1, b2 = b[..., 0], b[..., 1], b[..., 2]
    return np.stack([a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0], axis=-1)


def cross0(a, b) -> np.ndarray:
    """``a x b`` over the first axis (3, ...): for component-first arrays.

    Parameters
    ----------
    a, b : ndarray (3, ...)
        Any unit; broadcast together after the first axis.

    Returns
    -------
    ndarray (3, ...)
        In the product of the two units.
    """
    return np.stack([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]])


def local_rotations(phi, frames) -> np.ndarray:
    """Joint rotations ``C E(phi) C^T`` (T, 15, 3, 3) from anatomical angles (T, 27).

    Parameters
    ----------
    phi : ndarray (..., 27)
        Anatomical angles, radians.
    frames : ndarray (15, 3, 3)
        Joint frames ``C`` (:func:`handcap.hand.anatomy.joint_frames`).

    Returns
    -------
    ndarray (..., 15, 3, 3)
        Rotations of joints 1-15 relative to the flat hand (MANO ``hand_pose`` as matrices).
    """
    angles = np.zeros(phi.shape[:-1] + (15, 3))
    angles[..., PHI_JOINT - 1, PHI_AXIS] = phi
    ct, cs, cb = (np.cos(angles[..., i]) for i in range(3))
    st, ss, sb = (np.sin(angles[..., i]) for i in range(3))
    # Rz(bend) Ry(spread) Rx(twist) written out (handcap.core.rotations.matrix_from_euler_zyx).
    e = np.empty(phi.shape[:-1] + (15, 3, 3))
    e[..., 0, 0], e[..., 0, 1], e[..., 0, 2] = cb * cs, cb * ss * st - sb * ct, cb * ss * ct + sb * st
    e[..., 1, 0], e[..., 1, 1], e[..., 1, 2] = sb * cs, sb * ss * st + cb * ct, sb * ss * ct - cb * st
    e[..., 2, 0], e[..., 2, 1], e[..., 2, 2] = -ss, cs * st, cs * ct
    return frames @ e @ np.swapaxes(frames, -1, -2)


def dof_axes(phi, world_rot, frames, frame_sign) -> np.ndarray:
    """World axis (T, 27, 3) of every anatomical angle (intrinsic z-y'-x'' Euler axes).

    Turning angle d by a small ``da`` turns its joint's segment, in the
    world, by ``da`` about this axis.

    Parameters
    ----------
    phi : ndarray (T, 27)
        Anatomical angles, radians.
    world_rot : ndarray (T, 16, 3, 3)
        World rotations of the segments (:meth:`~handcap.solve.markers.MarkerModel.kinematics`).
    frames : ndarray (15, 3, 3)
        Joint frames ``C`` (:func:`handcap.hand.anatomy.joint_frames`).
    frame_sign : ndarray (15,)
        ``sign(det C)``: -1 for a mirrored frame (a left hand's), whose axes turn round.

    Returns
    -------
    ndarray (T, 27, 3)
        Unit vectors in the world.
    """
    angles = np.zeros(phi.shape[:-1] + (15, 3))
    angles[..., PHI_JOINT - 1, PHI_AXIS] = phi
    bend, spread = angles[..., 2], angles[..., 1]
    cb, sb, cs, ss = np.cos(bend), np.sin(bend), np.cos(spread), np.sin(spread)
    zero, one = np.zeros_like(bend), np.ones_like(bend)
    # Axes in the E frame: bend about z, spread about Rz(b) y, twist about Rz(b) Ry(s) x.
    local = np.stack([np.stack([cb * cs, sb * cs, -ss], -1),          # twist
                      np.stack([-sb, cb, zero], -1),                  # spread
                      np.stack([zero, zero, one], -1)], -2)           # bend
    # Into the parent's frame (mirrored frames turn the axis round), then the world.
    in_parent = np.einsum("jab,tjkb->tjka", frames, local) * frame_sign[None, :, None, None]
    parent_rot = world_rot[:, PARENTS[1:]]  # (T, 15, 3, 3)
    world = np.einsum("tjab,tjkb->tjka", parent_rot, in_parent)  # (T, 15, 3 dofs, 3)
    return world[:, PHI_JOINT - 1, PHI_AXIS]
