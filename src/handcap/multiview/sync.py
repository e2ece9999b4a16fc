"""Cameras that were not triggered together: each camera's time offset, found from its 2D detections.

Consumer cameras, phones and webcams start recording one by one, so frame k of
one camera is not the moment of frame k of another. A calibrated rig tells when
two views agree: the same named marker seen by cameras a and b at one moment
lies on the epipolar line of its other view. For every pair of cameras that
share markers, :func:`estimate_sync` slides b's frames against a's and keeps
the offset where the views agree best (the median distance to the epipolar
lines, in pixels), first in whole frames over the search range, then to a
twentieth of a frame with b's tracks interpolated between frames. The pairs'
offsets are then joined by least squares into one offset per camera, pairs that
disagree with the rest are left out, and the result is checked: a camera whose
offset no pair fixes (a still scene, no shared marker) is named in a warning.

Offsets are in frames of the detections' rate: camera c's frame f shows the
moment of the reference camera's frame ``f + offset[c]`` (a camera that started
recording 12 frames after the reference has +12). :func:`shift_detections`
puts every camera on the reference's frames, interpolating a camera's pixels
between its frames for a fractional offset. The offset is constant over the
take: cameras whose clocks run at different rates drift, which the check of
the take's first and last thirds reports.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from handcap.core.cameras import CameraRig
from handcap.core.errors import HandcapError
from handcap.multiview.detections import Detections
from handcap.multiview.epipolar import FINE_SAMPLES, MIN_MATCHES, EpipolarViews

#: Default search range of :func:`estimate_sync`, seconds either way.
MAX_OFFSET_S = 3.0
#: Views of the first camera of a pair that the whole-frame search samples (the fine search takes all).
SAMPLES = 2000
#: :func:`check_sync` looks for better offsets only where the views disagree by more (median epipolar distance,
#: pixels): synchronised views of markers agree to a pixel.
CHECK_PX = 2.0
#: Synchronised views that still disagree by more (median epipolar distance, pixels) get a warning.
NOISE_PX = 3.0
#: Views of the first camera of a pair that :func:`check_sync` samples.
CHECK_SAMPLES = 500
#: A pair's best offset must be this much clearer than its best offset two or more frames away: its median
#: epipolar distance at most this share of the other's.
CLEAR = 0.6
#: Pairs whose offset disagrees with the joined offsets by more than this many frames are left out.
AGREE_FRAMES = 0.35
#: Fractional offsets closer than this to a whole frame take that frame's pixels as they are.
WHOLE = 0.02


@dataclass(frozen=True)
class Sync:
    """Each camera's offset and how well it is known (see the module docstring).

    Attributes
    ----------
    camera_names : tuple of str, length C
    offsets : ndarray (C,) float
        Frames: camera c's frame f shows the reference's frame ``f + offsets[c]``; NaN where no pair fixed it.
    reference : str
        The camera whose frames the offsets count (its offset is 0).
    before, after : float
        How far the pairs' views disagree, with every offset 0 and with ``offsets``: the median epipolar
        distance of their matched views in pixels (:func:`estimate_sync`), or what ``measure`` and ``unit`` say.
    pairs : int
        Pairs of cameras whose offsets were joined.
    warnings : tuple of str
    measure, unit : str
        What ``before`` and ``after`` measure, and in what unit.
    """

    camera_names: tuple
    offsets: np.ndarray
    reference: str
    before: float
    after: float
    pairs: int
    warnings: tuple = ()
    measure: str = "epipolar distance"
    unit: str = "px"

    def summary(self) -> str:
        """One line: each camera's offset and how far the views disagree before and after."""
        shown = ", ".join(f"{name} {'unknown' if np.isnan(o) else f'{o:+.2f}'}"
                          for name, o in zip(self.camera_names, self.offsets))
        line = f"synchronised to {self.reference} from {self.pairs} pairs of cameras, offsets in frames: {shown}"
        if np.isfinite(self.before) or np.isfinite(self.after):
            line += f"; {self.measure} {self.before:.2f} {self.unit} -> {self.after:.2f} {self.unit} (median)"
        return line


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
        offsets -= offsets[_camera(names, reference)]
    return offsets


def estimate_sync(detections: Detections, rig: CameraRig, *, max_offset_s: float = MAX_OFFSET_S,
                  reference: str | None = None, seed: int = 0, noise_px: float = NOISE_PX) -> Sync:
    """Each camera's time offset from the epipolar agreement of its detections with other cameras'.

    Parameters
    ----------
    detections : Detections
        Named 2D detections of several cameras (coded-patch corners, markers or hand keypoints).
    rig : CameraRig
        Their calibrated cameras.
    max_offset_s : float
        Search range, seconds either way of every camera's frame 0.
    reference : str or None
        The camera the offsets count from (default: the detections' first camera).
    seed : int
        Picks the views the whole-frame search samples.
    noise_px : float
        Views that still disagree by more after synchronising (median epipolar distance, pixels) get a warning;
        a hand keypoint detector's points lie a few pixels off, so triangulate gives those more.

    Returns
    -------
    Sync
    """
    if not (np.isfinite(max_offset_s) and max_offset_s > 0):
        raise HandcapError(f"the search range must be a positive number of seconds, got {max_offset_s!r}")
    names = list(detections.camera_names)
    ref = _camera(names, names[0] if reference is None else reference)
    span = max(1, int(round(max_offset_s * detections.rate)))
    views = EpipolarViews(detections, rig)
    rng = np.random.default_rng(seed)
    found, warnings = [], []
    for a, b in views.pairs():
        pair = _pair_offset(views, a, b, span, rng)
        if pair is None:
            continue
        if pair[3] == "edge":
            warnings.append(f"cameras {names[a]} and {names[b]} agree best at the end of the search range "
                            f"({span} frames, {max_offset_s:g} s); search further (--max-offset)")
            continue
        found.append(pair[:3])
    offsets, used, disagree = join_offsets(found, len(names), ref)
    if disagree:
        warnings.append(f"{disagree} pairs of cameras disagreed with the joined offsets by more than "
                        f"{AGREE_FRAMES:g} frames and were left out")
    lost = [names[c] for c in range(len(names)) if np.isnan(offsets[c])]
    if lost:
        warnings.append(f"no offset found for camera {', '.join(lost)}: it shares too few markers with the other "
                        f"cameras, or the take moves too little to tell one offset from another; its detections "
                        f"are left out")
    before = views.median_distance(used, np.zeros(len(names)))
    after = views.median_distance(used, offsets)
    if np.isfinite(after) and after > noise_px:
        warnings.append(f"the views still disagree by {after:.1f} px (median epipolar distance) after synchronising: "
                        f"check the rig's calibration")
    drift = _drift(views, used, offsets, detections)
    if drift:
        warnings.append(drift)
    return Sync(tuple(names), offsets, names[ref], before, after, len(used), tuple(warnings))


def check_sync(detections: Detections, rig: CameraRig, offsets=None, *, reference: str | None = None,
               max_offset_s: float = MAX_OFFSET_S) -> Sync:
    """How well the views agree with given offsets (default every camera at 0), without searching for others.

    With offsets 0, each pair of cameras whose views disagree by more than :data:`CHECK_PX` (median epipolar
    distance) is also tried at every whole offset within ``max_offset_s`` (on a few hundred of its views), and pairs
    that agree clearly better a frame or more apart give a warning that the cameras seem not synchronised. With
    offsets given, views that agree worse with them than without give a warning that they may be wrong (a sign
    turned, say).

    Parameters
    ----------
    detections : Detections
    rig : CameraRig
    offsets : array_like (C,) or None
        Frames (see :class:`Sync`); None: every camera at 0.
    reference : str or None
        The camera named as the reference in the result (default: the detections' first).
    max_offset_s : float
        How far the check looks, seconds either way.

    Returns
    -------
    Sync
        The offsets as given, and the median epipolar distance without them and with them.
    """
    names = list(detections.camera_names)
    given = offsets is not None
    offsets = np.zeros(len(names)) if offsets is None else np.asarray(offsets, dtype=np.float64).reshape(-1)
    if offsets.shape != (len(names),):
        raise HandcapError(f"need one offset per camera ({len(names)}), got {offsets.shape}")
    ref = _camera(names, names[0] if reference is None else reference)
    views = EpipolarViews(detections, rig)
    rng = np.random.default_rng(0)
    span = max(1, int(round(max_offset_s * detections.rate)))
    pairs = [(a, b, 0.0) for a, b in views.pairs() if views.essential(a, b) is not None]
    before = views.median_distance(pairs, np.zeros(len(names)))
    after = views.median_distance(pairs, offsets) if given else before
    apart = 0
    for a, b, _ in [] if given else pairs:
        if views.median_distance([(a, b)], np.zeros(len(names))) > CHECK_PX:  # would they agree better apart?
            rows = np.arange(len(views.keys[a]))
            if len(rows) > CHECK_SAMPLES:
                rows = np.sort(rng.choice(rows, CHECK_SAMPLES, replace=False))
            cost = views.mean_by_shift(a, b, rows, np.arange(-span, span + 1), views.essential(a, b))
            apart += bool(np.isfinite(cost[span]) and cost.min() < CLEAR * cost[span])
    warnings = []
    if apart:
        warnings.append(f"{apart} of {len(pairs)} pairs of cameras agree clearly better a frame or more apart: the "
                        f"cameras seem not synchronised (frame k of one is not the moment of frame k of another); "
                        f"triangulate --sync auto finds each camera's offset")
    if given and np.isfinite(after) and np.isfinite(before) and after > before:
        warnings.append(f"the views agree worse with the given offsets than without ({after:.2f} px against "
                        f"{before:.2f} px, median epipolar distance): check their signs (camera c's frame f shows "
                        f"the reference's frame f + offset)")
    return Sync(tuple(names), offsets - offsets[ref], names[ref], before, after, len(pairs), tuple(warnings))


def shift_detections(detections: Detections, offsets) -> tuple[Detections, int]:
    """The detections on the reference camera's frames (see :class:`Sync`).

    Parameters
    ----------
    detections : Detections
    offsets : array_like (C,)
        Frames per camera of ``detections.camera_names``; a camera with NaN is left out.

    Returns
    -------
    (Detections, int)
        The shifted detections, with as many frames as reach the last moment any camera saw; and the rows left
        out (before the reference's frame 0, or of a camera with no offset). A fractional offset interpolates a
        camera's pixels between its two frames, where both saw the marker; such a row's score is the lower.
    """
    offsets = np.asarray(offsets, dtype=np.float64).reshape(-1)
    if offsets.shape != (len(detections.camera_names),):
        raise HandcapError(f"need one offset per camera ({len(detections.camera_names)}), got {offsets.shape}")
    d = detections
    parts = {"frame": [], "camera": [], "marker": [], "xy": [], "score": []}
    for c, offset in enumerate(offsets):
        rows = np.flatnonzero(d.camera == c)
        if not len(rows) or np.isnan(offset):
            continue
        whole = np.floor(offset + WHOLE)
        part = offset - whole
        if part < WHOLE:  # a whole number of frames: each row as it is
            frame, xy, score, marker = d.frame[rows] + int(whole), d.xy[rows], d.score[rows], d.marker[rows]
        else:  # between this frame and the next: frame f and f + 1 give reference frame f + whole + 1
            key = d.marker[rows] * (d.n_frames + 1) + d.frame[rows]
            order = np.argsort(key, kind="stable")
            key, rows = key[order], rows[order]
            at = np.minimum(np.searchsorted(key, key + 1), len(key) - 1)
            pair = key[at] == key + 1
            first, second = rows[pair], rows[at[pair]]
            frame = d.frame[first] + int(whole) + 1
            xy = part * d.xy[first] + (1 - part) * d.xy[second]
            score, marker = np.minimum(d.score[first], d.score[second]), d.marker[first]
        for key, value in zip(parts, (frame, np.full(len(frame), c), marker, xy, score)):
            parts[key].append(value)
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


def _camera(names: list, name: str) -> int:
    if name not in names:
        raise HandcapError(f"no camera {name!r} to count the offsets from (the detections have {', '.join(names)})")
    return names.index(name)


def _pair_offset(views: EpipolarViews, a: int, b: int, span: int, rng) -> tuple | None:
    """(a, b, offset of b minus a's in frames, 'edge' or '') or None where no offset is clearly best."""
    e = views.essential(a, b)
    if e is None:
        return None
    rows = np.arange(len(views.keys[a]))
    if len(rows) > SAMPLES:
        rows = np.sort(rng.choice(rows, SAMPLES, replace=False))
    shifts = np.arange(-span, span + 1)
    cost = views.mean_by_shift(a, b, rows, shifts, e)
    if not np.isfinite(cost).any():
        return None
    best = int(np.argmin(cost))
    away = np.abs(shifts - shifts[best]) >= 2
    if not np.isfinite(cost[away]).any() or cost[best] > CLEAR * cost[away].min():  # no clear least
        return None
    if best in (0, len(shifts) - 1) and span > 1:
        return a, b, np.nan, "edge"
    shift = views.fine_shift(a, b, int(shifts[best]), e)
    # a's frame f and b's frame f + shift show one moment: b's offset is a's minus the shift
    return (a, b, -shift, "") if shift is not None else None


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


def _drift(views: EpipolarViews, pairs: list, offsets: np.ndarray, detections: Detections) -> str:
    """A warning naming the cameras whose pairs want offsets a frame or more apart in the take's first and last
    thirds (clocks at different rates), else ''.

    A pair counts only where both thirds show a clear least distance; a camera drifts when most of its pairs that
    count, and two at least, drift.
    """
    third = detections.n_frames // 3
    if third < 10 or not pairs:
        return ""
    judged, drifting, size = np.zeros(len(offsets)), np.zeros(len(offsets)), {}
    for a, b, _ in pairs:
        e = views.essential(a, b)
        grid = offsets[a] - offsets[b] + np.linspace(-3, 3, 61)
        ends = []
        for lo, hi in ((0, third), (detections.n_frames - third, detections.n_frames)):
            rows = np.flatnonzero((views.frames[a] >= lo) & (views.frames[a] < hi))
            rows = rows[::max(1, len(rows) // FINE_SAMPLES)]
            cost = np.full(len(grid), np.inf)
            for k, shift in enumerate(grid):
                xb = views.at_offset(a, b, rows, shift)
                ok = np.isfinite(xb).all(axis=1)
                if ok.sum() >= MIN_MATCHES:
                    cost[k] = np.median(views.distance(a, b, views.points[a][rows[ok]], xb[ok], e))
            best = int(np.argmin(cost))
            clear = np.isfinite(cost[best]) and cost[best] < CLEAR * max(cost[0], cost[-1])
            ends.append(grid[best] if clear else np.nan)
        change = abs(ends[1] - ends[0])
        if np.isfinite(change):
            judged[[a, b]] += 1
            if change >= 1.0:
                drifting[[a, b]] += 1
                for c in (a, b):
                    size[c] = max(size.get(c, 0.0), change)
    cameras = [c for c in range(len(offsets)) if drifting[c] >= 2 and drifting[c] > judged[c] / 2]
    if not cameras:
        return ""
    names = detections.camera_names
    return (f"camera {', '.join(names[c] for c in cameras)} drifts against the others by up to "
            f"{max(size[c] for c in cameras):.1f} frames between the take's first and last thirds: its clock runs at "
            f"another rate, so one offset does not hold for the whole take")
