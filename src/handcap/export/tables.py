"""Exports as tables: joint angles (CSV), joints and virtual markers (C3D/TRC), MANO parameters (``.npz``)."""

from __future__ import annotations

import csv
import io

import numpy as np

from handcap.core.errors import HandcapError
from handcap.core.files import atomic_output, save_npz
from handcap.core.markers import MarkerSequence
from handcap.core.motion import HandMotion
from handcap.hand.anatomy import JOINT_NAMES, PHI_NAMES, TIP_NAMES
from handcap.io import write_markers

def write_angles_csv(motion: HandMotion, path, *, phi=None) -> None:
    """Joint angles as CSV: ``frame, time_s`` and one column per anatomical angle in degrees (``<name>_deg``,
    :data:`handcap.hand.anatomy.PHI_NAMES`); empty cells where a frame has no pose.

    Parameters
    ----------
    motion : HandMotion
    path : str or Path
    phi : ndarray (T, 27), optional
        Radians; default the motion's ``phi`` (or its ``hand_pose`` converted by the caller).
    """
    phi = motion.phi if phi is None else phi
    if phi is None:
        raise HandcapError("the motion has no anatomical angles (phi): solve it with handcap solve")
    text = io.StringIO()
    writer = csv.writer(text, lineterminator="\n")
    writer.writerow(["frame", "time_s", *(f"{n}_deg" for n in PHI_NAMES)])
    degrees = np.rad2deg(phi)
    for t, row in enumerate(degrees):
        writer.writerow([t, f"{t / motion.rate:.6f}", *("" if not np.isfinite(v) else f"{v:.4f}" for v in row)])
    with atomic_output(path) as fh:
        fh.write(text.getvalue().encode())


def write_joint_markers(motion: HandMotion, path) -> None:
    """The 21 joints (``wrist``, ``index1`` ... ``pinky_tip``) and the motion's virtual markers (``fit:<name>``,
    where the model puts each marker) as marker trajectories, metres in, the file's unit out.

    Parameters
    ----------
    motion : HandMotion
        With ``joints`` (T, 21, 3).
    path : str or Path
        ``.c3d``, ``.trc`` or ``.npz``.
    """
    if motion.joints is None:
        raise HandcapError("the motion has no joints: solve it with handcap solve")
    names = list(JOINT_NAMES + TIP_NAMES)
    positions = [motion.joints]
    if motion.marker_fit is not None and len(motion.marker_names):
        names += [f"fit:{n}" for n in motion.marker_names]
        positions.append(motion.marker_fit)
    write_markers(MarkerSequence(np.concatenate(positions, axis=1), tuple(names), motion.rate), path)


def write_mano_npz(motion: HandMotion, path) -> list[str]:
    """MANO's parameters (``betas``, ``global_orient``, ``hand_pose``, ``transl``, radians and metres) with
    ``side``, ``rate`` and ``model``; returns the warnings (a motion of the OpenHand model has MANO's pose
    layout but its own shape space: its betas are not MANO's).

    Parameters
    ----------
    motion : HandMotion
    path : str or Path
    """
    warnings = []
    if motion.model != "mano":
        warnings.append(f"the motion was solved with the {motion.model} hand: hand_pose and global_orient follow "
                        f"MANO's layout, but its betas are {motion.model}'s, not MANO's shape values")
    save_npz(path, {"betas": motion.betas, "global_orient": motion.global_orient, "hand_pose": motion.hand_pose,
                    "transl": motion.transl, "side": np.array(motion.side), "rate": np.array(motion.rate),
                    "model": np.array(motion.model)})
    return warnings
