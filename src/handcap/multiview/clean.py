"""Cleaning of triangulated 3D marker trajectories (DexterCap section 3.3): ``handcap clean``.

    cleaned, report = clean_markers(markers, "dense-patches")

Triangulated markers carry two kinds of wrong samples, and gaps. DexterCap
removes the wrong samples with two heuristics and fills short gaps; each step
here is a pure function of positions ``(T, M, 3)`` (metres, NaN = missing)
that returns new positions and a ``(T, M)`` mask of the samples it removed or
filled, and :func:`clean_markers` runs them in this order:

1. :func:`remove_cluster_outliers`. A mislabelled corner is triangulated
   where the corner it was mistaken for lies, usually far from its patch-mates.
   In every frame the markers of one group (a printed patch, or a hand segment
   when the layout has no patches) keep the largest cluster of points that
   all lie within ``radius`` of each other; the rest are removed. The radius
   comes from the layout's template (see :func:`layout_groups`).
2. :func:`remove_window_outliers`. Spikes: in a sliding window every sample is
   compared with a local quadratic fitted to its neighbours (itself left out),
   and removed when it deviates by more than ``z`` robust standard deviations
   (1.4826 x the median absolute residual of the samples within two window
   lengths) and by more than ``floor`` metres.
3. Gap filling, each method with its own longest gap (frames), applied in
   turn to what is still missing: :func:`fill_rigid` (the rigid motion of the
   marker's patch, from patch-mates seen both in the gap frame and next to
   the gap), :func:`fill_linear` (short gaps; DexterCap fills one or two
   frames) and :func:`fill_spline` (a cubic spline in time). The rigid fill
   goes first because it is the most accurate where it applies: on synthetic
   patches with 0.5 mm noise its error stays at the noise level whatever the
   gap's length, while interpolation in time grows with the gap and with the
   speed of the hand. Only interior gaps are filled: nothing is extrapolated
   past the first or last sample of a marker, and a gap longer than a method's
   maximum is left to the next method or stays missing.

References
----------
Liang Y, Xu S, Zhang Y, Zhan B, Zhang H, Liu L. DexterCap: affordable and
automated capture of complex hand-object interactions (``papers/`` in the
shared folder), section 3.3.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from handcap.core.errors import HandcapError
from handcap.core.checks import check_frames, check_odd_window, check_positions, check_positive
from handcap.core.markers import MarkerSequence, runs
from handcap.layouts import MarkerLayout, load_layout
from handcap.objects.rigid import kabsch
from handcap.occlusion.fill import fill_gaps

# Default radius of a group from its template: scale x (largest template distance) + margin.
# A printed patch is rigid, but the subject's hand (so the patch's place on it) differs from
# the template by up to ~20 %, and triangulation adds a few millimetres at most.
PATCH_SCALE, PATCH_MARGIN = 1.2, 0.005
# Markers of one hand segment sit on skin, not on one printed piece: skin over the
# joints stretches and slides as the fingers bend, so the allowance is wider.
SEGMENT_SCALE, SEGMENT_MARGIN = 1.5, 0.010

WINDOW = 15
Z = 5.0
FLOOR = 0.002
MAX_LINEAR, MAX_RIGID, MAX_SPLINE = 2, 30, 10
RIGID_TOLERANCE = 0.003
# A rigid fit needs markers off a line: RMS distance from their principal axis, metres.
RIGID_MIN_SPREAD = 0.001
MAD_TO_STD = 1.4826
# Elements per block of the windowed arrays (T x markers x 3 x window): bounds memory to some tens of MB.
_BLOCK = 2_000_000


@dataclass(frozen=True, eq=False)
class MarkerGroups:
    """Which markers move together, and how far apart they may be.

    Attributes
    ----------
    labels : ndarray of int, shape (M,)
        Group of each marker, -1 for markers in no group (not in the layout).
    names : tuple of str, length G
        Group names (patch or segment).
    radii : ndarray of shape (G,)
        Metres; the largest distance between two markers of a group that are
        still counted as neighbours; NaN where unknown (the group is then not
        clustered).
    """

    labels: np.ndarray
    names: tuple[str, ...]
    radii: np.ndarray

    def __post_init__(self):
        labels = np.asarray(self.labels, dtype=np.int64)
        radii = np.asarray(self.radii, dtype=np.float64)
        names = tuple(str(n) for n in self.names)
        if labels.ndim != 1 or radii.shape != (len(names),):
            raise HandcapError(f"groups need labels (M,) and one radius per name: got labels {labels.shape}, "
                               f"{len(names)} names, radii {radii.shape}")
        if labels.size and (labels.min() < -1 or labels.max() >= len(names)):
            raise HandcapError(f"group labels must be -1 (no group) or 0..{len(names) - 1}")
        object.__setattr__(self, "labels", labels)
        object.__setattr__(self, "names", names)
        object.__setattr__(self, "radii", radii)

    def members(self, group: int) -> np.ndarray:
        """Columns of the markers of ``group``."""
        return np.flatnonzero(self.labels == group)


@dataclass(frozen=True, eq=False)
class CleanReport:
    """What :func:`clean_markers` removed and filled, as ``(T, M)`` boolean masks.

    Attributes
    ----------
    cluster_removed : samples away from the largest cluster of their group (step 1).
    outlier_removed : spikes found by the sliding window (step 2).
    rigid_filled, linear_filled, spline_filled : samples filled by each method (step 3).
    missing : samples missing in the result.
    groups : MarkerGroups or None
        The groups used in steps 1 and 3 (None without a layout).
    """

    cluster_removed: np.ndarray
    outlier_removed: np.ndarray
    rigid_filled: np.ndarray
    linear_filled: np.ndarray
    spline_filled: np.ndarray
    missing: np.ndarray
    groups: MarkerGroups | None = None

    def summary(self) -> str:
        """One line: samples removed and filled by each step, and those left missing."""
        n = self.counts()
        return (f"removed {n['cluster_removed']} samples away from their patch and {n['outlier_removed']} spikes; "
                f"filled {n['rigid_filled']} rigid, {n['linear_filled']} linear, {n['spline_filled']} spline; "
                f"{n['missing']} of {self.missing.size} samples missing")

    def counts(self) -> dict:
        """Sample counts of every mask."""
        keys = ("cluster_removed", "outlier_removed", "rigid_filled", "linear_filled", "spline_filled", "missing")
        return {key: int(getattr(self, key).sum()) for key in keys}


# -- groups ------------------------------------------------------------------------------


def layout_groups(names, layout, *, radius: float | None = None) -> MarkerGroups:
    """Group the markers ``names`` by the patch (else the segment) the layout puts them on.

    Parameters
    ----------
    names : sequence of str, length M
        Marker names; a ``Subject:`` prefix is ignored. Names not in the layout
        get no group.
    layout : MarkerLayout or str
        A layout or a shipped layout name / TOML path.
    radius : float, optional
        Metres, the same for every group. Default: from the template, ``1.2 d + 5 mm``
        for a printed patch and ``1.5 d + 10 mm`` for a segment, with ``d`` the
        largest distance between two of the group's template positions (NaN
        when a position is not given).

    Returns
    -------
    MarkerGroups
    """
    if not isinstance(layout, MarkerLayout):
        layout = load_layout(layout)
    if radius is not None:
        radius = check_positive(radius, "cluster radius (metres)")
    by_name = {m.name: (i, m) for i, m in enumerate(layout.markers)}
    template = layout.positions()
    labels = np.full(len(names), -1)
    keys, members = [], []
    for col, name in enumerate(names):
        entry = by_name.get(str(name).rsplit(":", 1)[-1])
        if entry is None:
            continue
        i, marker = entry
        key = marker.patch if marker.patch else marker.segment
        if key not in keys:
            keys.append(key)
            members.append([])
        labels[col] = keys.index(key)
        members[labels[col]].append(i)
    radii = np.full(len(keys), np.nan if radius is None else radius)
    if radius is None:
        for g, idx in enumerate(members):
            pts = template[idx]
            if len(idx) < 2 or np.isnan(pts).any():
                continue
            largest = np.linalg.norm(pts[:, None] - pts[None], axis=-1).max()
            patch = layout.markers[idx[0]].patch is not None
            scale, margin = (PATCH_SCALE, PATCH_MARGIN) if patch else (SEGMENT_SCALE, SEGMENT_MARGIN)
            radii[g] = scale * largest + margin
    return MarkerGroups(labels, tuple(keys), radii)


def _check_groups(groups: MarkerGroups, n_markers: int) -> MarkerGroups:
    if groups.labels.shape != (n_markers,):
        raise HandcapError(f"groups label {len(groups.labels)} markers, the positions have {n_markers}")
    return groups


# -- step 1: clusters ----------------------------------------------------------------------


def remove_cluster_outliers(positions, groups: MarkerGroups) -> tuple[np.ndarray, np.ndarray]:
    """Keep, in every frame and group, the largest cluster of mutually close points.

    A cluster is a set of points all within the group's radius of each other
    (found greedily: the point with the fewest neighbours in the set leaves it,
    ties broken by the larger summed distance, until every pair is close). Its
    points are kept, all others of the group in that frame are removed. If the
    largest cluster is not larger than the largest one among the removed points,
    the frame's group is ambiguous and all its points are removed; a single
    point is kept. Groups with one marker or an unknown radius are left alone.

    Parameters
    ----------
    positions : ndarray of shape (T, M, 3)
        Metres, NaN where missing.
    groups : MarkerGroups
        See :func:`layout_groups`.

    Returns
    -------
    cleaned : ndarray of shape (T, M, 3)
        A copy with the removed samples NaN.
    removed : ndarray of bool, shape (T, M)
    """
    positions = check_positions(positions)
    groups = _check_groups(groups, positions.shape[1])
    removed = np.zeros(positions.shape[:2], bool)
    for g, radius in enumerate(groups.radii):
        cols = groups.members(g)
        if len(cols) < 2 or not np.isfinite(radius):
            continue
        # Frames in chunks: the distance matrices are (frames, n, n).
        step = max(1, _BLOCK // (len(cols) ** 2))
        for start in range(0, positions.shape[0], step):
            pts = positions[start:start + step, cols]
            present = ~np.isnan(pts[..., 0])
            dist = np.linalg.norm(pts[:, :, None] - pts[:, None], axis=-1)
            first = _greedy_cluster(dist, present, radius)
            second = _greedy_cluster(dist, present & ~first, radius)
            ambiguous = first.sum(axis=1) <= second.sum(axis=1)
            keep = np.where(ambiguous[:, None], present & (present.sum(axis=1) == 1)[:, None], first)
            removed[start:start + step, cols] = present & ~keep
    cleaned = positions.copy()
    cleaned[removed] = np.nan
    return cleaned, removed


def _greedy_cluster(dist, active, radius):
    """(F, n) mask of a set of points pairwise within ``radius`` (greedy largest clique)."""
    close = dist <= radius  # NaN distances (missing points) are not close
    active = active.copy()
    spread = np.nan_to_num(dist, nan=0.0)
    while True:
        degree = (close & active[:, None, :]).sum(axis=2)
        count = active.sum(axis=1)
        frames = np.flatnonzero((active & (degree < count[:, None])).any(axis=1))
        if len(frames) == 0:
            return active
        act = active[frames]
        total = (spread[frames] * act[:, None, :]).sum(axis=2)
        # Fewest neighbours leaves first; among equals the one farthest from the rest.
        key = degree[frames] - 0.5 * total / (total.max(axis=1, keepdims=True) + 1e-300)
        worst = np.argmin(np.where(act, key, np.inf), axis=1)
        active[frames, worst] = False


# -- step 2: sliding-window outliers -------------------------------------------------------


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
    block = max(1, _BLOCK // max(1, n_frames * 6 * window))  # the spread's windows are twice as long
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


# -- step 3: gap filling -------------------------------------------------------------------


def _interpolated(positions, max_gap_frames, method):
    """Reuse handcap.occlusion.fill_gaps, whose gaps are in seconds: at 1 Hz they are frames."""
    if max_gap_frames == 0 or positions.shape[0] < 3:
        return positions.copy(), np.zeros(positions.shape[:2], bool)
    names = [str(i) for i in range(positions.shape[1])]
    filled, _ = fill_gaps(MarkerSequence(positions, names, 1.0), method, max_gap_s=max_gap_frames)
    out = filled.positions
    return out, np.isnan(positions[..., 0]) & ~np.isnan(out[..., 0])


def fill_linear(positions, *, max_gap_frames: int = MAX_LINEAR) -> tuple[np.ndarray, np.ndarray]:
    """Fill interior gaps of at most ``max_gap_frames`` frames by straight-line interpolation.

    Parameters
    ----------
    positions : ndarray of shape (T, M, 3)
        Metres, NaN where missing.
    max_gap_frames : int
        Frames; 0 fills nothing.

    Returns
    -------
    filled : ndarray of shape (T, M, 3)
    mask : ndarray of bool, shape (T, M)
        Samples filled.

    See Also
    --------
    handcap.occlusion.fill_gaps : does the interpolation (method ``linear``).
    """
    return _interpolated(check_positions(positions), check_frames(max_gap_frames, "max_gap_frames (linear)"), "linear")


def fill_spline(positions, *, max_gap_frames: int = MAX_SPLINE) -> tuple[np.ndarray, np.ndarray]:
    """Fill interior gaps of at most ``max_gap_frames`` frames with a cubic spline in time.

    The spline (``scipy.interpolate.CubicSpline``) runs through every sample of
    the marker; a marker with fewer than four samples is interpolated linearly.

    Parameters
    ----------
    positions : ndarray of shape (T, M, 3)
        Metres, NaN where missing.
    max_gap_frames : int
        Frames; 0 fills nothing.

    Returns
    -------
    filled : ndarray of shape (T, M, 3)
    mask : ndarray of bool, shape (T, M)

    See Also
    --------
    handcap.occlusion.fill_gaps : does the interpolation (method ``spline``).
    """
    return _interpolated(check_positions(positions), check_frames(max_gap_frames, "max_gap_frames (spline)"), "spline")


def fill_rigid(positions, groups: MarkerGroups, *, max_gap_frames: int = MAX_RIGID,
               tolerance: float = RIGID_TOLERANCE) -> tuple[np.ndarray, np.ndarray]:
    """Fill gaps by carrying the marker along with the rigid motion of its group.

    For a gap of marker m from frame s to s + n - 1, the frames next to it,
    s - 1 and s + n, see m. In each gap frame t and for each of these reference
    frames r, the rotation and translation taking the group's other markers
    seen in both r and t from r to t (Kabsch, at least 3 markers, not all on a
    line) carry m's position at r to t. The two estimates are blended linearly
    across the gap (weight of r = s + n: (t - s + 1) / (n + 1)); where only one
    is available it is used alone. A fit whose RMS residual exceeds
    ``tolerance`` (the group is not rigid there, or holds a wrong point) is
    not used.

    Parameters
    ----------
    positions : ndarray of shape (T, M, 3)
        Metres, NaN where missing.
    groups : MarkerGroups
        Markers that move as one rigid body (patches; see :func:`layout_groups`).
    max_gap_frames : int
        Frames; longer gaps and gaps at the start or end of the take are not filled.
    tolerance : float
        Metres, largest RMS residual of the rigid fit.

    Returns
    -------
    filled : ndarray of shape (T, M, 3)
    mask : ndarray of bool, shape (T, M)

    See Also
    --------
    handcap.objects.rigid.kabsch
    """
    positions = check_positions(positions)
    groups = _check_groups(groups, positions.shape[1])
    max_gap_frames = check_frames(max_gap_frames, "max_gap_frames (rigid)")
    tolerance = check_positive(tolerance, "rigid tolerance (metres)")
    out = positions.copy()
    mask = np.zeros(positions.shape[:2], bool)
    present = ~np.isnan(positions[..., 0])
    n_frames = positions.shape[0]
    for g in range(len(groups.names)):
        cols = groups.members(g)
        if len(cols) < 4 or max_gap_frames == 0:
            continue
        frames, member, first, length = [], [], [], []
        for j, col in enumerate(cols):
            starts, lengths = runs(~present[:, col])
            ok = (starts > 0) & (starts + lengths < n_frames) & (lengths <= max_gap_frames)
            for s, n in zip(starts[ok], lengths[ok]):
                frames.append(np.arange(s, s + n))
                member += [j] * n
                first += [s] * n
                length += [n] * n
        if not frames:
            continue
        t = np.concatenate(frames)
        member, first, length = np.array(member), np.array(first), np.array(length)
        step = max(1, _BLOCK // (3 * len(cols)))  # gap samples at a time: arrays are (samples, n, 3)
        for a in range(0, len(t), step):
            k = slice(a, a + step)
            value, done = _rigid_fill(positions[:, cols], present[:, cols], t[k], member[k], first[k], length[k],
                                      tolerance)
            out[t[k][done], cols[member[k][done]]] = value[done]
            mask[t[k][done], cols[member[k][done]]] = True
    return out, mask


def _rigid_fill(pts, seen, t, member, first, length, tolerance):
    """Rigid-fill estimates (K, 3) of gap samples (frame t, member) of one group, and where they exist."""
    others = np.ones((len(t), pts.shape[1]), bool)
    others[np.arange(len(t)), member] = False
    estimates, valid = [], []
    for ref in (first - 1, first + length):
        shared = seen[ref] & seen[t] & others
        src, tgt = np.nan_to_num(pts[ref]), np.nan_to_num(pts[t])
        rot, trans = kabsch(src, tgt, shared.astype(np.float64))
        moved = np.einsum("kij,knj->kni", rot, src) + trans[:, None]
        count = shared.sum(axis=1)
        rms = np.sqrt((np.sum((moved - tgt) ** 2, axis=2) * shared).sum(axis=1) / np.maximum(count, 1))
        # The fit must pin down rotations about every axis: not all shared markers on a line.
        centred = np.where(shared[..., None], src - (src * shared[..., None]).sum(1, keepdims=True)
                           / np.maximum(count, 1)[:, None, None], 0.0)
        second = np.linalg.eigvalsh(np.einsum("kni,knj->kij", centred, centred))[:, 1]
        spread = second / np.maximum(count, 1) > RIGID_MIN_SPREAD ** 2
        valid.append((count >= 3) & (rms <= tolerance) & spread)
        estimates.append(np.einsum("kij,kj->ki", rot, pts[ref, member]) + trans)
    w = ((t - first + 1) / (length + 1))[:, None]
    both = valid[0] & valid[1]
    value = np.where(valid[0][:, None], estimates[0], estimates[1])
    value[both] = ((1 - w) * estimates[0] + w * estimates[1])[both]
    return value, valid[0] | valid[1]


# -- all steps -----------------------------------------------------------------------------


def clean_markers(markers: MarkerSequence, layout=None, *, radius: float | None = None, window: int = WINDOW,
                  z: float = Z, floor: float = FLOOR, max_linear_frames: int = MAX_LINEAR,
                  max_rigid_frames: int = MAX_RIGID, max_spline_frames: int = MAX_SPLINE,
                  rigid_tolerance: float = RIGID_TOLERANCE) -> tuple[MarkerSequence, CleanReport]:
    """Remove wrong samples and fill gaps of triangulated markers (DexterCap section 3.3).

    Runs :func:`remove_cluster_outliers` (only with a layout), then
    :func:`remove_window_outliers`, :func:`fill_rigid` (only with a layout),
    :func:`fill_linear` and :func:`fill_spline`, each on the result of the
    one before.

    Parameters
    ----------
    markers : MarkerSequence
        Metres, NaN where missing.
    layout : MarkerLayout or str, optional
        Gives the patches (or segments) for clustering and the rigid fill.
    radius : float, optional
        Cluster radius in metres for every group (default: from the layout).
    window, z, floor
        See :func:`remove_window_outliers` (frames, robust standard deviations, metres).
    max_linear_frames, max_rigid_frames, max_spline_frames : int
        Longest gap, frames, each method fills (0: the method is not used).
    rigid_tolerance : float
        Metres, see :func:`fill_rigid`.

    Returns
    -------
    cleaned : MarkerSequence
        Same names and rate; the residuals (if any) are NaN where removed or filled.
    report : CleanReport

    Raises
    ------
    HandcapError
        Unknown layout, bad window, threshold or gap length.
    """
    positions = markers.positions
    # Check every option before any work, also those of steps a missing layout skips.
    for value, what in ((max_linear_frames, "max_linear_frames"), (max_rigid_frames, "max_rigid_frames"),
                        (max_spline_frames, "max_spline_frames")):
        check_frames(value, what)
    check_odd_window(window)
    check_positive(z, "z (robust standard deviations)")
    check_positive(rigid_tolerance, "rigid tolerance (metres)")
    if radius is not None:
        check_positive(radius, "cluster radius (metres)")
    if not (np.isfinite(floor) and floor >= 0):
        raise HandcapError(f"floor must be a non-negative distance in metres, got {floor}")
    groups = None if layout is None else layout_groups(markers.names, layout, radius=radius)
    nothing = np.zeros(positions.shape[:2], bool)
    clustered = nothing
    if groups is not None:
        positions, clustered = remove_cluster_outliers(positions, groups)
    positions, spikes = remove_window_outliers(positions, window=window, z=z, floor=floor)
    rigid = nothing
    if groups is not None:
        positions, rigid = fill_rigid(positions, groups, max_gap_frames=max_rigid_frames, tolerance=rigid_tolerance)
    positions, linear = fill_linear(positions, max_gap_frames=max_linear_frames)
    positions, spline = fill_spline(positions, max_gap_frames=max_spline_frames)
    residuals = None
    if markers.residuals is not None:
        residuals = markers.residuals.copy()
        residuals[linear | rigid | spline] = np.nan
    cleaned = MarkerSequence(positions, markers.names, markers.rate, residuals)
    report = CleanReport(cluster_removed=clustered, outlier_removed=spikes, rigid_filled=rigid, linear_filled=linear,
                         spline_filled=spline, missing=cleaned.missing, groups=groups)
    return cleaned, report


__all__ = ["CleanReport", "MarkerGroups", "clean_markers", "fill_linear", "fill_rigid", "fill_spline",
           "layout_groups", "remove_cluster_outliers", "remove_window_outliers"]
