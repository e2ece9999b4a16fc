"""The paper's evaluation protocol (section 6.2, Tables 3 and 4).

Occlude k = 1..4 random markers at a random time of the test set for d =
0.1, 0.2, 0.5, 1.0 or 2.0 s, and measure the error of the occluded markers on
the last frame before they come back; average over many such windows and 5
seeds. Windows are drawn where every marker is really seen from a third of a
second before the occlusion (the moving average's history) to its last frame,
so the ground truth is known and exactly k markers are hidden.

Each method's prediction on the last frame is computed in closed form for all
windows at once; the streaming filler gives the same numbers frame by frame
(tested), since it keeps its state (velocities, affine weights, offsets) from
the frame before the occlusion.
"""

from __future__ import annotations

import numpy as np

from handcap.core.errors import HandcapError
from handcap.hand import OpenHand
from handcap.occlusion.baselines import MA_WINDOW_S, ac_apply, ac_weights, ma_velocity
from handcap.occlusion.history import DELAY_FRAMES, HISTORY_S, history_correction, history_frames
from handcap.occlusion.register import apply_registration, undo_registration

DURATIONS = (0.1, 0.2, 0.5, 1.0, 2.0)
COUNTS = (1, 2, 3, 4)
METHODS = ("lk", "ma", "ac", "nn")


def occlusion_windows(visible, rate: float, duration: float, k: int, n: int, rng):
    """Random occlusion windows on frames where every marker is seen.

    Parameters
    ----------
    visible : ndarray (T, M) bool
    rate : float
        Frames per second.
    duration : float
        Seconds the markers stay hidden.
    k : int
        Markers hidden at once.
    n : int
        Windows to draw (with replacement among the valid start frames).
    rng : numpy Generator

    Returns
    -------
    starts : ndarray (n,) int
        First hidden frame of each window.
    frames : int
        Frames hidden (the last one, ``starts + frames - 1``, is scored).
    hidden : ndarray (n, M) bool
    """
    t, m = visible.shape
    if not 1 <= k < m - 2:
        raise HandcapError(f"cannot hide {k} of {m} markers and keep 3 to register the hand")
    frames = max(1, int(round(duration * rate)))
    history = int(round(MA_WINDOW_S * rate)) + 1
    full = visible.all(axis=1).astype(np.int64)
    span = history + frames
    if t < span:
        raise HandcapError(f"the test take ({t} frames) is shorter than one {duration:g} s window")
    counts = np.convolve(full, np.ones(span, dtype=np.int64), mode="valid")  # counts[i]: frames i..i+span-1
    valid = np.flatnonzero(counts == span) + history
    if not len(valid):
        raise HandcapError(f"no {duration:g} s stretch of the test take has every marker seen")
    starts = rng.choice(valid, size=n)
    keys = rng.random((n, m))
    hidden = np.argsort(np.argsort(keys, axis=1), axis=1) < k
    return starts, frames, hidden


def predict_windows(method: str, positions, rate: float, starts, frames: int, hidden, predictor=None,
                    *, offset: bool = True) -> np.ndarray:
    """Each method's positions of every marker on the last hidden frame of each window.

    Parameters
    ----------
    method : {"lk", "ma", "ac", "nn"}
    positions : ndarray (T, M, 3)
        The complete take, metres.
    rate : float
    starts : ndarray (n,) int
    frames : int
    hidden : ndarray (n, M) bool
        Same count in every row.
    predictor : MarkerPredictor, for ``nn``
    offset : bool
        ``nn`` only: cancel the discontinuity at the start of the occlusion (section 3.2.2).

    Returns
    -------
    predicted : ndarray (n, M, 3)
        Metres; the hidden markers are predicted, the others are the truth.
    """
    return predict_gap_frames(method, positions, rate, starts, frames, hidden, predictor, offset=offset,
                              steps=[frames - 1])[:, 0]


def predict_gap_frames(method: str, positions, rate: float, starts, frames: int, hidden, predictor=None,
                       *, offset: bool = True, steps=None, history_s: float = HISTORY_S) -> np.ndarray:
    """Each method's positions of every marker on hidden frames of each window.

    Parameters
    ----------
    method, positions, rate, starts, frames, hidden, predictor, offset
        As :func:`predict_windows`.
    steps : sequence of int (F,), optional
        Which hidden frames, counted from the first (0) to the last (``frames - 1``);
        default all of them.
    history_s : float
        Seconds before each window from which ``nn`` learns its error, as the filler does
        (:mod:`~handcap.occlusion.history`); 0 (or ``offset=False``) leaves it out.

    Returns
    -------
    predicted : ndarray (n, F, M, 3)
        Metres; the hidden markers are predicted, the others are the truth.
    """
    positions = np.asarray(positions, dtype=np.float64)
    steps = np.arange(frames) if steps is None else np.asarray(steps, dtype=np.int64)
    before = positions[starts - 1]
    at = positions[starts[:, None] + steps[None]]  # (n, F, M, 3)
    hidden_f = np.broadcast_to(hidden[:, None], at.shape[:3])
    out = at.copy()
    if method == "lk":
        out[hidden_f] = np.broadcast_to(before[:, None], at.shape)[hidden_f]
    elif method == "ma":
        k = int(round(MA_WINDOW_S * rate))
        history = positions[(starts - 1)[:, None] + np.arange(-k, 1)[None]]
        moved = before[:, None] + ma_velocity(history, rate)[:, None] * (steps + 1)[None, :, None, None]
        out[hidden_f] = moved[hidden_f]
    elif method == "ac":
        n, m = hidden.shape
        order = np.argsort(hidden, axis=1, kind="stable")  # shown markers first
        n_hidden = int(hidden[0].sum())
        known_i, hidden_i = order[:, : m - n_hidden], order[:, m - n_hidden:]
        pick = lambda a, i: np.take_along_axis(a, i[..., None], axis=-2)  # noqa: E731
        w = ac_weights(pick(before, known_i), pick(before, hidden_i))
        known_at = pick(at, np.broadcast_to(known_i[:, None], at.shape[:2] + known_i.shape[1:]))
        idx = np.broadcast_to(hidden_i[:, None, :, None], at.shape[:2] + hidden_i.shape[1:] + (3,))
        np.put_along_axis(out, idx, ac_apply(w[:, None], known_at), axis=2)
    elif method == "nn":
        if predictor is None:
            raise HandcapError("the nn method needs a trained marker predictor")
        shown = ~hidden
        pose_before = predictor.register(before, shown)
        local_before = apply_registration(before, *pose_before)
        correction = local_before - predictor.predict_local(local_before, shown) if offset else 0.0
        shown_f = np.broadcast_to(shown[:, None], at.shape[:3])
        pose = predictor.register(at, shown_f)
        measured = apply_registration(at, *pose)
        local = predictor.predict_local(measured, shown_f)
        if offset:
            local = local + correction[:, None]
            keep, step = history_frames(rate, history_s)
            late = steps >= DELAY_FRAMES  # the filler learns the correction over the gap's first frames
            for i in range(len(starts) if keep and late.any() else 0):
                past = positions[max(starts[i] - keep, 0):starts[i]][::-1][::step][::-1]
                w = history_correction(predictor, past, shown[i], local_before[i], correction[i])
                change = (measured[i][late][:, shown[i]] - local_before[i][shown[i]]).reshape(late.sum(), -1) @ w
                local[i, late[:, None] & hidden[i][None]] += change.reshape(-1, 3)
        world = undo_registration(local, *pose)
        out[hidden_f] = world[hidden_f]
    else:
        raise HandcapError(f"unknown method {method!r}; choose one of {', '.join(METHODS)}")
    return out


def marker_error_table(positions, rate: float, predictor=None, *, methods=METHODS, counts=COUNTS,
                       durations=DURATIONS, seeds=range(5), windows: int = 500) -> dict:
    """Table 3: mean error of the occluded markers on the last frame before re-entry.

    Parameters
    ----------
    positions : ndarray (T, M, 3)
        The test take, metres, NaN where missing.
    rate : float
    predictor : MarkerPredictor, optional
        Needed for ``nn``.
    methods, counts, durations : sequences
    seeds : iterable of int
    windows : int
        Windows per seed and cell.

    Returns
    -------
    table : dict
        ``{method: ndarray (len(counts), len(durations))}`` of mean errors, metres.
        Also ``"nn-raw"`` (no discontinuity offset) when ``nn`` is asked for.
    """
    positions = np.asarray(positions, dtype=np.float64)
    visible = ~np.isnan(positions).any(axis=-1)
    names = list(methods) + (["nn-raw"] if "nn" in methods else [])
    table = {name: np.zeros((len(counts), len(durations))) for name in names}
    seeds = list(seeds)
    for seed in seeds:
        for i, k in enumerate(counts):
            for j, d in enumerate(durations):
                rng = np.random.default_rng([seed, k, j])
                starts, frames, hidden = occlusion_windows(visible, rate, d, k, windows, rng)
                truth = positions[starts + frames - 1][hidden]
                for name in names:
                    method = "nn" if name == "nn-raw" else name
                    predicted = predict_windows(method, positions, rate, starts, frames, hidden, predictor,
                                                offset=name != "nn-raw")
                    table[name][i, j] += np.linalg.norm(predicted[hidden] - truth, axis=-1).mean() / len(seeds)
    return table


def gap_error_table(positions, rate: float, predictor=None, *, methods=METHODS, counts=COUNTS,
                    duration: float = 0.5, seeds=range(5), windows: int = 200, history_s: float = HISTORY_S) -> dict:
    """Mean error over every hidden frame of whole gaps (issue 14's measure), not only the last one.

    A gap filler must be right all the way through a gap: this scores each of the
    ``duration * rate`` hidden frames of every window (the same windows as
    :func:`marker_error_table` draws).

    Parameters
    ----------
    positions : ndarray (T, M, 3)
        The test take, metres, NaN where missing.
    rate : float
    predictor : MarkerPredictor, optional
        Needed for ``nn``.
    methods, counts : sequences
    duration : float
        Length of every gap, seconds.
    seeds : iterable of int
    windows : int
        Windows per seed and count.
    history_s : float
        The history correction of ``nn`` (see :func:`predict_gap_frames`); 0 leaves it out.

    Returns
    -------
    table : dict
        ``{method: ndarray (len(counts),)}`` of mean errors over every hidden marker of every hidden
        frame, metres.
    """
    positions = np.asarray(positions, dtype=np.float64)
    visible = ~np.isnan(positions).any(axis=-1)
    table = {name: np.zeros(len(counts)) for name in methods}
    seeds = list(seeds)
    for seed in seeds:
        for i, k in enumerate(counts):
            rng = np.random.default_rng([seed, k, 1000])
            starts, frames, hidden = occlusion_windows(visible, rate, duration, k, windows, rng)
            truth = positions[starts[:, None] + np.arange(frames)[None]]
            hidden_f = np.broadcast_to(hidden[:, None], truth.shape[:3])
            for name in methods:
                predicted = predict_gap_frames(name, positions, rate, starts, frames, hidden, predictor,
                                               history_s=history_s)
                error = np.linalg.norm(predicted[hidden_f] - truth[hidden_f], axis=-1).mean()
                table[name][i] += error / len(seeds)
    return table


#: The finger joints of the paper's end-to-end error (p1, p2, p3 of every finger: the two
#: distal joints and the tip), as indices into the 21 joints of the File contracts.
FINGER_JOINTS = (2, 3, 5, 6, 8, 9, 11, 12, 14, 15, 16, 17, 18, 19, 20)


def joints_from_pose(phi, global_orient, transl, betas, side: str) -> np.ndarray:
    """The 21 joints (..., 21, 3) of the OpenHand in a pose, metres.

    Parameters
    ----------
    phi : ndarray (..., 27)
        Anatomical angles, radians.
    global_orient : ndarray (..., 3)
        Axis-angle of the wrist, radians.
    transl : ndarray (..., 3)
        Translation, metres.
    betas : ndarray (10,) or (..., 10)
        Shape values.
    side : {"right", "left"}
        A new :class:`~handcap.hand.OpenHand` of this side is loaded on every call.

    Returns
    -------
    ndarray (..., 21, 3)
        Metres: 16 MANO joints, then the tips of thumb, index, middle, ring, pinky.
    """
    return OpenHand(side).forward(betas, global_orient, transl=transl, phi=phi, vertices=False).joints


def _joint_errors(model, markers, take, frames, visible=None):
    phi, orient, transl = model.regressor.predict(markers, visible)
    joints = joints_from_pose(phi, orient, transl, take.betas, take.side)
    error = np.linalg.norm(joints - take.joints[frames], axis=-1)
    return error[..., list(FINGER_JOINTS)].mean(), error.mean()


def joint_error_table(takes, model, *, counts=COUNTS, durations=DURATIONS, seeds=range(5),
                      windows: int = 200) -> dict:
    """Table 4: end-to-end joint position error of the full pipeline (markers -> fill -> pose).

    Parameters
    ----------
    takes : sequence of PosedTake
        Test takes with true ``joints`` and ``betas`` (synthetic captures), of the model's side.
    model : OcclusionModel
        With a joint regressor.
    counts, durations, seeds, windows
        As :func:`marker_error_table` (windows per take, seed and cell).

    Returns
    -------
    dict
        ``none_fingers``, ``none_all``: mean error with no occlusion over every frame (metres), on the
        finger joints (the paper's measure) and on all 21 joints; ``fingers``, ``all``: ndarray
        (len(counts), len(durations)) with k markers hidden for d seconds, on the last hidden frame.
    """
    if model.regressor is None:
        raise HandcapError("the model has no joint regressor (train it with poses)")
    seeds = list(seeds)
    out = {"fingers": np.zeros((len(counts), len(durations))), "all": np.zeros((len(counts), len(durations)))}
    none_f, none_a = [], []
    for take in takes:
        positions = take.positions[:, [take.names.index(n) for n in model.names]]
        visible = ~np.isnan(positions).any(axis=-1)
        full = np.flatnonzero(visible.all(axis=1))
        f, a = _joint_errors(model, positions[full], take, full)
        none_f.append(f)
        none_a.append(a)
        for seed in seeds:
            for i, k in enumerate(counts):
                for j, d in enumerate(durations):
                    rng = np.random.default_rng([seed, k, j])
                    starts, frames, hidden = occlusion_windows(visible, take.rate, d, k, windows, rng)
                    filled = predict_windows("nn", positions, take.rate, starts, frames, hidden, model.predictor)
                    f, a = _joint_errors(model, filled, take, starts + frames - 1, ~hidden)
                    out["fingers"][i, j] += f / (len(seeds) * len(takes))
                    out["all"][i, j] += a / (len(seeds) * len(takes))
    out["none_fingers"], out["none_all"] = float(np.mean(none_f)), float(np.mean(none_a))
    return out
