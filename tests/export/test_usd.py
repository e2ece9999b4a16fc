"""The USD export, read back by Pixar's USD (the extra 'usd'): the stage's frames, rate and units, the
skeleton's 16 joints, UsdSkel's own skinning of the hand mesh within a millimetre of handcap's model, its
joints where handcap's forward kinematics puts them, and an object's animated transform."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from handcap.cli import main
from handcap.core.motion import ObjectMotion
from handcap.export.usd import joint_paths, write_usd
from handcap.hand import OpenHand
from handcap.io import write_hand_motion
from handcap.synth.scene import SynthConfig, synthesize

pxr = pytest.importorskip("pxr", reason="USD export needs the extra 'usd' (usd-core)")
from pxr import Usd, UsdGeom, UsdSkel  # noqa: E402


@pytest.fixture(scope="module")
def capture():
    return synthesize(SynthConfig(motion="precision", frames=260, rate=100.0, seed=2, cameras=4), progress=False)


def test_usd_skinning_by_pixars_reader_matches_the_model(capture, tmp_path):
    motion, hand = capture.hand_motion, OpenHand("right")
    path = tmp_path / "take.usdc"
    spin = np.column_stack([np.zeros(motion.n_frames), np.zeros(motion.n_frames), np.linspace(0, 1.5, motion.n_frames)])
    turning = ObjectMotion(spin, np.tile([0.1, 0.2, 0.9], (motion.n_frames, 1)), motion.rate, "mug 1", ("a",),
                           np.zeros((1, 3)))
    cube = np.array([[x, y, z] for x in (0, 0.05) for y in (0, 0.05) for z in (0, 0.05)])
    faces = np.array([[0, 1, 3], [0, 3, 2], [4, 6, 7], [4, 7, 5]])
    assert write_usd(motion, hand, path, [(turning, cube, faces)]) == []
    stage = Usd.Stage.Open(str(path))
    assert UsdGeom.GetStageMetersPerUnit(stage) == 1.0 and UsdGeom.GetStageUpAxis(stage) == "Z"
    assert stage.GetTimeCodesPerSecond() == 100.0 and stage.GetEndTimeCode() == motion.n_frames - 1
    skeleton = UsdSkel.Skeleton(stage.GetPrimAtPath("/Take/Skeleton"))
    assert list(skeleton.GetJointsAttr().Get()) == joint_paths() and len(joint_paths()) == 16
    cache = UsdSkel.Cache()
    root = UsdSkel.Root(stage.GetPrimAtPath("/Take"))
    cache.Populate(root, Usd.TraverseInstanceProxies())
    skel_query = cache.GetSkelQuery(skeleton)
    skinning = cache.GetSkinningQuery(stage.GetPrimAtPath("/Take/Hand"))
    mesh = UsdGeom.Mesh(stage.GetPrimAtPath("/Take/Hand"))
    xform_cache = UsdGeom.XformCache()
    for frame in (0, 57, motion.n_frames - 1):
        xform_cache.SetTime(frame)
        points = mesh.GetPointsAttr().Get()
        assert skinning.ComputeSkinnedPoints(skel_query.ComputeSkinningTransforms(frame), points, frame)
        model = hand.forward(motion.betas, motion.global_orient[frame], motion.hand_pose[frame], motion.transl[frame])
        np.testing.assert_array_less(np.linalg.norm(np.array(points) - np.asarray(model.vertices), axis=-1), 0.001)
        world = np.array(skel_query.ComputeJointWorldTransforms(xform_cache))
        np.testing.assert_allclose(world[:, 3, :3], motion.joints[frame, :16], atol=1e-5)  # float32 in the file
    obj = UsdGeom.Xformable(stage.GetPrimAtPath("/Take/Objects/mug_1"))
    matrix = np.array(obj.ComputeLocalToWorldTransform(motion.n_frames - 1))
    np.testing.assert_allclose(matrix[3, :3], [0.1, 0.2, 0.9], atol=1e-6)
    np.testing.assert_allclose(matrix[:3, :3].T, Rotation.from_rotvec([0, 0, 1.5]).as_matrix(), atol=1e-6)


def test_usd_export_verb_writes_text_and_refuses_what_it_cannot(capture, tmp_path, capsys):
    write_hand_motion(capture.hand_motion, tmp_path / "motion.npz")
    assert main(["export", str(tmp_path / "motion.npz"), "--to", str(tmp_path / "take.usda")]) == 0
    text = (tmp_path / "take.usda").read_text()
    assert text.startswith("#usda") and "def SkelRoot \"Take\"" in text and "rel skel:animationSource" in text
    assert not list(tmp_path.glob(".take*"))  # no temporary file left
    assert main(["export", str(tmp_path / "motion.npz"), "--to", str(tmp_path / "motion.npz.usda")]) == 0
    assert main(["export", str(tmp_path / "motion.npz"), "--to", str(tmp_path / "motion.npz")]) == 2  # its input
    assert "motion.npz" in capsys.readouterr().err
