"""Exports of a solved hand motion to the files other tools read (issue 19): glTF binary with the skinned
mesh and objects (:mod:`~handcap.export.gltf`), BVH (:mod:`~handcap.export.bvh`),
joint angles as CSV, joints and virtual markers as C3D/TRC, and the MANO parameters as ``.npz``
(:mod:`~handcap.export.tables`). :func:`export_motion` picks the format from the file's name."""

from handcap.export.bvh import bvh_text, write_bvh
from handcap.export.formats import FORMATS, export_motion
from handcap.export.gltf import glb_bytes, write_glb
from handcap.export.tables import write_angles_csv, write_joint_markers, write_mano_npz

__all__ = ["FORMATS", "bvh_text", "export_motion", "glb_bytes", "write_angles_csv", "write_bvh", "write_glb",
           "write_joint_markers", "write_mano_npz"]
