"""The shipped models: they load without torch and solve unseen synthetic subjects within the target."""

import numpy as np
import pytest

from handcap.layouts import load_layout
from handcap.occlusion import SHIPPED_MODELS, OcclusionFiller, OcclusionModel, joint_error_table
from handcap.occlusion.data import simulate_take
from handcap.occlusion.evaluate import joints_from_pose


@pytest.mark.parametrize("layout", SHIPPED_MODELS)
def test_shipped_model_meets_the_joint_error_target(layout):
    model = OcclusionModel.shipped(layout)
    assert model.names == tuple(m.name for m in load_layout(layout).hand_markers)
    assert model.regressor is not None and model.side == "right"
    assert "handcap.occlusion.shipped" in model.info.get("source", "")
    # Subjects (shape, marker placement) and motions the model never saw.
    motions = ("random", "grasp", "precision", "open-close")
    takes = [simulate_take(layout, motion, 600, 100.0, 424_242 + i) for i, motion in enumerate(motions)]
    table = joint_error_table(takes, model, counts=(1, 3), durations=(0.2, 1.0), seeds=range(1), windows=60)
    # The target: 5 mm mean joint error with no occlusion (active-9 4.4, glove-13 4.0, joints-19 3.7 mm here,
    # with the models trained on the varied grasps of 2026-12-01, whose wrist no longer presses the hand into the
    # object on the table; the grasp take alone reaches 7.0 mm with active-9, 5.2 mm with the others).
    assert table["none_all"] <= 0.005, table["none_all"]
    assert (table["all"] < 0.01).all(), table["all"]  # occluded markers predicted, pose still close
    assert (table["all"] >= table["none_all"] * 0.8).all()


def test_streaming_pose_matches_the_batch_regressor():
    model = OcclusionModel.shipped("active-9")
    take = simulate_take("active-9", "open-close", 200, 100.0, 99)
    # Returning markers snap (no re-entry residual), so the measured markers reach the regressor as measured.
    filler = OcclusionFiller(model, rate=100.0, hands=("right", "left"), reentry_speed=np.inf)
    left = take.positions * np.array([-1.0, 1.0, 1.0])  # the same hand mirrored: a left hand
    for t in range(0, 200, 7):
        right, mirrored = take.positions[t].copy(), left[t].copy()
        if t % 2:  # a fingertip hidden: the filler predicts it, then regresses on the completed hand
            right[5] = mirrored[5] = np.nan
        out = filler.update(np.stack([right, mirrored]))
        # The same numbers in batch: registration on the measured markers only.
        phi, orient, transl = model.regressor.predict(out.markers[0], ~out.filled[0])
        assert np.allclose(out.phi[0], phi, atol=1e-5) and np.allclose(out.phi[1], phi, atol=1e-5)
        assert np.allclose(out.transl[0], transl, atol=1e-7)
        right_joints = joints_from_pose(out.phi[0], out.global_orient[0], out.transl[0], take.betas, "right")
        left_joints = joints_from_pose(out.phi[1], out.global_orient[1], out.transl[1], take.betas, "left")
        assert np.allclose(left_joints, right_joints * np.array([-1.0, 1.0, 1.0]), atol=1e-6)
        assert np.linalg.norm(right_joints - take.joints[t], axis=-1).mean() < 0.01


def test_streaming_on_a_synthetic_capture():
    """End to end on a ``handcap synth`` capture: its gaps come from ray casting against hand and object."""
    from handcap.synth.scene import SynthConfig, synthesize

    model = OcclusionModel.shipped("glove-13")
    capture = synthesize(SynthConfig(layout="glove-13", motion="grasp", frames=300, seed=9002, cameras=8,
                                     ghost_rate=0.0, swap_rate=0.0), progress=False)
    markers = capture.markers.select(model.names).positions
    filler = OcclusionFiller(model, rate=capture.markers.rate)
    errors, filled = [], 0
    for t, frame in enumerate(markers):
        out = filler.update(frame)
        assert not out.lost
        filled += out.filled.sum()
        joints = joints_from_pose(out.phi, out.global_orient, out.transl, capture.hand_motion.betas, "right")
        errors.append(np.linalg.norm(joints - capture.hand_motion.joints[t], axis=-1).mean())
        assert np.isfinite(out.markers).all()
    assert filled > 0  # the capture did hide markers
    assert np.mean(errors) < 0.005, np.mean(errors)
