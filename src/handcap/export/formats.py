"""One entry for every export: :func:`export_motion` picks the format from the output file's name
(:data:`FORMATS`)."""

from __future__ import annotations

from pathlib import Path

from handcap.core.errors import HandcapError
from handcap.core.motion import HandMotion
from handcap.export.bvh import write_bvh
from handcap.export.gltf import write_glb
from handcap.export.tables import write_angles_csv, write_joint_markers, write_mano_npz
from handcap.export.usd import USD_SUFFIXES, write_usd

#: What each output suffix gets.
FORMATS = {".glb": "glTF binary: the skinned hand mesh with its animation (and objects as animated nodes)",
           ".bvh": "BVH: the joint tree at rest and every joint's rotation per frame",
           ".csv": "joint angles per frame (the 27 anatomical angles in degrees, and time in seconds)",
           ".c3d": "the 21 joints and the virtual markers as marker trajectories",
           ".trc": "the 21 joints and the virtual markers as marker trajectories",
           ".npz": "MANO parameters: betas (10,), global_orient (T, 3), hand_pose (T, 45), transl (T, 3)",
           **{suffix: "USD (the extra 'usd'): the skinned hand (UsdSkel) with its animation, and objects as animated "
                      "transforms" for suffix in USD_SUFFIXES}}


def export_motion(motion: HandMotion, hand, path, *, units: str = "cm", objects=()) -> list[str]:
    """Write ``motion`` in the format its file name asks for (:data:`FORMATS`); returns the warnings.

    Parameters
    ----------
    motion : HandMotion
    hand : HandModel
        The model it was solved with (BVH needs its rest joints).
    path : str or Path
    units : {'cm', 'mm', 'm'}
        Length unit of a BVH file.
    objects : sequence of (ObjectMotion, vertices (V, 3), faces (F, 3))
        Objects to animate in a ``.glb`` or USD (their meshes in their own frames, metres).

    Raises
    ------
    HandcapError
        A suffix without a format.
    """
    suffix = Path(path).suffix.lower()
    if suffix not in FORMATS:
        raise HandcapError(f"{path}: export to {', '.join(FORMATS)} (the suffix chooses the format)")
    if suffix == ".glb":
        return write_glb(motion, hand, path, objects)
    if suffix in USD_SUFFIXES:
        return write_usd(motion, hand, path, objects)
    if objects:
        raise HandcapError(f"{path}: objects go into a .glb or USD export only")
    if suffix == ".bvh":
        return write_bvh(motion, hand, path, units=units)
    if suffix == ".csv":
        write_angles_csv(motion, path, phi=motion.phi if motion.phi is not None else
                         hand.phi_from_hand_pose(motion.hand_pose))
        return []
    if suffix == ".npz":
        return write_mano_npz(motion, path)
    write_joint_markers(motion, path)
    return []
