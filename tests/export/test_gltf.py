"""The .glb export: valid by the Khronos glTF validator (when node and gltf-validator are at hand; .ci/run
installs them), the right frames and joints, and a viewer's skinning of it (computed here from the file's
nodes, animation and skin alone) puts the mesh where handcap's model does."""

import json
import os
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pygltflib as gl
import pytest
from scipy.spatial.transform import Rotation

from handcap.cli import main
from handcap.core.motion import ObjectMotion
from handcap.export import glb_bytes, write_glb
from handcap.hand import OpenHand
from handcap.io import write_hand_motion
from handcap.synth.scene import SynthConfig, synthesize

VALIDATOR = Path(__file__).with_name("validate_gltf.js")


@pytest.fixture(scope="module")
def capture():
    return synthesize(SynthConfig(motion="precision", frames=300, rate=100.0, seed=2, cameras=4), progress=False)


def _read(path):
    g = gl.GLTF2().load(str(path))
    blob = g.binary_blob()

    def accessor(i):
        a = g.accessors[i]
        view = g.bufferViews[a.bufferView]
        kind = {5126: np.float32, 5125: np.uint32, 5123: np.uint16}[a.componentType]
        width = {"SCALAR": 1, "VEC3": 3, "VEC4": 4, "MAT4": 16}[a.type]
        return np.frombuffer(blob, kind, a.count * width, view.byteOffset).reshape(a.count, width)

    return g, accessor


def _skinned(g, accessor, frame):
    """Linear blend skinning of the file's mesh at ``frame``, by the glTF rules (global joint matrix times
    inverse bind matrix, weights from the file)."""
    trs = {k: {"t": np.array(n.translation or [0, 0, 0], float), "r": np.array(n.rotation or [0, 0, 0, 1], float)}
           for k, n in enumerate(g.nodes)}
    for channel in g.animations[0].channels:
        values = accessor(g.animations[0].samplers[channel.sampler].output)
        trs[channel.target.node]["t" if channel.target.path == "translation" else "r"] = values[frame].astype(float)
    parent = {c: k for k, n in enumerate(g.nodes) for c in (n.children or [])}

    def world(k):
        m = np.eye(4)
        m[:3, :3], m[:3, 3] = Rotation.from_quat(trs[k]["r"]).as_matrix(), trs[k]["t"]
        return world(parent[k]) @ m if k in parent else m

    skin = g.skins[0]
    inverse = accessor(skin.inverseBindMatrices).reshape(-1, 4, 4).transpose(0, 2, 1)
    joints = np.array([world(k) for k in skin.joints]) @ inverse
    attributes = g.meshes[0].primitives[0].attributes
    rest = accessor(attributes.POSITION).astype(float)
    index, weight = accessor(attributes.JOINTS_0).astype(int), accessor(attributes.WEIGHTS_0).astype(float)
    placed = np.einsum("vkij,vj->vki", joints[index], np.c_[rest, np.ones(len(rest))])[..., :3]
    return np.einsum("vk,vki->vi", weight, placed)


def test_glb_frames_joints_and_skinning(capture, tmp_path):
    motion, hand = capture.hand_motion, OpenHand(capture.hand_motion.side)
    om = capture.object_motion
    from handcap.synth.objects import make_object

    obj = make_object(om.name, seed=2)
    assert write_glb(motion, hand, tmp_path / "take.glb", [(om, obj.vertices, obj.faces)]) == []
    g, accessor = _read(tmp_path / "take.glb")
    assert len(g.skins[0].joints) == 16 and len(g.animations) == 1
    assert accessor(g.animations[0].samplers[0].input).shape == (motion.n_frames, 1)
    assert np.isclose(accessor(g.animations[0].samplers[0].input)[-1, 0], (motion.n_frames - 1) / 100.0)
    truth = hand.forward(motion.betas, motion.global_orient, motion.hand_pose, motion.transl).vertices
    for frame in (0, 150, 299):
        error = np.linalg.norm(_skinned(g, accessor, frame) - truth[frame], axis=1)
        # the file keeps each vertex's four strongest joints: within a millimetre of the model's skinning
        assert np.median(error) < 1e-4 and error.max() < 1e-3, (frame, np.median(error), error.max())
    node = next(k for k, n in enumerate(g.nodes) if n.name == om.name)
    channels = {c.target.path: accessor(g.animations[0].samplers[c.sampler].output)
                for c in g.animations[0].channels if c.target.node == node}
    assert np.allclose(channels["translation"], om.translation, atol=1e-6)
    turn = Rotation.from_quat(channels["rotation"]).inv() * Rotation.from_rotvec(om.rotation)
    assert np.rad2deg(turn.magnitude()).max() < 1e-3


def test_glb_passes_the_khronos_validator(capture, tmp_path):
    node = shutil.which("node")
    if node is None:
        pytest.skip("node is not installed (.ci/run installs it with gltf-validator)")
    probe = subprocess.run([node, "-e", "require.resolve('gltf-validator')"], capture_output=True,
                           env={**os.environ})
    if probe.returncode:
        pytest.skip("the npm package gltf-validator is not on NODE_PATH (.ci/run installs it)")
    data, _ = glb_bytes(capture.hand_motion, OpenHand(capture.hand_motion.side))
    (tmp_path / "hand.glb").write_bytes(data)
    run = subprocess.run([node, str(VALIDATOR), str(tmp_path / "hand.glb")], capture_output=True, text=True,
                         timeout=120)
    report = json.loads(run.stdout)
    assert run.returncode == 0 and report["errors"] == 0 and report["warnings"] == 0, report["messages"]
    assert report["info"]["hasSkins"] and report["info"]["animationCount"] == 1


def test_export_verb_writes_a_glb_and_refuses_objects_elsewhere(capture, tmp_path, capsys):
    import trimesh

    from handcap.io import write_object_motion
    from handcap.synth.objects import make_object

    write_hand_motion(capture.hand_motion, tmp_path / "motion.npz")
    write_object_motion(capture.object_motion, tmp_path / "object.npz")
    obj = make_object(capture.object_motion.name, seed=2)
    trimesh.Trimesh(obj.vertices, obj.faces).export(tmp_path / "object.obj")
    argv = ["export", str(tmp_path / "motion.npz"), "--to", str(tmp_path / "take.glb")]
    assert main([*argv, "--object", str(tmp_path / "object.npz"), "--object-mesh", str(tmp_path / "object.obj")]) == 0
    g, _ = _read(tmp_path / "take.glb")
    assert [n.name for n in g.nodes][-1] == capture.object_motion.name and len(g.meshes) == 2
    capsys.readouterr()
    assert main([*argv, "--object", str(tmp_path / "object.npz")]) == 2
    assert "one --object-mesh per --object" in capsys.readouterr().err
    lost = ObjectMotion(np.full((3, 3), np.nan), np.full((3, 3), np.nan), 100.0, "x", ("a",), np.zeros((1, 3)))
    from handcap import HandcapError
    from handcap.export import export_motion

    with pytest.raises(HandcapError, match="objects go into a .glb"):
        export_motion(capture.hand_motion, OpenHand("right"), tmp_path / "a.bvh",
                      objects=[(lost, np.zeros((3, 3)), np.array([[0, 1, 2]]))])
