"""fit_keypoints: the hand model fitted to 3D keypoints, against synthetic hands of known pose and shape."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from handcap import HandcapError
from handcap.core.markers import MarkerSequence
from handcap.hand import OpenHand
from handcap.markerless import fit_keypoints, hand_names, keypoints_from_joints, palm_similarity
from handcap.markerless.joint_model import KeypointModel
from handcap.markerless.synthetic import synthetic_hand


@pytest.fixture(scope="module")
def hand_take():
    return synthetic_hand(120, 30.0, np.random.default_rng(3))


def test_keypoint_model_is_the_hand_models_joints():
    hand = OpenHand()
    rng = np.random.default_rng(0)
    betas, phi = rng.normal(0, 1, 10), rng.normal(0, 0.3, (4, 27))
    orient, transl = rng.normal(0, 1, (4, 3)), rng.normal(0, 0.1, (4, 3))
    model = KeypointModel(hand, betas)
    got = model.positions(transl, Rotation.from_rotvec(orient).as_matrix(), phi)
    joints = hand.forward(betas, orient, None, transl, phi=phi, vertices=False).joints
    np.testing.assert_allclose(got, keypoints_from_joints(joints), atol=1e-12)


def test_normal_equations_match_finite_differences():
    hand = OpenHand()
    rng = np.random.default_rng(1)
    model = KeypointModel(hand, rng.normal(0, 1, 10))
    transl, rot = rng.normal(0, 0.1, (1, 3)), Rotation.from_rotvec(rng.normal(0, 1, (1, 3))).as_matrix()
    phi = rng.normal(0, 0.3, (1, 27))
    target = model.positions(transl, rot, phi) + rng.normal(0, 0.01, (1, 21, 3))

    def pos(p):
        return model.positions(transl + p[:3], Rotation.from_rotvec(p[3:6]).as_matrix() @ rot, phi + p[6:])[0]

    x0 = pos(np.zeros(33))
    jac = np.stack([(pos(e) - pos(-e)) / 2e-6 for e in np.eye(33) * 1e-6], axis=-1).reshape(63, 33)
    weights = rng.uniform(0.5, 1.0, (1, 21))
    resid = (x0 - target[0])[None]
    hess, grad = model.normal_equations(transl, rot, phi, resid, weights, dtype=np.float64)
    w = np.repeat(weights[0], 3)
    np.testing.assert_allclose(hess[0], jac.T @ (w[:, None] * jac), atol=1e-6)
    np.testing.assert_allclose(grad[0], jac.T @ (w * resid[0].reshape(-1)), atol=1e-7)


def _seq(points, rate=30.0, prefix=""):
    return MarkerSequence(points, hand_names(prefix), rate)


def test_clean_keypoints_give_the_pose_and_shape(hand_take):
    motion = fit_keypoints(_seq(hand_take.keypoints), progress=False)
    err = np.linalg.norm(keypoints_from_joints(motion.joints) - hand_take.keypoints, axis=-1)
    assert err.mean() < 0.5e-3 and err.max() < 3e-3
    assert np.degrees(np.abs(motion.phi - hand_take.phi)).mean() < 3.0
    assert not motion.warnings


def test_noisy_missing_and_wrong_keypoints(hand_take):
    rng = np.random.default_rng(4)
    pts = hand_take.keypoints + rng.normal(0, 0.003, hand_take.keypoints.shape)
    wrong = rng.random(pts.shape[:2]) < 0.02
    pts[wrong] += rng.normal(0, 0.03, (wrong.sum(), 3))
    pts[rng.random(pts.shape[:2]) < 0.1] = np.nan
    motion = fit_keypoints(_seq(pts, prefix="right"), progress=False)
    assert motion.side == "right" and motion.marker_names[0] == "right:wrist"
    err = np.linalg.norm(keypoints_from_joints(motion.joints) - hand_take.keypoints, axis=-1)
    assert err.mean() < 5e-3
    assert np.degrees(np.abs(motion.phi - hand_take.phi)).mean() < 8.0


def test_palm_similarity_gives_the_scale(hand_take):
    scale, rot, trans = palm_similarity(hand_take.keypoints * 1.3)
    assert 1.1 < scale < 1.6  # a random shape changes the palm too
    scale1, _, _ = palm_similarity(hand_take.keypoints)
    assert scale / scale1 == pytest.approx(1.3, rel=1e-6)


def test_wrong_units_and_choice_of_hand(hand_take):
    with pytest.raises(HandcapError, match="metres"):
        fit_keypoints(_seq(hand_take.keypoints * 1000), progress=False)
    two = MarkerSequence(np.concatenate([hand_take.keypoints, hand_take.keypoints + 0.3], axis=1),
                         hand_names("left") + hand_names("right"), 30.0)
    with pytest.raises(HandcapError, match="several hands"):
        fit_keypoints(two, progress=False)
    with pytest.raises(HandcapError, match="no hand 'both'"):
        fit_keypoints(two, label="both", progress=False)
    with pytest.raises(HandcapError, match="none of the 21"):
        fit_keypoints(MarkerSequence(np.zeros((3, 1, 3)), ("hand_top",), 30.0), label="", progress=False)
    nothing = np.full_like(hand_take.keypoints, np.nan)
    with pytest.raises(HandcapError, match="palm"):
        fit_keypoints(_seq(nothing), progress=False)
