"""BVH export of a hand motion: the hand's joint tree at its rest pose, and every joint's rotation per frame.

The hierarchy is the hand model's (:data:`handcap.hand.anatomy.PARENTS`): the wrist is the root (position and
rotation channels), each finger joint a child with three rotation channels, and each fingertip an ``End
Site``. Offsets are the rest joints of the motion's shape (``betas``), so a reader that composes the file's
rotations down the tree gets the model's joint positions back. Rotation channels are ``Zrotation Xrotation
Yrotation`` in degrees (the rotation is ``Rz Rx Ry`` applied to the parent's frame), lengths in
centimetres by default (the unit Blender and MotionBuilder take for BVH).
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from handcap.core.errors import HandcapError
from handcap.core.files import atomic_output
from handcap.core.motion import HandMotion
from handcap.hand.anatomy import JOINT_NAMES, PARENTS, TIP_PARENTS

#: Length units a BVH file may be written in, and their size in metres.
UNITS = {"m": 1.0, "cm": 0.01, "mm": 0.001}


def nearest_found(found) -> np.ndarray:
    """For every frame, the index of the nearest frame that is ``found`` (T,) bool (the earlier one on a tie).

    Parameters
    ----------
    found : ndarray (T,) bool
        At least one True.
    """
    index = np.flatnonzero(found)
    after = np.clip(np.searchsorted(index, np.arange(len(found))), 0, len(index) - 1)
    before = np.clip(after - 1, 0, len(index) - 1)
    frames = np.arange(len(found))
    return np.where(np.abs(index[before] - frames) <= np.abs(index[after] - frames), index[before], index[after])


def filled_frames(motion: HandMotion):
    """The motion's ``global_orient`` (T, 3), ``hand_pose`` (T, 45) and ``transl`` (T, 3) with every frame
    without a pose (NaN) given the nearest frame's, and the warning that says so (a list, empty if none).

    Raises
    ------
    HandcapError
        A motion without a single frame with a pose.
    """
    params = np.concatenate([motion.global_orient, motion.hand_pose, motion.transl], axis=1)
    found = np.isfinite(params).all(axis=1)
    if not found.any():
        raise HandcapError("the motion has no frame with a pose: nothing to export")
    warnings = []
    if not found.all():
        warnings.append(f"{int((~found).sum())} of {motion.n_frames} frames have no pose; the export holds the "
                        f"nearest frame's pose there")
    near = nearest_found(found)
    return motion.global_orient[near], motion.hand_pose[near], motion.transl[near], warnings


def bvh_text(motion: HandMotion, hand, *, units: str = "cm") -> tuple[str, list[str]]:
    """The BVH file of ``motion`` as text, and the warnings it raised.

    Parameters
    ----------
    motion : HandMotion
    hand : HandModel
        The model the motion was solved with (its rest joints give the offsets).
    units : {'cm', 'mm', 'm'}
        Length unit of the offsets and the root's position.

    Returns
    -------
    text : str
    warnings : list of str
        Frames without a pose (NaN), written as the nearest frame with one.

    Raises
    ------
    HandcapError
        An unknown unit, or a motion without a single frame with a pose.
    """
    if units not in UNITS:
        raise HandcapError(f"BVH units {units!r}: choose cm, mm or m")
    scale = 1.0 / UNITS[units]
    global_orient, hand_pose, transl, warnings = filled_frames(motion)
    out = hand.forward(motion.betas, global_orient, hand_pose, transl, vertices=False)
    rotations = np.asarray(out.rotations)  # (T, 16, 3, 3) world
    local = rotations.copy()
    local[:, 1:] = np.einsum("tnji,tnjk->tnik", rotations[:, PARENTS[1:]], rotations[:, 1:])
    euler = Rotation.from_matrix(local.reshape(-1, 3, 3)).as_euler("ZXY", degrees=True).reshape(len(local), 16, 3)
    euler = np.unwrap(euler, period=360.0, axis=0)
    rest = hand.rest_joints(motion.betas) * scale
    lines = ["HIERARCHY"]

    def joint(j, depth):
        pad = "  " * depth
        offset = rest[j] - rest[PARENTS[j]] if j else np.zeros(3)
        head = "ROOT" if j == 0 else "JOINT"
        channels = ("CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation" if j == 0 else
                    "CHANNELS 3 Zrotation Xrotation Yrotation")
        lines.extend([f"{pad}{head} {JOINT_NAMES[j]}", f"{pad}{{", f"{pad}  OFFSET {_xyz(offset)}",
                      f"{pad}  {channels}"])
        for child in np.flatnonzero(PARENTS == j):
            joint(int(child), depth + 1)
        for tip in np.flatnonzero(TIP_PARENTS == j):
            lines.extend([f"{pad}  End Site", f"{pad}  {{", f"{pad}    OFFSET {_xyz(rest[16 + tip] - rest[j])}",
                          f"{pad}  }}"])
        lines.append(f"{pad}}}")

    joint(0, 0)
    order = _depth_first()
    root = np.asarray(out.joints)[:, 0] * scale
    frames = np.concatenate([root, euler[:, order].reshape(len(euler), -1)], axis=1)
    lines += ["MOTION", f"Frames: {len(frames)}", f"Frame Time: {1.0 / motion.rate:.8f}"]
    lines += [" ".join(f"{v:.6f}" for v in row) for row in frames]
    return "\n".join(lines) + "\n", warnings


def _depth_first() -> list[int]:
    order = []

    def visit(j):
        order.append(j)
        for child in np.flatnonzero(PARENTS == j):
            visit(int(child))

    visit(0)
    return order


def _xyz(v) -> str:
    return " ".join(f"{float(x):.6f}" for x in v)


def write_bvh(motion: HandMotion, hand, path, *, units: str = "cm") -> list[str]:
    """Write ``motion`` as a BVH file (atomically); returns the warnings (see :func:`bvh_text`).

    Parameters
    ----------
    motion : HandMotion
    hand : HandModel
    path : str or Path
    units : {'cm', 'mm', 'm'}
    """
    text, warnings = bvh_text(motion, hand, units=units)
    with atomic_output(path) as fh:
        fh.write(text.encode())
    return warnings
