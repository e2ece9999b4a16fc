"""Batched sparse forward differences: the Jacobian scipy's own differences give, from one call of the residuals."""

import numpy as np
from scipy.optimize import least_squares
from scipy.sparse import random as sparse_random

from handcap.markerless.numdiff import column_groups, sparse_differences


def _problem(seed=0, m=120, n=40):
    """Residuals r_i = sum_j a_ij sin(x_j) + b_ij x_j^2 over a random sparsity pattern, batched and single."""
    rng = np.random.default_rng(seed)
    pattern = sparse_random(m, n, density=0.08, random_state=seed, format="csr")
    pattern.data[:] = 1.0
    mask = pattern.toarray() > 0
    a, b = rng.normal(size=(m, n)) * mask, rng.normal(size=(m, n)) * mask

    def batched(x):
        return np.sin(x) @ a.T + (x ** 2) @ b.T

    return pattern, batched, a, b


def test_groups_share_no_row_and_cover_every_column():
    pattern, *_ = _problem()
    group = column_groups(pattern)
    dense = pattern.toarray() > 0
    assert len(group) == dense.shape[1] and group.max() < dense.shape[1]
    for g in range(group.max() + 1):
        assert (dense[:, group == g].sum(axis=1) <= 1).all()  # no row touched twice in a group
    assert group.max() + 1 < dense.shape[1]  # it does group


def test_the_jacobian_is_the_column_by_column_and_the_analytic_one():
    pattern, batched, a, b = _problem()
    x = np.random.default_rng(1).normal(size=pattern.shape[1]) * 3
    jac = sparse_differences(batched, pattern)(x).toarray()
    step = np.sqrt(np.finfo(float).eps) * np.maximum(1.0, np.abs(x))  # one column at a time, densely
    dense = np.stack([(batched((x + step[j] * np.eye(len(x))[j])[None])[0] - batched(x[None])[0]) / step[j]
                      for j in range(len(x))], axis=1)
    np.testing.assert_allclose(jac, dense * (pattern.toarray() > 0), rtol=0, atol=1e-5)  # rounding over the step
    analytic = a * np.cos(x) + 2 * b * x
    np.testing.assert_allclose(jac, analytic, atol=2e-6 * (1 + np.abs(x)).max() ** 2)


def test_least_squares_reaches_the_same_fit():
    pattern, batched, *_ = _problem(seed=2, m=80, n=30)
    target = batched(np.random.default_rng(3).normal(size=(1, 30)))[0]
    start = np.zeros(30)
    ours = least_squares(lambda v: batched(v[None])[0] - target, start,
                         jac=sparse_differences(lambda p: batched(p) - target, pattern), method="trf")
    theirs = least_squares(lambda v: batched(v[None])[0] - target, start, jac_sparsity=pattern, method="trf")
    assert abs(ours.cost - theirs.cost) <= 1e-6 * max(theirs.cost, 1e-12) + 1e-12
