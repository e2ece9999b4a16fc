"""Step ``export``: a solved hand motion written for other tools (BVH, CSV of joint angles, C3D/TRC of joints,
MANO parameters)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from handcap.core.errors import HandcapError
from handcap.export import FORMATS, export_motion
from handcap.hand import hand_model_from_options
from handcap.io import check_not_input, read_hand_motion, read_mesh, read_object_motion
from handcap.steps.step import Step


def export(motion, to, *, units: str = "cm", hand_model: str | None = None, mano_dir=None, objects=(),
           meshes=()) -> Step:
    """Write ``motion`` in the format the suffix of ``to`` names (:data:`handcap.export.FORMATS`).

    Parameters
    ----------
    motion, to : str or Path
        Hand motion ``.npz`` (``handcap solve``); the file to write.
    units : {'cm', 'mm', 'm'}
        Length unit of a BVH file.
    hand_model, mano_dir : str or None
        The hand model (default: the motion's).
    objects, meshes : sequences of str or Path
        Object motion ``.npz`` files (``track-object``) and each one's mesh in its own frame, for a ``.glb`` or USD.

    Returns
    -------
    Step
    """
    objects, meshes = list(objects or ()), list(meshes or ())
    if len(objects) != len(meshes):
        raise HandcapError(f"give one --object-mesh per --object ({len(objects)} objects, {len(meshes)} meshes)")
    check_not_input(to, motion, *objects, *meshes)
    solved = read_hand_motion(motion)
    loaded = []
    for path, mesh_path in zip(objects, meshes):
        mesh = read_mesh(mesh_path)
        if len(getattr(mesh, "faces", ())) == 0:
            raise HandcapError(f"{mesh_path}: holds no mesh faces; give the object's surface mesh")
        loaded.append((read_object_motion(path), np.asarray(mesh.vertices), np.asarray(mesh.faces)))
    if solved.n_frames == 0:
        raise HandcapError(f"{motion}: holds no frames")
    hand = hand_model_from_options(hand_model, mano_dir, side=solved.side, recorded=solved.model, what=str(motion))
    warnings = export_motion(solved, hand, to, units=units, objects=loaded)
    kind = FORMATS[Path(to).suffix.lower()].split(":")[0]
    return Step((f"{to}: {solved.n_frames} frames at {solved.rate:g} Hz, {kind}",), tuple(warnings), (str(to),),
                None)
