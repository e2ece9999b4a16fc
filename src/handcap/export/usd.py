"""USD export (``.usda``, ``.usdc``, ``.usd``): the skinned hand (UsdSkel) with its animation, objects as
animated transforms; the optional extra 'usd' (Pixar's ``usd-core``).

The stage is in metres (``metersPerUnit`` 1) with z up, as the capture had it, and one time code per frame
(``timeCodesPerSecond`` the take's rate). ``/Take`` is a SkelRoot holding:

- ``Skeleton``: the hand model's 16 joints (paths ``wrist``, ``wrist/index1`` ...), bound at the rest (flat)
  hand of the take's shape (``bindTransforms``: each joint's rest position), with ``Animation`` as its
  animation source: per frame, every joint's rotation relative to its parent (the wrist's to the world), the
  wrist's world position and the other joints' rest offsets;
- ``Hand``: the rest mesh, skinned to the skeleton with the model's four strongest weights per vertex (the
  same numbers as the ``.glb``, :mod:`handcap.export.skinning`), so a reader's linear blend skinning gives
  the model's mesh (a model with pose correctives, MANO, loses them);
- ``Objects/<name>``: each object's mesh under a transform with ``translate`` and ``orient`` samples.
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from handcap.core.errors import HandcapError
from handcap.core.motion import HandMotion
from handcap.export.bvh import nearest_found
from handcap.export.skinning import skinned_take
from handcap.hand.anatomy import JOINT_NAMES, PARENTS

#: Suffixes a USD stage is written as.
USD_SUFFIXES = (".usda", ".usdc", ".usd")


def _pxr():
    try:
        from pxr import Gf, Sdf, Usd, UsdGeom, UsdSkel, Vt  # noqa: PLC0415 (optional extra 'usd')
    except ImportError:
        raise HandcapError("USD export needs Pixar's USD: pip install 'handcap[usd]'") from None
    return Gf, Sdf, Usd, UsdGeom, UsdSkel, Vt


def joint_paths() -> list[str]:
    """The 16 joints as UsdSkel joint paths (``wrist``, ``wrist/thumb1``, ``wrist/thumb1/thumb2`` ...)."""
    paths = []
    for j, name in enumerate(JOINT_NAMES):
        paths.append(name if j == 0 else f"{paths[PARENTS[j]]}/{name}")
    return paths


def write_usd(motion: HandMotion, hand, path, objects=()) -> list[str]:
    """Write the USD stage of ``motion`` (and objects) to ``path`` atomically; returns the warnings.

    Parameters
    ----------
    motion : HandMotion
    hand : HandModel
        The model the motion was solved with.
    path : str or Path
        ``.usda`` (text), ``.usdc`` or ``.usd`` (binary crate).
    objects : sequence of (ObjectMotion, vertices (V, 3), faces (F, 3))
        Objects to animate, each with its mesh in its own frame (metres); same frames as ``motion``.

    Raises
    ------
    HandcapError
        No USD installed, a motion without a frame with a pose, or an object of another length.
    """
    Gf, Sdf, Usd, UsdGeom, UsdSkel, Vt = _pxr()
    path = Path(path)
    take = skinned_take(motion, hand)
    warnings = list(take.warnings)
    for om, _, _ in objects:
        if om.n_frames != motion.n_frames:
            raise HandcapError(f"object {om.name} moves for {om.n_frames} frames, the hand for {motion.n_frames}")
    fd, temporary = tempfile.mkstemp(suffix=path.suffix, prefix=f".{path.stem}.", dir=path.parent)
    os.close(fd)
    try:
        stage = Usd.Stage.CreateNew(temporary)
        UsdGeom.SetStageMetersPerUnit(stage, 1.0)
        UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.z)
        stage.SetTimeCodesPerSecond(motion.rate)
        stage.SetStartTimeCode(0)
        stage.SetEndTimeCode(motion.n_frames - 1)
        root = UsdSkel.Root.Define(stage, "/Take")
        stage.SetDefaultPrim(root.GetPrim())
        _skeleton(stage, take, Gf, Vt, UsdSkel)
        _hand_mesh(stage, take, Vt, UsdGeom, UsdSkel)
        for om, vertices, faces in objects:
            warnings += _object(stage, om, vertices, faces, Gf, Vt, UsdGeom)
        stage.GetRootLayer().Save()
        os.replace(temporary, path)
    finally:
        if os.path.exists(temporary):
            os.unlink(temporary)
    return warnings


def _skeleton(stage, take, Gf, Vt, UsdSkel) -> None:
    paths = joint_paths()
    offsets = take.rest_joints - np.where(np.arange(16)[:, None] > 0, take.rest_joints[np.maximum(PARENTS, 0)], 0.0)
    skeleton = UsdSkel.Skeleton.Define(stage, "/Take/Skeleton")
    skeleton.CreateJointsAttr(Vt.TokenArray(paths))
    skeleton.CreateJointNamesAttr(Vt.TokenArray(list(JOINT_NAMES)))
    skeleton.CreateBindTransformsAttr(Vt.Matrix4dArray([Gf.Matrix4d(1.0).SetTranslate(Gf.Vec3d(*map(float, p)))
                                                        for p in take.rest_joints]))
    skeleton.CreateRestTransformsAttr(Vt.Matrix4dArray([Gf.Matrix4d(1.0).SetTranslate(Gf.Vec3d(*map(float, p)))
                                                        for p in offsets]))
    animation = UsdSkel.Animation.Define(stage, "/Take/Skeleton/Animation")
    animation.CreateJointsAttr(Vt.TokenArray(paths))
    translations, rotations = animation.CreateTranslationsAttr(), animation.CreateRotationsAttr()
    animation.CreateScalesAttr().Set(Vt.Vec3hArray.FromNumpy(np.ones((16, 3), dtype=np.float16)))
    local = np.repeat(offsets[None], len(take.times), axis=0)
    local[:, 0] = take.wrist
    wxyz = take.local_quats[..., [3, 0, 1, 2]].astype(np.float32)
    for t in range(len(take.times)):
        translations.Set(Vt.Vec3fArray.FromNumpy(local[t].astype(np.float32)), float(t))
        rotations.Set(Vt.QuatfArray([Gf.Quatf(*map(float, q)) for q in wxyz[t]]), float(t))
    UsdSkel.BindingAPI.Apply(skeleton.GetPrim()).CreateAnimationSourceRel().SetTargets([animation.GetPath()])


def _hand_mesh(stage, take, Vt, UsdGeom, UsdSkel) -> None:
    mesh = UsdGeom.Mesh.Define(stage, "/Take/Hand")
    mesh.CreatePointsAttr(Vt.Vec3fArray.FromNumpy(take.rest_vertices.astype(np.float32)))
    mesh.CreateFaceVertexCountsAttr(Vt.IntArray([3] * len(take.faces)))
    mesh.CreateFaceVertexIndicesAttr(Vt.IntArray(take.faces.reshape(-1).astype(int).tolist()))
    mesh.CreateSubdivisionSchemeAttr(UsdGeom.Tokens.none)
    binding = UsdSkel.BindingAPI.Apply(mesh.GetPrim())
    binding.CreateSkeletonRel().SetTargets(["/Take/Skeleton"])
    binding.CreateJointIndicesPrimvar(False, 4).Set(Vt.IntArray(take.joint_index.reshape(-1).astype(int).tolist()))
    binding.CreateJointWeightsPrimvar(False, 4).Set(Vt.FloatArray(take.joint_weight.reshape(-1).tolist()))


def _object(stage, om, vertices, faces, Gf, Vt, UsdGeom) -> list[str]:
    name = "".join(c if c.isalnum() or c == "_" else "_" for c in om.name) or "object"
    if not name[0].isalpha():
        name = f"object_{name}"
    xform = UsdGeom.Xform.Define(stage, f"/Take/Objects/{name}")
    mesh = UsdGeom.Mesh.Define(stage, f"/Take/Objects/{name}/Mesh")
    mesh.CreatePointsAttr(Vt.Vec3fArray.FromNumpy(np.asarray(vertices, dtype=np.float32)))
    faces = np.asarray(faces)
    mesh.CreateFaceVertexCountsAttr(Vt.IntArray([faces.shape[1]] * len(faces)))
    mesh.CreateFaceVertexIndicesAttr(Vt.IntArray(faces.reshape(-1).astype(int).tolist()))
    ok = np.isfinite(om.translation).all(axis=1) & np.isfinite(om.rotation).all(axis=1)
    if not ok.any():
        return [f"object {om.name} has no pose in any frame: written unanimated"]
    index = nearest_found(ok)
    translate, orient = xform.AddTranslateOp(), xform.AddOrientOp()
    quats = Rotation.from_rotvec(om.rotation[index]).as_quat()[:, [3, 0, 1, 2]]
    for t, (p, q) in enumerate(zip(om.translation[index], quats)):
        translate.Set(Gf.Vec3d(*map(float, p)), float(t))
        orient.Set(Gf.Quatf(*map(float, q)), float(t))
    return []
