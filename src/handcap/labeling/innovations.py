"""The Kalman filters' noise search: every setting's one-step innovation log-likelihood over a training take.

:meth:`handcap.labeling.kalman.KalmanSettings.fit` scores a grid of jerk densities and measurement noises
(198 settings) on every marker of the training take; this is most of a labelling model's training time.
"""

from __future__ import annotations

import numpy as np

from handcap.core.compiled import AVAILABLE as COMPILED
from handcap.core.compiled import njit as _njit


def innovation_log_likelihoods(base, jerk, measurement, positions, max_coast: int = 10,
                               per_marker: bool = False) -> np.ndarray:
    """Log-likelihood (C,) of the one-step innovations of trajectories (T, M, 3) under C noise settings
    ((C, M), each marker's own, with ``per_marker``).

    All settings run at once: filters (C, M) restarted after gaps longer than ``max_coast`` frames,
    innovations counted once a filter has had 2 updates. Compiled where numba is installed
    (:func:`likelihoods_compiled`: one loop over frames, markers and settings; a 2,000-frame take of 20
    markers on the 198 settings of the first grid, 0.42 s instead of 1.4-2.1 s), else
    :func:`likelihoods_numpy`; they agree to rounding (tested).

    Parameters
    ----------
    base : KalmanSettings
        The frame time, and the filters' process noise at unit jerk and their restart variances.
    jerk, measurement : ndarray (C,)
        The settings: jerk densities (m^2/s^5) and measurement variances (m^2).
    positions : ndarray (T, M, 3)
        Metres, NaN where missing.
    max_coast : int
    per_marker : bool

    Returns
    -------
    ndarray (C,) or (C, M)
    """
    if not COMPILED:
        return likelihoods_numpy(base, jerk, measurement, positions, max_coast, per_marker)
    dt = base.dt
    pos = np.ascontiguousarray(positions, dtype=np.float64)
    process = np.ascontiguousarray(np.asarray(jerk, dtype=np.float64)[:, None, None] * base.process[None])
    total = likelihoods_compiled(float(dt), process, np.ascontiguousarray(measurement, dtype=np.float64), pos,
                                 int(max_coast), float(base.initial_velocity), float(base.initial_acceleration))
    return total if per_marker else total.sum(axis=1)


@_njit
def likelihoods_compiled(dt, process, measurement, positions, max_coast, initial_velocity, initial_acceleration):
    """The loop of :func:`likelihoods_numpy`, compiled: (C, M) log-likelihoods.

    Parameters
    ----------
    dt : float
        Seconds between frames.
    process : ndarray (C, 3, 3)
        Each setting's process noise covariance of one axis over one frame.
    measurement : ndarray (C,)
        Each setting's measurement variance, m^2.
    positions : ndarray (T, M, 3)
        Metres, NaN where missing.
    max_coast : int
    initial_velocity, initial_acceleration : float
        Variances of a restarted filter's velocity and acceleration.

    Returns
    -------
    ndarray (C, M)
    """
    n_frames, n_markers = positions.shape[0], positions.shape[1]
    n_settings = len(measurement)
    half = 0.5 * dt * dt
    # By marker, then setting: the inner loop over settings walks memory in order.
    state = np.zeros((n_markers, n_settings, 3, 3))  # (position, velocity, acceleration) x axis
    cov = np.zeros((n_markers, n_settings, 6))  # p00, p01, p02, p11, p12, p22
    total = np.zeros((n_markers, n_settings))
    age = np.zeros(n_markers, np.int64)
    missed = np.full(n_markers, 1 << 30, np.int64)
    log_2pi = np.log(2.0 * np.pi)
    for t in range(n_frames):
        for m in range(n_markers):
            z = positions[t, m]
            has = not np.isnan(z[0])
            use = has and age[m] >= 2 and missed[m] <= max_coast
            update = has and missed[m] <= max_coast
            fresh = has and missed[m] > max_coast
            for c in range(n_settings):
                x = state[m, c]
                p = cov[m, c]
                q = process[c]
                r = measurement[c]
                for k in range(3):  # predict: x <- F x
                    x[0, k] += dt * x[1, k] + half * x[2, k]
                    x[1, k] += dt * x[2, k]
                a00 = p[0] + dt * p[1] + half * p[2]
                a01 = p[1] + dt * p[3] + half * p[4]
                a02 = p[2] + dt * p[4] + half * p[5]
                a11 = p[3] + dt * p[4]
                a12 = p[4] + dt * p[5]
                p00 = a00 + dt * a01 + half * a02 + q[0, 0]
                p01 = a01 + dt * a02 + q[0, 1]
                p02 = a02 + q[0, 2]
                p11 = a11 + dt * a12 + q[1, 1]
                p12 = a12 + q[1, 2]
                p22 = p[5] + q[2, 2]
                s = p00 + r
                if update:
                    i0 = z[0] - x[0, 0]
                    i1 = z[1] - x[0, 1]
                    i2 = z[2] - x[0, 2]
                    if use:
                        total[m, c] += -1.5 * (log_2pi + np.log(s)) - 0.5 * (i0 * i0 + i1 * i1 + i2 * i2) / s
                    g0, g1, g2 = p00 / s, p01 / s, p02 / s
                    x[0, 0] += g0 * i0
                    x[0, 1] += g0 * i1
                    x[0, 2] += g0 * i2
                    x[1, 0] += g1 * i0
                    x[1, 1] += g1 * i1
                    x[1, 2] += g1 * i2
                    x[2, 0] += g2 * i0
                    x[2, 1] += g2 * i1
                    x[2, 2] += g2 * i2
                    p00, p01, p02, p11, p12, p22 = (p00 - g0 * p00, p01 - g0 * p01, p02 - g0 * p02,
                                                    p11 - g1 * p01, p12 - g1 * p02, p22 - g2 * p02)
                if fresh:
                    for k in range(3):
                        x[0, k] = z[k]
                        x[1, k] = 0.0
                        x[2, k] = 0.0
                    p00, p01, p02, p11, p12, p22 = r, 0.0, 0.0, initial_velocity, 0.0, initial_acceleration
                p[0], p[1], p[2], p[3], p[4], p[5] = p00, p01, p02, p11, p12, p22
            if has:
                age[m] = 1 if fresh else age[m] + 1
                missed[m] = 0
            else:
                missed[m] += 1
    return total.T


def likelihoods_numpy(base, jerk, measurement, positions, max_coast: int = 10, per_marker: bool = False) -> np.ndarray:
    """:func:`innovation_log_likelihoods` in numpy, without numba.

    The filter is written out by components (arrays (C, M) for each entry of
    the symmetric covariance, (C, M, 3) for the state), not as 3 x 3 products:
    about 30 times faster on a take of 22 markers.

    Parameters
    ----------
    base : KalmanSettings
    jerk, measurement : ndarray (C,)
    positions : ndarray (T, M, 3)
    max_coast : int
    per_marker : bool

    Returns
    -------
    ndarray (C,) or (C, M)
    """
    dt = base.dt
    q = jerk[:, None, None, None] * base.process  # (C, 1, 3, 3)
    q00, q01, q02, q11, q12, q22 = (q[..., i, j] for i, j in ((0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2)))
    r = measurement[:, None]  # (C, 1)
    n_settings, n_markers = len(jerk), positions.shape[1]
    shape = (n_settings, n_markers)
    pos, vel, acc = (np.zeros(shape + (3,)) for _ in range(3))
    p00, p01, p02, p11, p12, p22 = (np.zeros(shape) for _ in range(6))
    age = np.zeros(n_markers, dtype=np.int64)
    missed = np.full(n_markers, 1 << 30)
    total = np.zeros(shape)
    half = 0.5 * dt * dt
    for z in positions:
        has = ~np.isnan(z[:, 0])
        # predict: x <- F x, P <- F P F' + Q, F = [[1, dt, dt^2/2], [0, 1, dt], [0, 0, 1]]
        pos = pos + dt * vel + half * acc
        vel = vel + dt * acc
        a00, a01, a02 = p00 + dt * p01 + half * p02, p01 + dt * p11 + half * p12, p02 + dt * p12 + half * p22
        a11, a12 = p11 + dt * p12, p12 + dt * p22
        p00, p01, p02 = a00 + dt * a01 + half * a02 + q00, a01 + dt * a02 + q01, a02 + q02
        p11, p12, p22 = a11 + dt * a12 + q11, a12 + q12, p22 + q22
        use = has & (age >= 2) & (missed <= max_coast)
        s = p00 + r  # (C, M)
        update = has & (missed <= max_coast)
        innovation = np.where(update[:, None], np.where(has[:, None], z, 0.0) - pos, 0.0)  # (C, M, 3)
        if use.any():
            ll = -1.5 * np.log(2 * np.pi * s) - 0.5 * (innovation**2).sum(-1) / s
            total += np.where(use, ll, 0.0)
        if update.any():
            g0, g1, g2 = (np.where(update, p / s, 0.0) for p in (p00, p01, p02))
            pos = pos + g0[..., None] * innovation
            vel = vel + g1[..., None] * innovation
            acc = acc + g2[..., None] * innovation
            p00, p01, p02, p11, p12, p22 = (p00 - g0 * p00, p01 - g0 * p01, p02 - g0 * p02, p11 - g1 * p01,
                                            p12 - g1 * p02, p22 - g2 * p02)
        fresh = has & (missed > max_coast)
        if fresh.any():
            pos = np.where(fresh[:, None], z, pos)
            vel, acc = (np.where(fresh[:, None], 0.0, v) for v in (vel, acc))
            p00 = np.where(fresh, r, p00)
            p01, p02, p12 = (np.where(fresh, 0.0, p) for p in (p01, p02, p12))
            p11, p22 = np.where(fresh, base.initial_velocity, p11), np.where(fresh, base.initial_acceleration, p22)
        age = np.where(has, age + 1, age)
        age[fresh] = 1
        missed = np.where(has, 0, missed + 1)
    return total if per_marker else total.sum(axis=1)
