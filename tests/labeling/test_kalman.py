"""The constant-acceleration Kalman filters (handcap.labeling.kalman) against the textbook equations."""

import numpy as np
import pytest
from scipy.stats import multivariate_normal

from handcap.labeling import KalmanBatch, KalmanSettings
from handcap.labeling.innovations import COMPILED, innovation_log_likelihoods, likelihoods_numpy
from handcap.labeling.kalman import JERKS, SIGMAS_MM


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


def test_noise_tuning_scores_every_setting_like_the_filters_do():
    # The vectorised grid search must give each setting the likelihood a KalmanBatch run gives it.
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
    unit = KalmanSettings(0.01, 1.0, 1.0)
    for score in (innovation_log_likelihoods, likelihoods_numpy):  # compiled (with numba), and numpy
        np.testing.assert_allclose(score(unit, jerk, measurement, pos), expected, rtol=1e-10)
    tuned = KalmanSettings.from_training(pos, 100.0)
    assert np.isclose(np.sqrt(tuned.measurement), 3e-4, rtol=0.5)  # the noise put in


def test_noise_tuning_compiled_and_in_numpy_agree():
    # Gaps, restarts after long gaps, a marker never seen, markers seen once: each (setting, marker) the same.
    if not COMPILED:
        pytest.skip("numba is not installed (extra 'stream'): the noise tuning runs in numpy only")
    rng = np.random.default_rng(3)
    pos = np.cumsum(np.cumsum(rng.normal(0, 2e-6, (500, 6, 3)), axis=0), axis=0) + rng.normal(0, 2e-4, (500, 6, 3))
    pos[rng.uniform(size=(500, 6)) < 0.1] = np.nan
    pos[200:240, 2] = np.nan
    pos[:, 4] = np.nan
    pos[:-1, 5] = np.nan
    sigmas, jerks = np.asarray(SIGMAS_MM) * 1e-3, np.asarray(JERKS)
    measurement, jerk = np.repeat(sigmas**2, len(jerks)), np.tile(jerks, len(sigmas))
    numpy_ll = likelihoods_numpy(KalmanSettings(0.01, 1.0, 1.0), jerk, measurement, pos, 10, per_marker=True)
    compiled = innovation_log_likelihoods(KalmanSettings(0.01, 1.0, 1.0), jerk, measurement, pos, per_marker=True)
    assert compiled.shape == (len(jerk), 6) and (compiled[:, 4:] == 0).all() and (compiled[:, 0] != 0).all()
    np.testing.assert_allclose(compiled, numpy_ll, rtol=1e-12, atol=1e-9)


def _smooth_tracks(seed=0, frames=600, markers=4, noise=3e-4, jerk=30.0):
    """Markers driven by white jerk of density ``jerk`` (m^2/s^5) at 100 Hz, seen with ``noise`` metres of noise."""
    rng = np.random.default_rng(seed)
    dt = 0.01
    acceleration = np.cumsum(rng.normal(0, np.sqrt(jerk * dt), (frames, markers, 3)), axis=0)
    velocity = np.cumsum(acceleration * dt, axis=0)
    return np.cumsum(velocity * dt, axis=0) + rng.normal(0, noise, (frames, markers, 3))


def test_tuning_finds_the_noise_put_in_inside_the_grid_and_warns_of_nothing():
    tuned = KalmanSettings.from_training(_smooth_tracks(), 100.0)
    assert np.isclose(np.sqrt(tuned.measurement), 3e-4, rtol=0.3)
    assert 10 <= tuned.jerk <= 100 and tuned.edge_warning() == ""


def test_a_noise_below_the_first_grid_is_found_on_the_wider_one():
    # 0.02 mm of noise: below the first grid's 0.05 mm, found on the wider grid, which still goes lower.
    tuned = KalmanSettings.from_training(_smooth_tracks(noise=2e-5), 100.0)
    assert np.isclose(np.sqrt(tuned.measurement), 2e-5, rtol=0.5) and tuned.edge_warning() == ""


def test_tracks_that_jump_or_are_not_in_metres_are_a_warning():
    tracks = _smooth_tracks() + np.array([0.0, 0.05, 0.1, 0.15])[None, :, None]
    swapped = tracks.copy()
    swapped[::2, [0, 1]] = tracks[::2, [1, 0]]  # two labels swapped back and forth every other frame
    for bad in (swapped, tracks * 1000.0):  # and millimetres read as metres
        line = KalmanSettings.from_training(bad, 100.0).edge_warning()
        assert "at the edge of what is searched" in line and "Check the training take" in line
