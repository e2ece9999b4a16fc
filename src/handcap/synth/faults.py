"""Faults of real capture systems, added to clean synthetic markers.

All functions take a ``numpy.random.Generator`` and return new arrays plus a
record of what they did, so the truth file can say which samples are faulty.
"""

from __future__ import annotations

import numpy as np


def burst_dropouts(rng, shape, probability: float, mean_length: float = 5.0) -> np.ndarray:
    """Extra missing samples in bursts (a two-state Markov chain per marker).

    Parameters
    ----------
    shape : (T, M)
    probability : float
        Long-run fraction of samples dropped.
    mean_length : float
        Mean burst length in frames.

    Returns
    -------
    dropped : ndarray (T, M) bool
    """
    n_frames, n_markers = shape
    dropped = np.zeros(shape, bool)
    if probability <= 0 or n_frames == 0:
        return dropped
    stop = 1.0 / max(mean_length, 1.0)
    start = probability * stop / max(1.0 - probability, 1e-9)
    u = rng.random(shape)
    state = rng.random(n_markers) < probability
    for t in range(n_frames):
        state = np.where(state, u[t] >= stop, u[t] < start)
        dropped[t] = state
    return dropped


def swap_labels(rng, positions, rate_per_frame: float, *, max_distance: float = 0.04,
                length=(5, 30)) -> tuple[np.ndarray, list]:
    """Swap the labels of two nearby visible markers for a few frames.

    Parameters
    ----------
    positions : ndarray (T, M, 3)
        Observed positions (NaN missing).
    rate_per_frame : float
        Expected swap events per frame.

    Returns
    -------
    swapped : ndarray (T, M, 3)
    events : list of (start_frame, stop_frame, marker_a, marker_b)
    """
    out = positions.copy()
    events = []
    n_frames, n_markers = positions.shape[:2]
    if rate_per_frame <= 0 or n_markers < 2:
        return out, events
    for t0 in np.flatnonzero(rng.random(n_frames) < rate_per_frame):
        seen = np.flatnonzero(~np.isnan(out[t0, :, 0]))
        if len(seen) < 2:
            continue
        a = rng.choice(seen)
        dist = np.linalg.norm(out[t0, seen] - out[t0, a], axis=1)
        near = seen[(dist > 0) & (dist < max_distance)]
        if len(near) == 0:
            continue
        b = rng.choice(near)
        t1 = min(n_frames, t0 + int(rng.integers(length[0], length[1] + 1)))
        out[t0:t1, [a, b]] = out[t0:t1, [b, a]]
        events.append((int(t0), int(t1), int(a), int(b)))
    return out, events


def ghost_markers(rng, positions, rate_per_frame: float, *, distance=(0.005, 0.025), length=(1, 10),
                  jitter: float = 0.0005) -> tuple[np.ndarray, list]:
    """Ghost markers: false points near real ones, as wrong camera correspondences make.

    Each ghost follows one visible marker at a fixed offset for a few frames.

    Parameters
    ----------
    positions : ndarray (T, M, 3)
    rate_per_frame : float
        Expected new ghosts per frame.

    Returns
    -------
    ghosts : ndarray (T, G, 3)
        One column per ghost, NaN outside its life.
    events : list of (start_frame, stop_frame, marker)
    """
    n_frames = positions.shape[0]
    tracks, events = [], []
    if rate_per_frame > 0:
        for t0 in np.flatnonzero(rng.random(n_frames) < rate_per_frame):
            seen = np.flatnonzero(~np.isnan(positions[t0, :, 0]))
            if len(seen) == 0:
                continue
            m = int(rng.choice(seen))
            t1 = min(n_frames, t0 + int(rng.integers(length[0], length[1] + 1)))
            offset = rng.normal(size=3)
            offset *= rng.uniform(*distance) / np.linalg.norm(offset)
            track = np.full((n_frames, 3), np.nan)
            track[t0:t1] = positions[t0:t1, m] + offset + rng.normal(0, jitter, (t1 - t0, 3))
            tracks.append(track)
            events.append((int(t0), int(t1), m))
    ghosts = np.stack(tracks, axis=1) if tracks else np.zeros((n_frames, 0, 3))
    return ghosts, events
