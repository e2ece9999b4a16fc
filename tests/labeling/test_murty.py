"""N best assignments (handcap.labeling.murty, and compiled: handcap.labeling.lap) against brute force."""

import itertools

import numpy as np
import pytest

from handcap.labeling import k_best_assignments, lap

COMPILED = [False, pytest.param(True, marks=pytest.mark.skipif(not lap.AVAILABLE, reason="numba not installed "
                                                                   "(extra 'stream')"))]


def _random_cost(rng, *, ties: bool):
    rows = int(rng.integers(1, 6))
    cols = int(rng.integers(rows, 8))
    cost = rng.normal(size=(rows, cols))
    if ties:
        cost = np.round(cost)  # many assignments of equal cost
    cost[rng.uniform(size=cost.shape) < rng.uniform(0.0, 0.6)] = np.inf
    return cost


@pytest.mark.parametrize("compiled", COMPILED)
@pytest.mark.parametrize("seed", range(40))
def test_murty_k_best_equals_brute_force(seed, compiled):
    rng = np.random.default_rng(seed)
    cost = _random_cost(rng, ties=seed % 3 == 0)
    rows, cols = cost.shape
    every = sorted(v for perm in itertools.permutations(range(cols), rows)
                   if np.isfinite(v := cost[np.arange(rows), perm].sum()))
    k = int(rng.integers(1, 12))
    got = k_best_assignments(cost, k, compiled=compiled)
    assert len(got) == min(k, len(every))
    np.testing.assert_allclose([t for _, t in got], every[:len(got)], atol=1e-12)
    assert len({tuple(c) for c, _ in got}) == len(got)  # all different
    for columns, total in got:
        assert len(set(columns)) == rows and np.isclose(cost[np.arange(rows), columns].sum(), total)


@pytest.mark.skipif(not lap.AVAILABLE, reason="numba not installed (extra 'stream')")
def test_compiled_ranking_equals_scipy_on_labelling_sized_problems():
    # The labeler's shape: 16 free labels, 20 points and an occlusion column per label, most pairings
    # forbidden. Without ties the k best are unique, so the two must give the same assignments.
    rng = np.random.default_rng(5)
    for _ in range(200):
        cost = np.full((16, 36), np.inf)
        cost[:, :20] = np.where(rng.uniform(size=(16, 20)) < 0.25, rng.exponential(3.0, size=(16, 20)), np.inf)
        cost[np.arange(16), 20 + np.arange(16)] = 2.7 + rng.normal(0, 0.01, 16)
        for k in (1, 2, 5):
            fast, slow = k_best_assignments(cost, k), k_best_assignments(cost, k, compiled=False)
            assert len(fast) == len(slow) == k
            for (a, ta), (b, tb) in zip(fast, slow):
                np.testing.assert_array_equal(a, b)
                assert ta == pytest.approx(tb, abs=1e-12)


@pytest.mark.parametrize("compiled", COMPILED)
def test_murty_edge_cases(compiled):
    assert k_best_assignments(np.full((2, 3), np.inf), 3, compiled=compiled) == []
    assert k_best_assignments(np.array([[0.0, np.inf], [0.0, np.inf]]), 2, compiled=compiled) == []
    (cols, total), = k_best_assignments(np.zeros((0, 4)), 2, compiled=compiled)
    assert cols.shape == (0,) and total == 0.0
    with pytest.raises(ValueError):
        k_best_assignments(np.zeros((3, 2)), 1, compiled=compiled)
