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
recording 12 frames after the reference has +12). Clocks that run at different
rates drift apart: the offsets are found again in pieces of the take, and a
camera whose offset moves along a line gets it, ``f + offset[c] + drift[c] * f``.
:func:`shift_detections` puts every camera on the reference's frames,
interpolating a camera's pixels between its frames.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from handcap.core.cameras import CameraRig
from handcap.core.errors import HandcapError
from handcap.multiview.detections import Detections
from handcap.multiview.epipolar import MIN_MATCHES, EpipolarViews
from handcap.multiview.offsets import (AGREE_FRAMES, CLEAR, camera_index, clear_least, join_offsets, least_on_grid,
                                       offsets_from_names, parse_offsets, shift_detections)

#: Default search range of :func:`estimate_sync`, seconds either way.
MAX_OFFSET_S = 3.0
#: Views of the first camera of a pair that the whole-frame search samples (the fine search takes more).
SAMPLES = 2000
#: :func:`check_sync` looks for better offsets only where the views disagree by more (median epipolar distance,
#: pixels): synchronised views of markers agree to a pixel.
CHECK_PX = 2.0
#: Synchronised views that still disagree by more (median epipolar distance, pixels) get a warning.
NOISE_PX = 3.0
#: Views of the first camera of a pair that :func:`check_sync` samples.
CHECK_SAMPLES = 500
#: Pieces of the take in which each camera's offset is found again, to see its clock drift.
WINDOWS = 6
#: Least frames of a piece (shorter takes are taken as drifting not at all).
DRIFT_PIECE = 20
#: A piece's offset is searched this many frames either way of the whole take's.
DRIFT_SEARCH = 3.0
#: Views of a pair's first camera that each piece's search takes at most.
WINDOW_SAMPLES = 2000
#: A clock is corrected when it drifts this many frames or more over the take.
DRIFT_MIN = 0.2


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
    drift : ndarray (C,) or None
        Frames of offset per frame of the camera's own (its clock's rate against the reference's, less 1): camera
        c's frame f shows the reference's frame ``f + offsets[c] + drift[c] * f``. None: no drift.
    notes : tuple of str
        What was corrected besides the offsets (a clock's drift).
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
    drift: np.ndarray | None = None
    notes: tuple = ()

    def summary(self) -> str:
        """One line: each camera's offset and how far the views disagree before and after."""
        shown = ", ".join(f"{name} {'unknown' if np.isnan(o) else f'{o:+.2f}'}"
                          for name, o in zip(self.camera_names, self.offsets))
        line = f"synchronised to {self.reference} from {self.pairs} pairs of cameras, offsets in frames: {shown}"
        if np.isfinite(self.before) or np.isfinite(self.after):
            line += f"; {self.measure} {self.before:.2f} {self.unit} -> {self.after:.2f} {self.unit} (median)"
        return "; ".join((line, *self.notes))


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
    ref = camera_index(names, names[0] if reference is None else reference)
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
        found.append(pair)
    # A pair whose views agree nowhere to within the noise matched no moments (they share few markers, seen at
    # other times): left out where other pairs do agree. Where none does, the rig is off and a warning below says so.
    far = [p for p in found if p[4] > noise_px]
    if len(far) < len(found):
        found = [p for p in found if not p[4] > noise_px]
        warnings += [f"cameras {names[a]} and {names[b]} agree best {abs(shift):.0f} frames apart, but only to "
                     f"{cost:.1f} px (median epipolar distance), more than the {noise_px:g} px synchronised views "
                     f"agree within: they share too few markers to time one against the other (or one is calibrated "
                     f"off), so that pair is left out"
                     for a, b, shift, _, cost in far]
    offsets, used, disagree = join_offsets([p[:3] for p in found], len(names), ref)
    if disagree:
        warnings.append(f"{disagree} pairs of cameras disagreed with the joined offsets by more than "
                        f"{AGREE_FRAMES:g} frames and were left out")
    lost = [names[c] for c in range(len(names)) if np.isnan(offsets[c])]
    if lost:
        warnings.append(f"no offset found for camera {', '.join(lost)}: it shares too few markers with the other "
                        f"cameras, or the take moves too little to tell one offset from another; its detections "
                        f"are left out")
    offsets, in_step = _no_worse_than_none(views, used, offsets, names, ref)
    before = views.median_distance(used, np.zeros(len(names)))
    after = views.median_distance(used, offsets)
    if np.isfinite(after) and after > noise_px:
        warnings.append(f"the views still disagree by {after:.1f} px (median epipolar distance) after synchronising: "
                        f"check the rig's calibration")
    offsets, drift, lines, jumps = _clocks(views, used, offsets, detections, ref)
    warnings.extend(jumps)
    if lines:
        after = views.median_distance(used, offsets, drift)
    return Sync(tuple(names), offsets, names[ref], before, after, len(used), tuple(warnings), drift=drift,
                notes=tuple(lines) + ((in_step,) if in_step else ()))


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
    ref = camera_index(names, names[0] if reference is None else reference)
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


def _pair_offset(views: EpipolarViews, a: int, b: int, span: int, rng) -> tuple | None:
    """(a, b, offset of b minus a's in frames, 'edge' or '', the views' median epipolar distance there in pixels)
    or None where no offset is clearly best.

    The whole-frame search samples a's views; the best shift and its two neighbours are then scored on all of them
    (a slow take's neighbouring shifts differ by less than the sample's noise), before the fine search."""
    e = views.essential(a, b)
    if e is None:
        return None
    every = np.arange(len(views.keys[a]))
    rows = np.sort(rng.choice(every, SAMPLES, replace=False)) if len(every) > SAMPLES else every
    shifts = np.arange(-span, span + 1)
    best = clear_least(shifts, views.mean_by_shift(a, b, rows, shifts, e))
    if best is None:
        return None
    if best in (0, len(shifts) - 1) and span > 1:
        return a, b, np.nan, "edge", np.nan
    near = shifts[best] + np.arange(-1, 2)
    cost = views.mean_by_shift(a, b, every, near, e)
    shift = views.fine_shift(a, b, int(near[np.argmin(cost)] if np.isfinite(cost).any() else shifts[best]), e)
    if shift is None:
        return None
    # a's frame f and b's frame f + shift show one moment: b's offset is a's minus the shift
    at = np.zeros(len(views.keys))
    at[b] = -shift
    return a, b, -shift, "", views.median_distance([(a, b)], at)


def _no_worse_than_none(views: EpipolarViews, pairs: list, offsets: np.ndarray, names, ref: int):
    """``offsets`` with every camera set to 0 whose views agree as well there (its pairs' median epipolar distance),
    and a line naming those cameras, if any. A camera filmed in step with the reference needs no offset; a search
    over a take that moves slowly, or whose cameras share few markers, can settle a frame or more off it."""
    offsets, reset = offsets.copy(), []
    for c in range(len(offsets)):
        if c == ref or not np.isfinite(offsets[c]) or offsets[c] == 0:
            continue
        own = [p for p in pairs if c in p[:2]]
        at_zero = offsets.copy()
        at_zero[c] = 0.0
        found, none = views.median_distance(own, offsets), views.median_distance(own, at_zero)
        if np.isfinite(none) and not none > found:
            reset.append(f"{names[c]} ({none:.2f} px at 0 against {found:.2f} px at {offsets[c]:+.2f})")
            offsets[c] = 0.0
    if not reset:
        return offsets, None
    return offsets, ("in step with the others (their views agree as well with no offset): " + ", ".join(reset))


def _clocks(views: EpipolarViews, pairs: list, offsets: np.ndarray, detections: Detections, ref: int):
    """Each camera's clock against the reference's: (offsets (C,), drift (C,), lines, warnings).

    The take is cut into :data:`WINDOWS` pieces of the reference's frames. In each, every pair's offset is found
    again within :data:`DRIFT_SEARCH` frames of the whole take's, at the middle of the views it used; a line through
    them gives the pair's change of offset over the take. The pairs' lines join into one per camera (least
    squares, as the offsets do). A camera whose line moves :data:`DRIFT_MIN` frames or more over the take gets it
    (its clock runs at another rate); one whose pairs' offsets jump about, off any line, gets a warning (dropped
    frames, say) and keeps the take's offset.
    """
    n = detections.n_frames
    piece = n // WINDOWS
    drift = np.zeros(len(offsets))
    if piece < DRIFT_PIECE or not pairs:
        return offsets, drift, [], []
    starts, changes, jumps = [], [], np.zeros(len(offsets), int)
    for a, b, _ in pairs:
        times, values = [], []
        for k in range(WINDOWS):
            lo, hi = k * piece - offsets[a], (k + 1) * piece - offsets[a]  # the piece in a's own frames
            found = _window_shift(views, a, b, offsets[a] - offsets[b], lo, hi)
            if found is not None:
                times.append(found[1] + offsets[a])
                values.append(-found[0])
        if len(times) < 3:
            continue
        times, values = np.array(times), np.array(values)
        slope, intercept = np.polyfit(times, values, 1)
        if np.abs(values - intercept - slope * times).max() > 0.3:
            jumps[[a, b]] += 1
            continue
        starts.append((a, b, intercept))
        changes.append((a, b, slope * n))  # frames over the take
    names = detections.camera_names
    warnings = [f"camera {names[c]}'s offset changes within the take, not along a line (dropped frames?): one offset "
                f"does not hold for the whole take" for c in np.flatnonzero(jumps >= 2)]
    start, change = join_offsets(starts, len(offsets), ref)[0], join_offsets(changes, len(offsets), ref)[0]
    offsets, lines = offsets.copy(), []
    drifts = np.isfinite(change) & np.isfinite(start) & (np.abs(change) >= DRIFT_MIN)
    if not drifts.any():
        return offsets, drift, lines, warnings
    offsets[np.isfinite(start)] = start[np.isfinite(start)]  # every camera's, with the drifting ones' lines
    for c in np.flatnonzero(drifts):
        rate = change[c] / n  # offset = start + rate * (the reference's frame): in the camera's own frames
        offsets[c], drift[c] = start[c] / (1 - rate), rate / (1 - rate)
        lines.append(f"{names[c]}'s clock runs {100 * drift[c]:+.3f} % against {names[ref]}'s ({change[c]:+.1f} "
                     f"frames over the take), corrected")
    return offsets, drift, lines, warnings


def _window_shift(views: EpipolarViews, a: int, b: int, shift: float, lo: float, hi: float) -> tuple | None:
    """A pair's shift in a's frames [lo, hi), within :data:`DRIFT_SEARCH` frames of ``shift``, and the middle of the
    frames it used; None unless clear. Half frames first, then a sixteenth about the least."""
    e = views.essential(a, b)
    rows = np.flatnonzero((views.frames[a] >= lo) & (views.frames[a] < hi))
    rows = rows[::max(1, len(rows) // WINDOW_SAMPLES)]

    def costs(grid):
        cost = np.full(len(grid), np.inf)
        for k, s in enumerate(grid):
            xb = views.at_offset(a, b, rows, s)
            ok = np.isfinite(xb).all(axis=1)
            if ok.sum() >= MIN_MATCHES:
                cost[k] = np.median(views.distance(a, b, views.points[a][rows[ok]], xb[ok], e))
        return cost

    coarse = shift + np.arange(-DRIFT_SEARCH, DRIFT_SEARCH + 0.25, 0.5)
    cost = costs(coarse)
    best = int(np.argmin(cost))
    if not np.isfinite(cost[best]) or best in (0, len(coarse) - 1) or cost[best] > CLEAR * max(cost[0], cost[-1]):
        return None
    grid = coarse[best] + np.linspace(-0.5, 0.5, 17)
    return least_on_grid(grid, costs(grid)), float(views.frames[a][rows].mean())


__all__ = ["CHECK_PX", "MAX_OFFSET_S", "NOISE_PX", "Sync", "check_sync", "estimate_sync", "join_offsets",
           "offsets_from_names", "parse_offsets", "shift_detections"]
