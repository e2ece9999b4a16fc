"""The take's own recent past as a correction to the marker predictor (beyond the paper).

The filler's prediction of an occluded marker is the network's output plus the
offset that makes it continuous at the start of the gap (section 3.2.2). A
network trained on other hands (synthetic ones, say) is wrong in a way that is
the take's own: this subject's fingers, this glove, this placement. Just before
the gap that error is measured on every frame where the now-hidden marker was
still seen. This module fits it there: over the last :data:`HISTORY_S` seconds,
the network's error on each hidden marker (true minus predicted, in the hand's
registered frame, with the visible set of the gap) is regressed linearly on the
visible markers' registered positions, by ridge regression through the frame
the offset was taken on. In the gap the correction is then

    local[hidden] = network(local) + offset + (local[visible] - reference) @ W

which is zero on the reference frame (no jump) and grows only as the visible
markers move away from where they were. No weight of the network changes and
nothing but frames before the gap is used, so it runs online; the streaming
filler applies it once :data:`DELAY_FRAMES` frames of the gap have passed.

Measured on the real glove (every frame of 0.5 s gaps, NN/AC, the shipped network,
trained on synthetic takes only): 0.68 without, 0.53 with. The settings were chosen
on synthetic takes of unseen subjects (NN/AC over 5 motions; 8 motions x 2 seeds for
the last pair): history 1 s 0.45, 2 s 0.40, 4 s 0.41, 8 s 0.41 (2 s 0.46 and 4 s 0.47
on the larger set; the network alone 0.62); ridge at 4 s: (0.3 mm)^2 0.41, (1 mm)^2
0.41, (1.7 mm)^2 0.42, (3.2 mm)^2 0.44.
"""

from __future__ import annotations

import numpy as np

from handcap.core.errors import HandcapError
from handcap.occlusion.register import apply_registration

#: Seconds of the take before a gap that the correction learns from.
HISTORY_S = 2.0
#: Seconds between the past frames it uses (every frame gave the same figures at 100 Hz, four times the work).
HISTORY_STEP_S = 0.04
#: Ridge penalty, square metres per frame and coordinate: visible markers' movements well under a
#: millimetre are treated as noise, not as evidence of how the hidden marker moves.
RIDGE = 1e-6
#: Fewest past frames (with the hidden marker seen) worth a correction.
MIN_FRAMES = 5
#: Frames of a gap without the correction: the streaming filler learns it one stage a frame
#: (registration, network, regression) so that no frame pays for all of it (about 0.45 ms on 2 cores).
#: Near the gap's start the visible markers have hardly moved, so the correction is small there anyway.
DELAY_FRAMES = 3


def check_history(history_s) -> float:
    """``history_s`` as seconds, or one clear error.

    Parameters
    ----------
    history_s : float
        Seconds of history; 0 switches the correction off.

    Returns
    -------
    float

    Raises
    ------
    HandcapError
        Not a number, negative, NaN or infinite.
    """
    if isinstance(history_s, bool) or not isinstance(history_s, (int, float, np.number)) or not (
            0 <= history_s < np.inf):
        raise HandcapError(f"the history must be a non-negative, finite number of seconds, got {history_s!r}")
    return float(history_s)


def history_frames(rate: float, history_s: float = HISTORY_S) -> tuple:
    """How many frames the filler keeps and every how many it uses.

    Parameters
    ----------
    rate : float
        Frames per second.
    history_s : float
        Seconds of history; 0 switches the correction off.

    Returns
    -------
    keep : int
        Frames to remember (0 when off).
    step : int
        Use every ``step``-th of them.
    """
    keep = max(int(round(history_s * rate)), 0)
    return keep, max(int(round(HISTORY_STEP_S * rate)), 1)


def fit_correction(features, errors, seen, *, ridge: float = RIDGE) -> np.ndarray:
    """Ridge regression of the network's error on the hidden markers over the visible ones' movement.

    Parameters
    ----------
    features : ndarray (F, 3V)
        Registered positions of the V visible markers on F past frames, minus the reference
        frame's, metres.
    errors : ndarray (F, K, 3)
        The K hidden markers' registered positions minus the network's output and the offset, metres
        (anything where not ``seen``).
    seen : ndarray (F, K) bool
        Hidden markers seen on each past frame.
    ridge : float
        Penalty, square metres per frame and coordinate.

    Returns
    -------
    weights : ndarray (3V, 3K)
        The correction is ``features_now.ravel() @ weights`` (flattened (K, 3)), metres. Columns of a
        marker seen on fewer than :data:`MIN_FRAMES` frames are zero.
    """
    n_features, k = features.shape[1], errors.shape[1]
    weights = np.zeros((n_features, 3 * k))
    groups = [np.arange(k)] if seen.all() else [[j] for j in range(k)]  # one solve when every frame sees all
    for cols in groups:
        use = seen[:, cols[0]]
        n = int(use.sum())
        if n < MIN_FRAMES:
            continue
        x = features[use]
        gram = x.T @ x
        gram[np.diag_indices(n_features)] += ridge * n
        target = errors[use][:, cols].reshape(n, -1)
        weights[:, 3 * cols[0]:3 * cols[-1] + 3] = np.linalg.solve(gram, x.T @ target)
    return weights


def correction_stages(past, visible, reference, offset, register, predict, *, ridge: float = RIDGE):
    """:func:`history_correction` as a generator of three stages (registration, network, regression).

    The streaming filler runs one stage a frame (:data:`DELAY_FRAMES`), with its own fast registration and
    network; :func:`history_correction` runs them at once.

    Parameters
    ----------
    past, visible, reference, offset, ridge
        As :func:`history_correction`.
    register : callable (frames (F, M, 3), visible (M,)) -> ndarray (F, M, 3)
        The frames registered with ``visible`` (template frame, metres).
    predict : callable (local (F, M, 3), visible (M,)) -> ndarray (F, K, 3)
        The network's output for the K hidden markers (template frame, metres).

    Yields
    ------
    None
        After the registration and after the network.

    Returns
    -------
    weights : ndarray (3V, 3K)
        See :func:`fit_correction` (the generator's ``StopIteration.value``).
    """
    visible = np.asarray(visible, dtype=bool)
    hidden = np.flatnonzero(~visible)
    seen = ~np.isnan(np.asarray(past, dtype=np.float64)).any(axis=-1)
    rows = seen[:, visible].all(axis=1) & seen[:, hidden].any(axis=1)
    if np.count_nonzero(rows) < MIN_FRAMES or not len(hidden):
        return np.zeros((3 * int(visible.sum()), 3 * len(hidden)))
    frames = past[rows]
    local = register(frames, visible)
    yield
    errors = local[:, hidden] - predict(local, visible) - offset[hidden]
    yield
    features = (local[:, visible] - reference[visible]).reshape(len(frames), -1)
    return fit_correction(features, errors, seen[rows][:, hidden], ridge=ridge)


def history_correction(predictor, past, visible, reference, offset, *, ridge: float = RIDGE):
    """The linear correction of the network's error on the hidden markers, learned from past frames.

    Parameters
    ----------
    predictor : MarkerPredictor
    past : ndarray (P, M, 3)
        Earlier frames of the take, world metres, NaN where a marker was not seen.
    visible : ndarray (M,) bool
        The markers seen now; the others are the hidden ones to correct.
    reference : ndarray (M, 3)
        The frame the offset was taken on, registered with ``visible`` (template frame, metres).
    offset : ndarray (M, 3)
        The filler's offsets (reference minus network, template frame, metres); rows of the
        hidden markers are used.
    ridge : float
        Penalty, square metres per frame and coordinate.

    Returns
    -------
    weights : ndarray (3V, 3K)
        With V visible and K hidden markers: see :func:`fit_correction`. All zero when fewer than
        :data:`MIN_FRAMES` frames show every visible marker and a hidden one.
    """
    def register(frames, shown):
        shown = np.broadcast_to(shown, frames.shape[:2])
        return apply_registration(frames, *predictor.register(frames, shown))

    def predict(local, shown):
        return predictor.predict_local(local, np.broadcast_to(shown, local.shape[:2]))[:, ~shown]

    stages = correction_stages(past, visible, reference, offset, register, predict, ridge=ridge)
    while True:
        try:
            next(stages)
        except StopIteration as done:
            return done.value
