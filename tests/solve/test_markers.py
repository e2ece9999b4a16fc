"""MarkerModel: exact positions and an analytic Jacobian checked by finite differences."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from handcap.hand import PHI_LIMITS, OpenHand
from handcap.hand.attachment import MarkerAttachment
from handcap.layouts import load_layout
from handcap.solve.markers import MarkerModel


def _random_poses(side, layout, seed, n):
    """A marker model of a random subject and n random poses within the joint limits."""
    hand = OpenHand(side)
    rng = np.random.default_rng(seed)
    att = MarkerAttachment.from_layout(load_layout(layout), hand, rng.normal(size=10) * 0.5)
    phi = rng.uniform(PHI_LIMITS[:, 0], PHI_LIMITS[:, 1], (n, 27))
    rot = Rotation.from_rotvec(rng.normal(size=(n, 3))).as_matrix()
    return hand, att, MarkerModel(hand, att), rng, rng.normal(size=(n, 3)), rot, phi


@pytest.mark.parametrize("side", ["right", "left"])
@pytest.mark.parametrize("layout", ["glove-13", "dense-patches"])
def test_positions_exact_and_jacobian_matches_finite_differences(side, layout):
    n = 2
    hand, att, model, rng, transl, rot, phi = _random_poses(side, layout, 1, n)
    x = model.positions(transl, rot, phi)
    out = hand.forward(att.betas, Rotation.from_matrix(rot).as_rotvec(), phi=phi, transl=transl)
    np.testing.assert_allclose(x, att.positions(out.vertices, hand.faces), atol=1e-12)
    jac = model.jacobian(transl, rot, phi)
    eps = 1e-6
    numeric = np.zeros_like(jac)
    for p in range(33):
        d = np.zeros(33)
        d[p] = eps

        def f(d):
            r = Rotation.from_rotvec(np.tile(d[3:6], (n, 1))).as_matrix() @ rot
            return np.swapaxes(model.positions(transl + d[:3], r, phi + d[6:]), 1, 2)
        numeric[..., p] = (f(d) - f(-d)) / (2 * eps)
    # Exact on rigid parts; the blended-weight approximation stays within 0.3 % elsewhere.
    assert np.abs(jac - numeric).max() < 3e-3 * np.abs(numeric).max()
    rigid = model.marker_weights.max(axis=1) > 0.999
    assert np.abs(jac - numeric)[:, :, rigid].max() < 1e-3 * np.abs(numeric).max()


@pytest.mark.parametrize("side", ["right", "left"])
@pytest.mark.parametrize("layout", ["glove-13", "dense-patches"])
def test_normal_equations_equal_the_dense_products(side, layout):
    # The solver never forms J: its J^T W J and J^T W r must equal those of the dense Jacobian.
    n = 3
    _, _, model, rng, transl, rot, phi = _random_poses(side, layout, 2, n)
    m = model.n_markers
    weights = rng.uniform(0, 1, (n, m)) * (rng.uniform(size=(n, m)) > 0.2)
    resid = rng.normal(scale=0.01, size=(n, m, 3))
    jac = np.swapaxes(model.jacobian(transl, rot, phi), 1, 2).reshape(n, 3 * m, 33)  # rows (marker, axis)
    w = np.repeat(weights, 3, axis=1)
    hess = np.einsum("tkp,tk,tkq->tpq", jac, w, jac)
    grad = np.einsum("tkp,tk->tp", jac, w * resid.reshape(n, -1))
    h64, g64 = model.normal_equations(transl, rot, phi, resid, weights, dtype=np.float64)
    np.testing.assert_allclose(h64, hess, atol=1e-12 * np.abs(hess).max())
    np.testing.assert_allclose(g64, grad, atol=1e-12 * np.abs(grad).max())
    h32, g32 = model.normal_equations(transl, rot, phi, resid, weights)
    assert h32.dtype == np.float64
    np.testing.assert_allclose(h32, hess, atol=1e-5 * np.abs(hess).max())
    np.testing.assert_allclose(g32, grad, atol=1e-5 * np.abs(grad).max())
