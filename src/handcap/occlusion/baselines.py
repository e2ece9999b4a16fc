"""The paper's three baselines for occluded markers (section 3.2.1), as pure functions.

* **LK**, last known position: an occluded marker stays where it was last seen.
* **MA**, moving average: it keeps moving at its mean velocity over the last
  third of a second before it was lost (after Piazza et al. 2009).
* **AC**, affine combination: it is an affine combination of the markers still
  seen, with weights fitted on the last frame where it was seen (eq. 3-8,
  ridge-regularised, lambda = 1e-8). Invariant to rigid motions of the hand.

The streaming versions live in :mod:`handcap.occlusion.filler`; the functions
here are shared by it, by the batch gap filler and by the evaluation.

References
----------
Pavllo D, Delahaye M, Porssut T, Herbelin B, Boulic R. Real-time neural network
prediction for handling two-hands mutual occlusions. Comput Graph X 2019;2:100011.
doi:10.1016/j.cagx.2019.100011
"""

from __future__ import annotations

import numpy as np

AC_LAMBDA = 1e-8
MA_WINDOW_S = 1.0 / 3.0


def ac_weights(known, hidden, *, lam: float = AC_LAMBDA) -> np.ndarray:
    """Affine weights that express ``hidden`` markers through ``known`` ones (eq. 8).

    ``W = Y X^T (X X^T + lambda I)^-1`` with homogeneous rows ``[x, y, z, 1]``,
    computed through the equivalent 4 x 4 system ``Y (X^T X + lambda I)^-1 X^T``
    (push-through identity), vectorised over a batch.

    Parameters
    ----------
    known : ndarray (..., N, 3)
        Positions of the markers that stay visible, metres (no NaN).
    hidden : ndarray (..., K, 3)
        Positions of the markers to be expressed, on the same frame.
    lam : float
        Ridge constant (the paper's 1e-8).

    Returns
    -------
    weights : ndarray (..., K, N)
        Each row sums to 1 (up to the ridge term).
    """
    known = np.asarray(known, dtype=np.float64)
    hidden = np.asarray(hidden, dtype=np.float64)
    x = np.concatenate([known, np.ones(known.shape[:-1] + (1,))], axis=-1)
    y = np.concatenate([hidden, np.ones(hidden.shape[:-1] + (1,))], axis=-1)
    gram = np.swapaxes(x, -1, -2) @ x + lam * np.eye(4)
    # Y G^-1 X^T = (G^-1 Y^T)^T X^T; G is symmetric.
    return np.swapaxes(np.linalg.solve(gram, np.swapaxes(y, -1, -2)), -1, -2) @ np.swapaxes(x, -1, -2)


def ac_apply(weights, known) -> np.ndarray:
    """Positions (..., K, 3) of hidden markers from the known ones (..., N, 3) and weights (..., K, N).

    Parameters
    ----------
    weights : ndarray (..., K, N)
        From :func:`ac_weights`.
    known : ndarray (..., N, 3)
        Positions of the visible markers on the current frame, metres (no NaN; an ndarray, not a list).

    Returns
    -------
    ndarray (..., K, 3)
        Metres.
    """
    x = np.concatenate([known, np.ones(known.shape[:-1] + (1,))], axis=-1)
    return (weights @ x)[..., :3]


def ma_velocity(history, rate: float, window_s: float = MA_WINDOW_S) -> np.ndarray:
    """Mean velocity of each marker over the last ``window_s`` seconds of ``history``.

    Parameters
    ----------
    history : ndarray (..., H, M, 3)
        The last H frames before the occlusion (oldest first), metres, NaN where missing.
    rate : float
        Frames per second.

    Returns
    -------
    velocity : ndarray (..., M, 3)
        Metres per frame: (last seen - first seen in the window) / frames between;
        zero where the marker was seen fewer than twice.
    """
    k = max(1, int(round(window_s * rate)))
    window = np.asarray(history, dtype=np.float64)[..., -(k + 1):, :, :]
    seen = ~np.isnan(window[..., 0])
    h = window.shape[-3]
    index = np.arange(h)[:, None]
    first = np.where(seen, index, h).min(axis=-2)
    last = np.where(seen, index, -1).max(axis=-2)
    span = last - first
    take = lambda i: np.take_along_axis(window, np.clip(i, 0, h - 1)[..., None, :, None], axis=-3)[..., 0, :, :]  # noqa: E731
    velocity = (take(last) - take(first)) / np.maximum(span, 1)[..., None]
    return np.where((span > 0)[..., None], velocity, 0.0)
