"""Forward kinematics and linear blend skinning, for numpy arrays and torch tensors.

Stateless functions on arrays (the model objects in :mod:`handcap.hand.model`
hold the data and call these). Written once against the array-API namespace,
so the torch path is differentiable and gives the numpy results.

Shapes: ``...`` is any batch (usually T frames); J = 16 joints; V vertices.
"""

from __future__ import annotations

import numpy as np
from array_api_compat import array_namespace

from handcap.core.rotations import matrix_from_axis_angle
from handcap.hand.anatomy import PARENTS

# Joints grouped by depth in the tree (one finger each), so each level is one batched product.
_LEVELS = (np.array([1, 4, 7, 10, 13]), np.array([2, 5, 8, 11, 14]), np.array([3, 6, 9, 12, 15]))


def _take(xp, a, index, axis):
    return xp.take(a, xp.asarray(index, device=getattr(a, "device", None)), axis=axis)


def pose_rotations(global_orient, hand_pose):
    """Joint rotation matrices (..., 16, 3, 3) from axis-angle parameters.

    Parameters
    ----------
    global_orient : array (..., 3)
    hand_pose : array (..., 45)
    """
    xp = array_namespace(global_orient, hand_pose)
    aa = xp.concat([global_orient[..., None, :],
                    xp.reshape(hand_pose, hand_pose.shape[:-1] + (15, 3))], axis=-2)
    return matrix_from_axis_angle(aa)


def chain_transforms(rotations, rest_joints):
    """World rotation and position of every joint (forward kinematics).

    Parameters
    ----------
    rotations : array (..., 16, 3, 3)
        Local rotations (joint 0: global orientation), MANO convention: each
        rotates its subtree about the joint's rest position.
    rest_joints : array (..., 16, 3)
        Rest-pose joint positions.

    Returns
    -------
    world_rot : array (..., 16, 3, 3)
    world_pos : array (..., 16, 3)
        Posed joint positions (the root stays at its rest position).
    """
    xp = array_namespace(rotations, rest_joints)
    batch = rotations.shape[:-3]
    rest_joints = xp.broadcast_to(rest_joints, batch + rest_joints.shape[-2:])
    offsets = rest_joints - _take(xp, rest_joints, np.maximum(PARENTS, 0), -2)
    # The parents of each level are the previous level, finger by finger.
    root_rot, root_pos = rotations[..., :1, :, :], rest_joints[..., :1, :]
    parent_rot = xp.broadcast_to(root_rot, batch + (5, 3, 3))
    parent_pos = xp.broadcast_to(root_pos, batch + (5, 3))
    rots, poss = [root_rot], [root_pos]
    for level in _LEVELS:
        off = _take(xp, offsets, level, -2)
        pos = parent_pos + xp.sum(parent_rot * off[..., None, :], axis=-1)
        rot = xp.matmul(parent_rot, _take(xp, rotations, level, -3))
        rots.append(rot)
        poss.append(pos)
        parent_rot, parent_pos = rot, pos
    order = np.argsort(np.concatenate([[0], *_LEVELS]))
    world_rot = _take(xp, xp.concat(rots, axis=-3), order, -3)
    world_pos = _take(xp, xp.concat(poss, axis=-2), order, -2)
    return world_rot, world_pos


def attached_points(world_rot, world_pos, rest_joints, points, joint_of_point):
    """Posed positions of points rigidly attached to joints (e.g. fingertips).

    Parameters
    ----------
    world_rot, world_pos : arrays (..., 16, 3, 3), (..., 16, 3)
    rest_joints : array (..., 16, 3)
    points : array (..., P, 3)
        Rest positions.
    joint_of_point : sequence of int (P,)
    """
    xp = array_namespace(world_rot, points)
    rot = _take(xp, world_rot, joint_of_point, -3)
    pos = _take(xp, world_pos, joint_of_point, -2)
    rest = _take(xp, rest_joints, joint_of_point, -2)
    return pos + xp.sum(rot * (points - rest)[..., None, :], axis=-1)


def skinning_transforms(world_rot, world_pos, rest_joints):
    """Per-joint affine maps from the rest pose to the posed mesh, (..., 16, 3, 4).

    Parameters
    ----------
    world_rot : array (..., 16, 3, 3)
        World rotations of the joints (:func:`chain_transforms`).
    world_pos : array (..., 16, 3)
        Posed joint positions, metres.
    rest_joints : array (..., 16, 3)
        Rest-pose joint positions, metres.

    Returns
    -------
    transforms : array (..., 16, 3, 4)
        ``[R | p - R r]`` per joint: a rest-pose point ``x`` goes to ``R x + p - R r``;
        translation column in metres. Of the inputs' array type.
    """
    xp = array_namespace(world_rot, world_pos)
    trans = world_pos - xp.sum(world_rot * rest_joints[..., None, :], axis=-1)
    return xp.concat([world_rot, trans[..., None]], axis=-1)


def linear_blend_skinning(rest_vertices, weights, transforms):
    """Skin rest vertices with per-joint affine maps.

    Parameters
    ----------
    rest_vertices : array (V, 3) or (..., V, 3)
    weights : array (V, J)
        Rows sum to one.
    transforms : array (..., J, 3, 4)

    Returns
    -------
    vertices : array (..., V, 3)
    """
    xp = array_namespace(rest_vertices, transforms)
    batch = transforms.shape[:-3]
    flat = xp.reshape(transforms, batch + (transforms.shape[-3], 12))
    blended = xp.reshape(xp.matmul(weights, flat), batch + (weights.shape[0], 3, 4))
    return xp.sum(blended[..., :3] * rest_vertices[..., None, :], axis=-1) + blended[..., 3]
