"""Anatomical pose: frames, the phi <-> hand_pose map and the limits table."""

import numpy as np
import pytest
import torch

from handcap.core.rotations import matrix_from_axis_angle, matrix_from_euler_zyx
from handcap.hand import PHI_LIMITS, PHI_NAMES, OpenHand, anatomy


@pytest.fixture(scope="module", params=["right", "left"])
def hand(request):
    return OpenHand(request.param)


def test_layout_names_and_limits():
    assert len(PHI_NAMES) == 27 and len(set(PHI_NAMES)) == 27
    assert PHI_NAMES[:5] == ("index_mcp_twist", "index_mcp_spread", "index_mcp_bend",
                             "index_pip_bend", "index_dip_bend")
    assert PHI_NAMES[20:] == ("thumb_cmc_twist", "thumb_cmc_spread", "thumb_cmc_bend",
                              "thumb_mcp_twist", "thumb_mcp_spread", "thumb_mcp_bend", "thumb_ip_bend")
    deg = dict(zip(PHI_NAMES, np.degrees(PHI_LIMITS)))
    np.testing.assert_allclose(deg["ring_mcp_bend"], [-30, 90])
    np.testing.assert_allclose(deg["pinky_pip_bend"], [0, 110])
    np.testing.assert_allclose(deg["middle_dip_bend"], [0, 90])
    np.testing.assert_allclose(deg["thumb_cmc_twist"], [-45, 45])
    np.testing.assert_allclose(deg["thumb_mcp_bend"], [0, 60])
    np.testing.assert_allclose(deg["thumb_ip_bend"], [-15, 90])
    assert "Cooney" in anatomy.LIMIT_SOURCES


def test_frames_are_orthonormal_and_mirrored(hand):
    f = hand.frames
    np.testing.assert_allclose(np.swapaxes(f, 1, 2) @ f, np.broadcast_to(np.eye(3), f.shape), atol=1e-12)
    np.testing.assert_allclose(np.linalg.det(f), 1.0 if hand.is_right else -1.0, atol=1e-12)


@pytest.mark.parametrize("scale", [1.0, 1.6])
def test_phi_round_trip_is_exact(hand, scale):
    rng = np.random.default_rng(0)
    lo, hi = PHI_LIMITS[:, 0] * scale, PHI_LIMITS[:, 1] * scale
    phi = rng.uniform(np.maximum(lo, -1.5), np.minimum(hi, 1.5), size=(500, 27))
    back = hand.phi_from_hand_pose(hand.hand_pose_from_phi(phi))
    np.testing.assert_allclose(back, phi, atol=1e-9)


def test_hand_pose_is_c_e_ct(hand):
    """Independent check of R_i = C_i E(phi_i) C_i^T with scipy-free matrices."""
    rng = np.random.default_rng(1)
    phi = rng.uniform(PHI_LIMITS[:, 0], PHI_LIMITS[:, 1])
    rot = matrix_from_axis_angle(hand.hand_pose_from_phi(phi).reshape(15, 3))
    for i, (t, s, b) in enumerate(_angles_per_joint(phi)):
        c = hand.frames[i]
        expect = c @ matrix_from_euler_zyx(np.array(b), np.array(s), np.array(t)) @ c.T
        np.testing.assert_allclose(rot[i], expect, atol=1e-12)


def _angles_per_joint(phi):
    out = [[0.0, 0.0, 0.0] for _ in range(15)]
    for k, value in enumerate(phi):
        out[anatomy.PHI_JOINT[k] - 1][anatomy.PHI_AXIS[k]] = value
    return out


def test_torch_map_matches_numpy(hand):
    phi = np.random.default_rng(2).uniform(PHI_LIMITS[:, 0], PHI_LIMITS[:, 1], size=(7, 27))
    ref = hand.hand_pose_from_phi(phi)
    out = hand.hand_pose_from_phi(torch.tensor(phi))
    np.testing.assert_allclose(out.numpy(), ref, atol=1e-12)


def test_hinge_joints_only_bend(hand):
    phi = np.zeros(27)
    phi[PHI_NAMES.index("middle_dip_bend")] = 0.7
    pose = hand.hand_pose_from_phi(phi).reshape(15, 3)
    assert np.count_nonzero(np.linalg.norm(pose, axis=1) > 0) == 1
    np.testing.assert_allclose(np.linalg.norm(pose[5]), 0.7)


def test_projection_of_off_axis_rotation_keeps_the_bend():
    hand = OpenHand()
    pose = np.zeros(45)
    c = hand.frames[1]  # index PIP
    twist = c @ matrix_from_euler_zyx(np.array(0.5), np.array(0.0), np.array(0.2)) @ c.T
    from handcap.core.rotations import axis_angle_from_matrix
    pose[3:6] = axis_angle_from_matrix(twist)
    phi = hand.phi_from_hand_pose(pose)
    assert phi[PHI_NAMES.index("index_pip_bend")] == pytest.approx(0.5)


def test_limit_violation_is_zero_inside_and_signed_outside():
    phi = np.zeros(27)
    assert not anatomy.limit_violation(phi).any()
    phi[PHI_NAMES.index("index_pip_bend")] = -0.3
    phi[PHI_NAMES.index("index_dip_bend")] = 2.0
    v = anatomy.limit_violation(phi)
    assert v[PHI_NAMES.index("index_pip_bend")] == pytest.approx(0.3)
    assert v[PHI_NAMES.index("index_dip_bend")] == pytest.approx(np.pi / 2 - 2.0)
    vt = anatomy.limit_violation(torch.tensor(phi))
    np.testing.assert_allclose(vt.numpy(), v)
