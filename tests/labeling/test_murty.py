"""N best assignments (handcap.labeling.murty) against brute force."""

import itertools

import numpy as np
import pytest

from handcap.labeling import k_best_assignments


@pytest.mark.parametrize("seed", range(40))
def test_murty_k_best_equals_brute_force(seed):
    rng = np.random.default_rng(seed)
    rows = int(rng.integers(1, 5))
    cols = int(rng.integers(rows, 7))
    cost = rng.normal(size=(rows, cols))
    cost[rng.uniform(size=cost.shape) < 0.2] = np.inf
    every = sorted(v for perm in itertools.permutations(range(cols), rows)
                   if np.isfinite(v := cost[np.arange(rows), perm].sum()))
    k = int(rng.integers(1, 12))
    got = k_best_assignments(cost, k)
    assert len(got) == min(k, len(every))
    np.testing.assert_allclose([t for _, t in got], every[:len(got)], atol=1e-12)
    assert len({tuple(c) for c, _ in got}) == len(got)  # all different
    for columns, total in got:
        assert len(set(columns)) == rows and np.isclose(cost[np.arange(rows), columns].sum(), total)


def test_murty_edge_cases():
    assert k_best_assignments(np.full((2, 3), np.inf), 3) == []
    (cols, total), = k_best_assignments(np.zeros((0, 4)), 2)
    assert cols.shape == (0,) and total == 0.0
    with pytest.raises(ValueError):
        k_best_assignments(np.zeros((3, 2)), 1)
