"""Cameras' time offsets as data: given by name, joined from pairs of cameras, and applied to detections.

Offsets count as :class:`handcap.multiview.sync.Sync` counts them: camera c's frame f shows the moment of the
reference camera's frame ``f + offset[c]`` (``+ drift[c] * f`` for a clock that runs at another rate).
"""

from __future__ import annotations

import numpy as np

from handcap.core.errors import HandcapError
from handcap.multiview.detections import Detections

#: A pair's best offset must be this much clearer than its best offset two or more frames away: its cost at most
#: this share of the other's.
CLEAR = 0.6
#: Pairs whose offset disagrees with the joined offsets by more than this many frames are left out.
AGREE_FRAMES = 0.35
#: Fractional offsets closer than this to a whole frame take that frame's pixels as they are.
WHOLE = 0.02
#: :func:`curving`: a camera's tracks are moved between its frames along a spline where the straight line's median
#: squared error, leaving a frame out, is over this many times the cubic's ((9 / 4 + 1.5) / 1.94 from the noise and
#: acceleration terms); and :data:`MIN_CURVING` points or more tell.
CURVING = 1.93
MIN_CURVING = 20


def parse_offsets(items) -> dict:
    """``{camera: frames}`` from ``CAM=FRAMES`` items (a string may hold several, joined by commas).

    Parameters
    ----------
    items : str or sequence of str
        E.g. ``"cam_2=+12.5, cam_3=-4"`` or ``["cam_2=12.5", "cam_3=-4"]``.

    Raises
    ------
    HandcapError
        For an item without ``=``, a camera named twice, or an offset that is not a finite number.
    """
    items = [items] if isinstance(items, str) else list(items)
    offsets = {}
    for item in (part.strip() for text in items for part in str(text).split(",")):
        name, sep, value = item.partition("=")
        name = name.strip()
        if not sep or not name:
            raise HandcapError(f"an offset is CAMERA=FRAMES (e.g. cam_2=+12.5), got {item!r}")
        if name in offsets:
            raise HandcapError(f"camera {name!r} is given two offsets")
        try:
            offsets[name] = float(value)
        except ValueError:
            raise HandcapError(f"the offset of camera {name!r} must be a number of frames, got {value.strip()!r}") \
                from None
        if not np.isfinite(offsets[name]):
            raise HandcapError(f"the offset of camera {name!r} must be a finite number of frames, got {value!r}")
    if not offsets:
        raise HandcapError("no offsets given: CAMERA=FRAMES, e.g. cam_2=+12.5")
    return offsets


def offsets_from_names(detections: Detections, given: dict, reference: str | None = None) -> np.ndarray:
    """Offsets (C,) in the detections' camera order from ``{camera: frames}``; cameras not named get 0.

    Parameters
    ----------
    detections : Detections
    given : dict of str to float
        Frames, as :class:`Sync` counts them.
    reference : str or None
        A camera to count from: its given offset is taken from every camera's.

    Raises
    ------
    HandcapError
        For a camera the detections lack, or an offset that is not a finite number.
    """
    names = list(detections.camera_names)
    offsets = np.zeros(len(names))
    for name, value in given.items():
        if name not in names:
            raise HandcapError(f"an offset for camera {name!r}, which the detections lack (they have "
                               f"{', '.join(names)})")
        try:
            offsets[names.index(name)] = float(value)
        except (TypeError, ValueError):
            raise HandcapError(f"the offset of camera {name!r} must be a number of frames, got {value!r}") from None
    if not np.isfinite(offsets).all():
        raise HandcapError("every camera's offset must be a finite number of frames")
    if reference is not None:
        offsets -= offsets[camera_index(names, reference)]
    return offsets


def shift_detections(detections: Detections, offsets, drift=None) -> tuple[Detections, int]:
    """The detections on the reference camera's frames (see :class:`Sync`).

    Parameters
    ----------
    detections : Detections
    offsets : array_like (C,)
        Frames per camera of ``detections.camera_names``; a camera with NaN is left out.
    drift : array_like (C,) or None
        Each camera's clock drift, as :class:`Sync` counts it (None: none).

    Returns
    -------
    (Detections, int)
        The shifted detections, with as many frames as reach the last moment any camera saw; and the rows left
        out (before the reference's frame 0, or of a camera with no offset). A moment of the reference's that falls
        between two of a camera's frames that both saw the marker is interpolated between them: along the
        Catmull-Rom spline through its frames before and after too, where it saw the marker then and the camera's
        tracks curve more than their noise (:func:`curving`), else along the straight line; such a row's score is
        the lower of the two frames'.
    """
    offsets = np.asarray(offsets, dtype=np.float64).reshape(-1)
    if offsets.shape != (len(detections.camera_names),):
        raise HandcapError(f"need one offset per camera ({len(detections.camera_names)}), got {offsets.shape}")
    drift = np.zeros(len(offsets)) if drift is None else np.asarray(drift, dtype=np.float64).reshape(-1)
    d = detections
    parts = {"frame": [], "camera": [], "marker": [], "xy": [], "score": []}
    for c, offset in enumerate(offsets):
        rows = np.flatnonzero(d.camera == c)
        if not len(rows) or np.isnan(offset):
            continue
        key = d.marker[rows] * (d.n_frames + 1) + d.frame[rows]
        order = np.argsort(key, kind="stable")
        key, rows = key[order], rows[order]
        moment = d.frame[rows] + offset + drift[c] * d.frame[rows]  # the reference's frame each row shows
        on = np.abs(moment - np.rint(moment)) < WHOLE  # on a reference frame: the row as it is
        near = [_next(key, step) for step in (-1, 1, 2)]  # the marker in the camera's frames around each row
        pair = np.flatnonzero(near[1] >= 0)  # ... in its next frame too
        start, end = moment[pair], moment[near[1][pair]]
        frame = np.floor(start + WHOLE).astype(np.int64) + 1  # the reference frame between the two
        inside = frame < end - WHOLE
        pair, start, end, frame = pair[inside], start[inside], end[inside], frame[inside]
        four = [rows[k] for k in (near[0][pair], pair, near[1][pair], near[2][pair])]
        xy = between(d.xy[four[0]], d.xy[four[1]], d.xy[four[2]], d.xy[four[3]], (frame - start) / (end - start),
                      (near[0][pair] >= 0) & (near[2][pair] >= 0) & curving(d.xy[rows], key))
        columns = (np.concatenate([np.rint(moment[on]).astype(np.int64), frame]), np.full(on.sum() + len(frame), c),
                   np.concatenate([d.marker[rows[on]], d.marker[four[1]]]), np.concatenate([d.xy[rows[on]], xy]),
                   np.concatenate([d.score[rows[on]], np.minimum(d.score[four[1]], d.score[four[2]])]))
        for name, value in zip(parts, columns):
            parts[name].append(value)
    if not parts["frame"]:
        raise HandcapError("no camera has an offset: nothing to synchronise")
    frame, camera, marker, xy, score = (np.concatenate(parts[key]) for key in parts)
    keep = frame >= 0
    n_frames = int(frame[keep].max()) + 1 if keep.any() else 0
    order = np.lexsort((marker[keep], camera[keep], frame[keep]))
    out = Detections(d.camera_names, d.marker_names, frame[keep][order], camera[keep][order],
                     marker[keep][order], xy[keep][order], score[keep][order], d.rate, max(n_frames, 1),
                     d.source, d.pitch)
    return out, len(d.frame) - len(out.frame)


def _next(key: np.ndarray, step: int) -> np.ndarray:
    """For each of the sorted ``key`` (marker and frame), the index of ``key + step`` (the same marker ``step``
    frames on), or -1 where the camera did not see it then."""
    at = np.minimum(np.searchsorted(key, key + step), len(key) - 1)
    return np.where(key[at] == key + step, at, -1)


def curving(xy: np.ndarray, key: np.ndarray) -> bool:
    """Whether a camera's tracks curve between its frames by more than their noise moves them: then a spline through
    four frames places a moment between two better than the straight line.

    Each point seen in the two frames before and the two after it too is predicted from them, leaving it out: by the
    straight line from its neighbours (weights 1/2, 1/2), and by the cubic through all four (-1/6, 2/3, 2/3, -1/6).
    For a track of acceleration ``a`` (pixels per frame squared) and noise ``s`` (pixels), their squared errors are
    about ``a^2 / 4 + 1.5 s^2`` and ``1.94 s^2`` (the cubic's own error is of the fourth derivative, small). Halfway
    between two frames, the straight line misses by ``a / 8`` and carries ``0.5 s^2`` of noise, the spline ``0.64
    s^2``: the spline is the better where ``a^2 > 9 s^2``, which is where the line's median squared error is over
    :data:`CURVING` times the cubic's. (On synthetic takes at 60 Hz with half a pixel of noise the line is the better;
    on a rendered grasp at 20 Hz the spline, by far.)

    Parameters
    ----------
    xy : ndarray (N, 2)
        The camera's detections, pixels, in the order of ``key``.
    key : ndarray (N,) int
        Sorted: marker times (frames + 1) plus frame, so that ``key + k`` is the same marker k frames on.

    Returns
    -------
    bool
        False where fewer than :data:`MIN_CURVING` points can be predicted so.
    """
    around = [_next(key, step) for step in (-2, -1, 1, 2)]
    inside = np.logical_and.reduce([k >= 0 for k in around])
    if inside.sum() < MIN_CURVING:
        return False
    p = [xy[k[inside]] for k in around]
    line = np.sum((xy[inside] - (p[1] + p[2]) / 2) ** 2, axis=1)
    cubic = np.sum((xy[inside] - (4 * (p[1] + p[2]) - p[0] - p[3]) / 6) ** 2, axis=1)
    return bool(np.median(line) > CURVING * np.median(cubic))


def between(p0: np.ndarray, p1: np.ndarray, p2: np.ndarray, p3: np.ndarray, t: np.ndarray,
            cubic: np.ndarray) -> np.ndarray:
    """Points (N, 2) a share ``t`` of the way from a camera's frame ``p1`` to its next ``p2``: the Catmull-Rom
    spline through the frames before and after too (``p0``, ``p3``) where ``cubic``, else the straight line. A
    moving finger curves between frames: at 20 Hz the straight line puts it off by more than the detector's
    precision.

    Parameters
    ----------
    p0, p1, p2, p3 : ndarray (N, 2)
        A track's points in four frames in a row (``p0`` and ``p3`` may be NaN where not ``cubic``).
    t : ndarray (N,)
        Shares of the way from ``p1`` to ``p2``, 0 to 1.
    cubic : ndarray (N,) bool
        Along the spline; else along the straight line.
    """
    t = t[:, None]
    line = (1 - t) * p1 + t * p2
    spline = 0.5 * (2 * p1 + (p2 - p0) * t + (2 * p0 - 5 * p1 + 4 * p2 - p3) * t ** 2
                    + (3 * p1 - p0 - 3 * p2 + p3) * t ** 3)
    return np.where(cubic[:, None], spline, line)


def camera_index(names, name: str) -> int:
    """The index of camera ``name`` among ``names``, the camera offsets count from.

    Parameters
    ----------
    names : sequence of str
    name : str

    Raises
    ------
    HandcapError
        Naming the cameras there are.
    """
    names = list(names)
    if name not in names:
        raise HandcapError(f"no camera {name!r} to count the offsets from (the detections have {', '.join(names)})")
    return names.index(name)


def join_offsets(found: list, n: int, ref: int) -> tuple[np.ndarray, list, int]:
    """One offset per camera from pairs' offsets, by least squares with the reference at 0.

    Pairs that disagree with the rest by more than :data:`AGREE_FRAMES` are left out, worst first.

    Parameters
    ----------
    found : list of (int, int, float)
        Pairs of cameras (a, b) and b's offset minus a's, frames.
    n : int
        Cameras.
    ref : int
        The reference camera.

    Returns
    -------
    (ndarray (n,), list, int)
        The offsets (NaN for a camera no pair joins to the reference), the pairs used, and the pairs left out.
    """
    pairs = list(found)
    dropped = 0
    while True:
        offsets = np.full(n, np.nan)
        reached = _component(pairs, n, ref)
        use = [p for p in pairs if p[0] in reached and p[1] in reached]
        cams = sorted(reached - {ref})
        if not cams or not use:
            offsets[ref] = 0.0
            return offsets, use, dropped
        column = {c: i for i, c in enumerate(cams)}
        rows = np.zeros((len(use), len(cams)))
        for i, (a, b, _) in enumerate(use):
            if b in column:
                rows[i, column[b]] += 1
            if a in column:
                rows[i, column[a]] -= 1
        value = np.array([p[2] for p in use])
        solution = np.linalg.lstsq(rows, value, rcond=None)[0]
        residual = np.abs(rows @ solution - value)
        worst = int(np.argmax(residual))
        if residual[worst] > AGREE_FRAMES and len(use) > 1:
            pairs.remove(use[worst])
            dropped += 1
            continue
        offsets[ref] = 0.0
        offsets[cams] = solution
        return offsets, use, dropped


def _component(pairs: list, n: int, start: int) -> set:
    reached, grow = {start}, True
    while grow:
        grow = False
        for a, b, _ in pairs:
            if (a in reached) != (b in reached):
                reached |= {a, b}
                grow = True
    return reached


def clear_least(shifts: np.ndarray, cost: np.ndarray) -> int | None:
    """The index of the least cost where it is clearly least: at most :data:`CLEAR` of the least cost two or more
    frames away, which must be known too; else None.

    Parameters
    ----------
    shifts : ndarray (S,)
        Frames, ascending.
    cost : ndarray (S,)
        How far the views disagree at each shift (NaN or inf where unknown).
    """
    cost = np.where(np.isnan(cost), np.inf, cost)
    if not np.isfinite(cost).any():
        return None
    best = int(np.argmin(cost))
    away = np.abs(shifts - shifts[best]) >= 2
    if not np.isfinite(cost[away]).any() or cost[best] > CLEAR * cost[away].min():
        return None
    return best


def least_on_grid(grid: np.ndarray, cost: np.ndarray) -> float:
    """Where ``cost`` is least on an evenly spaced ``grid``, refined by a parabola through the least and its two
    neighbours where both are known and it curves upwards.

    Parameters
    ----------
    grid : ndarray (G,)
        Evenly spaced, ascending.
    cost : ndarray (G,)
        NaN or inf where unknown; at least one known.
    """
    cost = np.where(np.isnan(cost), np.inf, cost)
    k = int(np.argmin(cost))
    if 0 < k < len(grid) - 1 and np.isfinite(cost[k - 1:k + 2]).all():
        left, mid, right = cost[k - 1:k + 2]
        if left - 2 * mid + right > 0:
            return float(grid[k] + 0.5 * (left - right) / (left - 2 * mid + right) * (grid[1] - grid[0]))
    return float(grid[k])
