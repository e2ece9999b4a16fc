"""Step 2 of the cleaning: spikes, samples far from a robust local fit of their neighbours in time.

In a sliding window every sample of a marker is compared with a local quadratic fitted to its neighbours
(itself left out), and removed when it deviates by more than ``z`` robust standard deviations (1.4826 x the
median absolute residual of the samples within two window lengths) and by more than ``floor`` metres; see
:func:`remove_window_outliers`.
"""

from __future__ import annotations

import numpy as np

from handcap.core.checks import check_odd_window, check_positions, check_positive
from handcap.core.errors import HandcapError
from handcap.multiview.clean_groups import BLOCK_ELEMENTS

WINDOW = 15
Z = 5.0
FLOOR = 0.002
MAD_TO_STD = 1.4826


def remove_window_outliers(positions, *, window: int = WINDOW, z: float = Z, floor: float = FLOOR,
                           iterations: int = 5) -> tuple[np.ndarray, np.ndarray]:
    """Remove spikes: samples far from a robust local fit of their neighbours in time.

    For each sample, a quadratic in time is fitted by weighted least squares to
    the other samples of its window (tricube weights), and the residual is
    divided by its standard error (``sqrt(1 + var(prediction))``, so a
    prediction made from one side only is not held to the same tolerance as
    one made from both). The robust standard deviation of each coordinate is
    1.4826 x the median absolute residual of the samples within two window
    lengths (the median of a single window's 14 values is too unsteady and
    gives false removals). A
    sample is removed when a coordinate's residual exceeds both
    ``z`` x that deviation and ``floor``. The fit and the test are repeated
    without the removed samples (so a spike does not condemn its neighbours)
    until nothing changes, at most ``iterations`` times.

    Parameters
    ----------
    positions : ndarray of shape (T, M, 3)
        Metres, NaN where missing.
    window : int
        Frames in the window, odd, at least 7; samples with fewer than 6
        neighbours in it are not tested.
    z : float
        Threshold in robust standard deviations.
    floor : float
        Metres; smaller deviations are never removed (noise-free stretches have a
        tiny spread).
    iterations : int

    Returns
    -------
    cleaned : ndarray of shape (T, M, 3)
    removed : ndarray of bool, shape (T, M)
    """
    positions = check_positions(positions)
    window = check_odd_window(window)
    z = check_positive(z, "z (robust standard deviations)")
    floor = float(floor)
    if not np.isfinite(floor) or floor < 0:
        raise HandcapError(f"floor must be a non-negative distance in metres, got {floor}")
    n_frames, n_markers = positions.shape[:2]
    removed = np.zeros((n_frames, n_markers), bool)
    if n_frames == 0:
        return positions.copy(), removed
    block = max(1, BLOCK_ELEMENTS // max(1, n_frames * 6 * window))  # the spread's windows are twice as long
    for start in range(0, n_markers, block):
        cols = slice(start, start + block)
        removed[:, cols] = _window_flags(positions[:, cols], window, z, floor, int(iterations))
    cleaned = positions.copy()
    cleaned[removed] = np.nan
    return cleaned, removed


def _windows(values, half, fill=None):
    """(T, ..., W) windows of ``values`` (T, ...) centred on each frame, padded with ``fill`` (NaN, False)."""
    if fill is None:
        fill = False if values.dtype == bool else np.nan
    pad = np.full((len(values) + 2 * half,) + values.shape[1:], fill, values.dtype)
    pad[half:half + len(values)] = values
    return np.lib.stride_tricks.sliding_window_view(pad, 2 * half + 1, axis=0)


def _nanmedian_last(values):
    """Median over the last axis ignoring NaN (NaN where all are), and the count used."""
    count = (~np.isnan(values)).sum(axis=-1)
    ordered = np.sort(values, axis=-1)  # NaN last
    lo = np.take_along_axis(ordered, np.maximum(count - 1, 0)[..., None] // 2, axis=-1)[..., 0]
    hi = np.take_along_axis(ordered, (count // 2)[..., None], axis=-1)[..., 0]
    median = np.where(count > 0, 0.5 * (lo + hi), np.nan)
    return median, count


def _window_flags(x, window, z, floor, iterations, min_neighbours=6):
    """Outlier flags (T, m) of trajectories ``x`` (T, m, 3)."""
    present = ~np.isnan(x[..., 0])
    flags = np.zeros_like(present)
    cols = np.arange(x.shape[1])
    for _ in range(max(1, iterations)):
        # Flags only change the windows of their own marker: markers whose flags stayed are done.
        new = _window_test(x[:, cols], present[:, cols], flags[:, cols], window // 2, z, floor, min_neighbours)
        changed = (new != flags[:, cols]).any(axis=0)
        flags[:, cols] = new
        cols = cols[changed]
        if len(cols) == 0:
            break
    return flags


def _window_test(x, present, flags, half, z, floor, min_neighbours):
    """One pass of the test: flags (T, m) of ``x`` (T, m, 3) given the samples flagged so far."""
    tau = np.arange(-half, half + 1, dtype=np.float64)
    kernel = (1.0 - (np.abs(tau) / (half + 1)) ** 3) ** 3
    kernel[half] = 0.0  # leave the sample itself out
    powers = tau[:, None] ** np.arange(5)[None, :]  # (W, 5)
    kept = present & ~flags
    keep = _windows(kept, half)  # (T, m, W)
    w = keep * kernel
    s, s2 = w @ powers, (w * w) @ powers  # (T, m, 5): weighted moments of tau
    idx = np.arange(3)[:, None] + np.arange(3)[None, :]
    normal, spread = s[..., idx], s2[..., idx]  # (T, m, 3, 3)
    testable = present & (keep.sum(axis=-1) >= min_neighbours)
    coef = np.zeros(present.shape + (3,))
    if testable.any():
        e0 = np.broadcast_to(np.array([1.0, 0.0, 0.0]), (int(testable.sum()), 3))
        coef[testable] = np.linalg.solve(normal[testable], e0[..., None])[..., 0]
    # The prediction at tau = 0 is e0' A^-1 b = coef' b, and its variance (unit noise) coef' B coef.
    b = (_windows(np.where(np.isnan(x), 0.0, x), half, 0.0) * w[:, :, None, :]) @ powers[:, :3]  # (T, m, 3, 3)
    pred = np.einsum("tmp,tmcp->tmc", coef, b)
    var = np.einsum("tmp,tmpq,tmq->tm", coef, spread, coef)
    dev = np.abs(x - pred) / np.sqrt(1.0 + var)[..., None]
    dev[~testable] = np.nan
    # The spread is taken over twice the window: a median of 14 values is too unsteady.
    median, count = _nanmedian_last(_windows(np.where(kept[..., None], dev, np.nan), 2 * half))
    limit = np.maximum(z * MAD_TO_STD * median, floor)
    return testable & (count >= min_neighbours).all(axis=-1) & (dev > limit).any(axis=-1)


__all__ = ["FLOOR", "MAD_TO_STD", "WINDOW", "Z", "remove_window_outliers"]
