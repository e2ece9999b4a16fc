import numpy as np
import pytest
import torch
from scipy.spatial.transform import Rotation

from handcap.core.rotations import (
    axis_angle_from_matrix,
    euler_zyx_from_matrix,
    matrix_from_axis_angle,
    matrix_from_euler_zyx,
)


def test_matrix_from_axis_angle_matches_scipy_including_tiny_angles():
    rng = np.random.default_rng(0)
    aa = np.concatenate([rng.normal(size=(200, 3)), rng.normal(size=(20, 3)) * 1e-9, np.zeros((1, 3))])
    np.testing.assert_allclose(matrix_from_axis_angle(aa), Rotation.from_rotvec(aa).as_matrix(), atol=1e-14)


def test_round_trip_and_batch_shapes():
    rng = np.random.default_rng(1)
    aa = rng.normal(size=(4, 5, 3))
    norm = np.linalg.norm(aa, axis=-1, keepdims=True)
    aa *= (np.pi - 1e-3) * np.tanh(norm) / norm
    m = matrix_from_axis_angle(aa)
    assert m.shape == (4, 5, 3, 3)
    np.testing.assert_allclose(axis_angle_from_matrix(m), aa, atol=1e-10)


def test_torch_gradient_at_zero_is_finite():
    aa = torch.zeros(3, dtype=torch.float64, requires_grad=True)
    m = matrix_from_axis_angle(aa)
    (m[0, 1] + m[1, 2] * 2 + m[2, 0] * 3).backward()
    # d R / d aa at zero is the skew map: R[0,1] = -z, R[1,2] = -x, R[2,0] = -y.
    np.testing.assert_allclose(aa.grad.numpy(), [-2.0, -3.0, -1.0])


@pytest.mark.parametrize("seed", range(3))
def test_euler_zyx_round_trip_and_meaning(seed):
    rng = np.random.default_rng(seed)
    bend, spread, twist = rng.uniform(-3, 3, 50), rng.uniform(-1.5, 1.5, 50), rng.uniform(-3, 3, 50)
    m = matrix_from_euler_zyx(bend, spread, twist)
    np.testing.assert_allclose(m, Rotation.from_euler("ZYX", np.c_[bend, spread, twist]).as_matrix(), atol=1e-12)
    b, s, t = euler_zyx_from_matrix(m)
    np.testing.assert_allclose(np.c_[b, s, t], np.c_[bend, spread, twist], atol=1e-12)
