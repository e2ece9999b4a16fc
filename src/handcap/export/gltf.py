"""glTF binary (``.glb``) export: the skinned hand mesh with its animation, and objects as animated nodes.

Built with pygltflib. The skeleton is the hand model's 16 joints as nodes (the wrist the root), each with
its rest offset from its parent as translation; the mesh is the rest (flat) hand of the take's shape,
skinned to them with the model's four strongest weights per vertex (renormalised), and each joint's inverse
bind matrix undoes its rest position. One animation holds, per frame, every joint's rotation relative to its
parent (the wrist's to the world) and the wrist's position, so a viewer's skinning reproduces the model's
linear blend skinning (a model with pose correctives, MANO, loses them). Objects are nodes carrying their
mesh, with translation and rotation channels. Metres, seconds; glTF's y-up is not imposed: the world frame
is handcap's (z up), as the capture had it.
"""

from __future__ import annotations

import numpy as np
import pygltflib as gl
from scipy.spatial.transform import Rotation

from handcap.core.errors import HandcapError
from handcap.core.files import atomic_output
from handcap.core.motion import HandMotion
from handcap.export.bvh import nearest_found
from handcap.export.skinning import skinned_take
from handcap.hand.anatomy import JOINT_NAMES, PARENTS

_FLOAT, _UINT, _USHORT = 5126, 5125, 5123


class _Buffer:
    """One binary buffer and the accessors into it."""

    def __init__(self, gltf: gl.GLTF2):
        self.gltf, self.blob = gltf, bytearray()

    def add(self, array, kind: str, component: int = _FLOAT, target=None, minmax: bool = False) -> int:
        data = np.ascontiguousarray(array, dtype={_FLOAT: np.float32, _UINT: np.uint32, _USHORT: np.uint16}[component])
        while len(self.blob) % 4:
            self.blob.append(0)
        view = gl.BufferView(buffer=0, byteOffset=len(self.blob), byteLength=data.nbytes, target=target)
        self.blob += data.tobytes()
        self.gltf.bufferViews.append(view)
        flat = data.reshape(len(data), -1)
        accessor = gl.Accessor(bufferView=len(self.gltf.bufferViews) - 1, componentType=component, count=len(data),
                               type=kind)
        if minmax:
            accessor.min, accessor.max = flat.min(axis=0).tolist(), flat.max(axis=0).tolist()
        self.gltf.accessors.append(accessor)
        return len(self.gltf.accessors) - 1


def glb_bytes(motion: HandMotion, hand, objects=()) -> tuple[bytes, list[str]]:
    """The ``.glb`` of ``motion`` (and objects), and the warnings it raised.

    Parameters
    ----------
    motion : HandMotion
    hand : HandModel
        The model the motion was solved with (rest mesh, weights, joints).
    objects : sequence of (ObjectMotion, vertices (V, 3), faces (F, 3))
        Objects to animate, each with its mesh in its own frame (metres); same frames as ``motion``.

    Returns
    -------
    bytes, list of str

    Raises
    ------
    HandcapError
        A motion without a frame with a pose, or an object of another length.
    """
    take = skinned_take(motion, hand)
    warnings = list(take.warnings)
    rest_vertices, rest_joints, quats, times = take.rest_vertices, take.rest_joints, take.local_quats, take.times

    gltf = gl.GLTF2(asset=gl.Asset(version="2.0", generator="handcap"), scene=0)
    buf = _Buffer(gltf)
    # skeleton: joint j is node j
    for j in range(16):
        offset = rest_joints[j] - (rest_joints[PARENTS[j]] if j else 0.0)
        children = [int(c) for c in np.flatnonzero(PARENTS == j)]
        gltf.nodes.append(gl.Node(name=JOINT_NAMES[j], translation=offset.tolist(), children=children or None))
    top, strength = take.joint_index, take.joint_weight  # a joint given no weight is joint 0 (the validator asks)
    inverse_bind = np.tile(np.eye(4), (16, 1, 1))
    inverse_bind[:, :3, 3] = -rest_joints
    mesh = gl.Mesh(name="hand", primitives=[gl.Primitive(
        attributes=gl.Attributes(POSITION=buf.add(rest_vertices, "VEC3", target=34962, minmax=True),
                                 JOINTS_0=buf.add(top, "VEC4", _USHORT, target=34962),
                                 WEIGHTS_0=buf.add(strength, "VEC4", target=34962)),
        indices=buf.add(np.asarray(hand.faces).reshape(-1), "SCALAR", _UINT, target=34963))])
    gltf.meshes.append(mesh)
    gltf.skins.append(gl.Skin(joints=list(range(16)), skeleton=0, name="hand",
                              inverseBindMatrices=buf.add(inverse_bind.transpose(0, 2, 1).reshape(16, 16), "MAT4")))
    gltf.nodes.append(gl.Node(name="hand_mesh", mesh=0, skin=0))
    scene_nodes = [0, 16]
    time_accessor = buf.add(times, "SCALAR", minmax=True)
    samplers, channels = [], []

    def animate(node, path, values, kind):
        samplers.append(gl.AnimationSampler(input=time_accessor, output=buf.add(values, kind), interpolation="LINEAR"))
        channels.append(gl.AnimationChannel(sampler=len(samplers) - 1, target=gl.AnimationChannelTarget(node=node,
                                                                                                       path=path)))

    animate(0, "translation", take.wrist, "VEC3")
    for j in range(16):
        animate(j, "rotation", quats[:, j], "VEC4")
    for om, vertices, faces in objects:
        if om.n_frames != motion.n_frames:
            raise HandcapError(f"object {om.name} moves for {om.n_frames} frames, the hand for {motion.n_frames}")
        gltf.meshes.append(gl.Mesh(name=om.name, primitives=[gl.Primitive(
            attributes=gl.Attributes(POSITION=buf.add(vertices, "VEC3", target=34962, minmax=True)),
            indices=buf.add(np.asarray(faces).reshape(-1), "SCALAR", _UINT, target=34963))]))
        gltf.nodes.append(gl.Node(name=om.name, mesh=len(gltf.meshes) - 1))
        node = len(gltf.nodes) - 1
        scene_nodes.append(node)
        ok = np.isfinite(om.translation).all(axis=1) & np.isfinite(om.rotation).all(axis=1)
        if not ok.any():
            warnings.append(f"object {om.name} has no pose in any frame: written unanimated")
            continue
        index = nearest_found(ok)
        animate(node, "translation", om.translation[index], "VEC3")
        animate(node, "rotation", Rotation.from_rotvec(om.rotation[index]).as_quat(), "VEC4")
    gltf.animations.append(gl.Animation(name="take", samplers=samplers, channels=channels))
    gltf.scenes.append(gl.Scene(nodes=scene_nodes))
    gltf.buffers.append(gl.Buffer(byteLength=len(buf.blob)))
    gltf.set_binary_blob(bytes(buf.blob))
    return b"".join(gltf.save_to_bytes()), warnings


def write_glb(motion: HandMotion, hand, path, objects=()) -> list[str]:
    """Write the ``.glb`` of :func:`glb_bytes` atomically; returns the warnings.

    Parameters
    ----------
    motion : HandMotion
    hand : HandModel
    path : str or Path
    objects : sequence of (ObjectMotion, vertices, faces)
    """
    data, warnings = glb_bytes(motion, hand, objects)
    with atomic_output(path) as fh:
        fh.write(data)
    return warnings
