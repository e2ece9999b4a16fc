"""Each part of the labeler against an independent computation."""

import itertools

import numpy as np
import pytest
from scipy.stats import multivariate_normal

from handcap.labeling import KalmanBatch, KalmanSettings, SpatialModel, k_best_assignments
from handcap.labeling.viterbi import viterbi_path


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


def test_kalman_likelihood_is_the_gaussian_density():
    rng = np.random.default_rng(0)
    residual, variance = rng.normal(size=(5, 3)) * 0.002, rng.uniform(1e-6, 1e-5, 5)
    expected = [multivariate_normal(np.zeros(3), v * np.eye(3)).logpdf(r) for r, v in zip(residual, variance)]
    np.testing.assert_allclose(KalmanBatch.log_likelihood(residual, variance), expected, rtol=1e-12)


def test_kalman_filter_matches_the_textbook_equations():
    # One 9-state filter written out with explicit matrices against the batched, axis-shared one.
    s = KalmanSettings(dt=0.01, jerk=50.0, measurement=(0.3e-3) ** 2)
    rng = np.random.default_rng(1)
    track = np.cumsum(rng.normal(0, 0.001, (30, 3)), axis=0)
    track[[7, 8, 15]] = np.nan
    f1 = np.kron(np.eye(3), s.transition)  # state [x vx ax y vy ay z vz az]
    q = np.kron(np.eye(3), s.process)
    h = np.kron(np.eye(3), np.array([[1.0, 0.0, 0.0]]))
    r = s.measurement * np.eye(3)
    x = np.zeros(9)
    x[[0, 3, 6]] = track[0]
    p = np.kron(np.eye(3), np.diag([s.measurement, s.initial_velocity, s.initial_acceleration]))
    batch = KalmanBatch(s, 1)
    batch.restart(np.array([True]), track[:1])
    for z in track[1:]:
        x, p = f1 @ x, f1 @ p @ f1.T + q
        if not np.isnan(z[0]):
            innovation_cov = h @ p @ h.T + r
            gain = p @ h.T @ np.linalg.inv(innovation_cov)
            x = x + gain @ (z - h @ x)
            p = (np.eye(9) - gain @ h) @ p
        batch.step(z[None])
        np.testing.assert_allclose(batch.state[0].T.ravel(), x, rtol=1e-9, atol=1e-12)
        np.testing.assert_allclose(batch.cov[0], p[:3, :3], rtol=1e-9, atol=1e-15)



def test_successors_equal_copy_step_and_restart():
    # The labeler's one-call advance against the separate operations: pick filters, step, restart the lost.
    s = KalmanSettings(dt=0.01, jerk=50.0, measurement=(0.3e-3) ** 2)
    rng = np.random.default_rng(4)
    batch = KalmanBatch(s, 6)
    batch.restart(np.ones(6, bool), rng.normal(size=(6, 3)))
    for t in range(15):  # filters 4 and 5 go unseen from frame 3 on: past max_coast = 10
        z = rng.normal(scale=0.01, size=(6, 3)) + t * 0.001
        z[4:] = np.nan if t >= 3 else z[4:]
        batch.step(z)
    index = np.array([0, 0, 2, 4, 5, 1, 3])
    measured = rng.normal(size=(7, 3))
    measured[[1, 4]] = np.nan
    fast = batch.successors(index, measured, batch.predicted(), max_coast=10)
    slow = KalmanBatch(s, 0)
    slow.copy_from(batch, index)
    lost = (slow.missed > 10) & ~np.isnan(measured[:, 0])
    assert lost.tolist() == [False, False, False, True, False, False, False]
    slow.step(np.where(lost[:, None], np.nan, measured))
    slow.restart(lost, measured)
    for name in ("state", "cov", "age", "missed"):
        np.testing.assert_allclose(getattr(fast, name), getattr(slow, name), rtol=1e-12, atol=0, err_msg=name)


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


def test_spatial_model_matches_scikit_learn():
    from sklearn.mixture import GaussianMixture
    rng = np.random.default_rng(2)
    local = np.stack([rng.normal([0.05, 0.0, 0.0], 0.01, (300, 3)),
                      np.concatenate([rng.normal([0.0, 0.08, 0.0], 0.004, (150, 3)),
                                      rng.normal([0.0, 0.1, 0.03], 0.006, (150, 3))])], axis=1)
    local[::7, 1] = np.nan
    model = SpatialModel.fit(["a", "b"], local, components=3, seed=0)
    query = rng.normal(0.03, 0.05, (9, 3))
    for i in range(2):
        x = local[:, i][~np.isnan(local[:, i, 0])]
        ref = GaussianMixture(3, covariance_type="full", reg_covar=1e-6, random_state=0).fit(x)
        np.testing.assert_allclose(model.log_likelihood(query)[i], ref.score_samples(query), rtol=1e-9)
    again = SpatialModel.from_arrays(model.to_arrays())
    np.testing.assert_array_equal(again.log_likelihood(query), model.log_likelihood(query))


def test_noise_tuning_scores_every_setting_like_the_filters_do():
    # The vectorised grid search must give each setting the likelihood a KalmanBatch run gives it.
    from handcap.labeling.kalman import _innovation_log_likelihoods
    rng = np.random.default_rng(0)
    pos = np.cumsum(np.cumsum(rng.normal(0, 1e-6, (400, 3, 3)), axis=0), axis=0) + rng.normal(0, 3e-4, (400, 3, 3))
    pos[rng.uniform(size=(400, 3)) < 0.05] = np.nan
    pos[100:120, 1] = np.nan  # longer than 10 frames: a restart

    def by_filters(s):
        batch, total = KalmanBatch(s, 3), 0.0
        for z in pos:
            has = ~np.isnan(z[:, 0])
            state, cov = batch.predicted()
            use = has & (batch.age >= 2) & (batch.missed <= 10)
            total += KalmanBatch.log_likelihood(z[use] - state[use, 0], cov[use, 0, 0] + s.measurement).sum()
            lost = batch.missed > 10
            batch.step(np.where((lost & has)[:, None], np.nan, z))
            batch.restart(lost & has, z)
        return total

    jerk, measurement = np.array([10.0, 1e4, 1e6]), np.array([1e-8, 1e-7, 4e-8])
    expected = [by_filters(KalmanSettings(0.01, j, m)) for j, m in zip(jerk, measurement)]
    np.testing.assert_allclose(_innovation_log_likelihoods(0.01, jerk, measurement, pos), expected, rtol=1e-10)
    tuned = KalmanSettings.from_training(pos, 100.0)
    assert np.isclose(np.sqrt(tuned.measurement), 3e-4, rtol=0.5)  # the noise put in
