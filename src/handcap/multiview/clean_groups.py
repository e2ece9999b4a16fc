"""Which markers move together (a printed patch, else a hand segment), and step 1 of the cleaning.

Step 1 of :func:`handcap.multiview.clean.clean_markers` is :func:`remove_cluster_outliers`: a mislabelled
corner is triangulated where the corner it was mistaken for lies, usually far from its patch-mates, so in
every frame the markers of one group keep the largest cluster of points that all lie within the group's
radius of each other. The groups and their radii come from the layout (:func:`layout_groups`); the rigid
gap fill (:func:`handcap.multiview.clean_gaps.fill_rigid`) uses the same groups.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from handcap.core.checks import check_positions, check_positive
from handcap.core.errors import HandcapError
from handcap.core.grid import MIN_SIDES, grid_cell, grid_sides
from handcap.layouts import MarkerLayout, load_layout

# Default radius of a group from its template: scale x (largest template distance) + margin.
# A printed patch is rigid, but the subject's hand (so the patch's place on it) differs from
# the template by up to ~20 %, and triangulation adds a few millimetres at most.
PATCH_SCALE, PATCH_MARGIN = 1.2, 0.005
# Markers of one hand segment sit on skin, not on one printed piece: skin over the
# joints stretches and slides as the fingers bend, so the allowance is wider.
SEGMENT_SCALE, SEGMENT_MARGIN = 1.5, 0.010
# Elements per block of the windowed arrays (T x markers x 3 x window) of every cleaning step: bounds memory to
# some tens of MB.
BLOCK_ELEMENTS = 2_000_000


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


def layout_groups(names, layout, *, radius: float | None = None, positions=None) -> MarkerGroups:
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
        when a position is not given). A patch whose corners have no positions but grid names
        (``PATCH_r{r}c{c}``: a layout made from a template) takes ``d`` from its grid, the largest distance
        between two of its corners in squares times the take's square side (:func:`handcap.core.grid.grid_sides`
        of ``positions``, the median); without ``positions``, or a group of other names, no radius.
    positions : ndarray (T, M, 3), optional
        The take (metres, NaN missing), to measure the patches' square side in.

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
        unsized = [g for g, idx in enumerate(members) if np.isnan(radii[g]) and len(idx) >= 2
                   and layout.markers[idx[0]].patch is not None]
        if unsized and positions is not None:
            _grid_radii(radii, unsized, [[layout.markers[i].name for i in members[g]] for g in unsized], positions,
                        names)
    return MarkerGroups(labels, tuple(keys), radii)


def _grid_radii(radii, unsized, corner_names, positions, names) -> None:
    """Fill ``radii[g]`` of the patches ``unsized`` from their corners' grid (see :func:`layout_groups`)."""
    sides = grid_sides(check_positions(positions), [str(n) for n in names])  # an OWNER: prefix keeps hands apart
    if len(sides) < MIN_SIDES:
        return
    side = float(np.median(sides))
    for g, group in zip(unsized, corner_names):
        cells = [grid_cell(n) for n in group]
        if any(c is None for c in cells):
            continue
        rc = np.array([(r, c) for _, r, c in cells], float)
        radii[g] = PATCH_SCALE * side * np.linalg.norm(rc[:, None] - rc[None], axis=-1).max() + PATCH_MARGIN


def check_groups(groups: MarkerGroups, n_markers: int) -> MarkerGroups:
    """The groups, checked to label the ``n_markers`` markers (M) of the positions they are used with.

    Parameters
    ----------
    groups : MarkerGroups
        With labels of shape (M,).
    n_markers : int
        Markers M of the positions ``(T, M, 3)``.

    Returns
    -------
    MarkerGroups
        ``groups`` itself.

    Raises
    ------
    HandcapError
        If the groups label another number of markers.
    """
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
    groups = check_groups(groups, positions.shape[1])
    removed = np.zeros(positions.shape[:2], bool)
    for g, radius in enumerate(groups.radii):
        cols = groups.members(g)
        if len(cols) < 2 or not np.isfinite(radius):
            continue
        # Frames in chunks: the distance matrices are (frames, n, n).
        step = max(1, BLOCK_ELEMENTS // (len(cols) ** 2))
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


__all__ = ["BLOCK_ELEMENTS", "PATCH_MARGIN", "PATCH_SCALE", "SEGMENT_MARGIN", "SEGMENT_SCALE", "MarkerGroups",
           "check_groups", "layout_groups", "remove_cluster_outliers"]
