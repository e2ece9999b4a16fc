"""Viterbi over hypotheses (handcap.labeling.viterbi) against exhaustive search."""

import itertools

import numpy as np
import pytest

from handcap.labeling.viterbi import viterbi_path


@pytest.mark.parametrize("seed", range(20))
def test_viterbi_equals_exhaustive_search(seed):
    rng = np.random.default_rng(seed)
    sizes = rng.integers(1, 4, size=int(rng.integers(1, 6)))
    emissions = [rng.normal(size=n) for n in sizes]
    transitions = [rng.normal(size=(a, b)) for a, b in zip(sizes[:-1], sizes[1:])]
    best, best_path = -np.inf, None
    for path in itertools.product(*(range(n) for n in sizes)):
        score = sum(e[s] for e, s in zip(emissions, path)) + sum(t[a, b] for t, a, b in
                                                                 zip(transitions, path[:-1], path[1:]))
        if score > best:
            best, best_path = score, list(path)
    path, score = viterbi_path(emissions, transitions)
    assert path == best_path and np.isclose(score, best)
