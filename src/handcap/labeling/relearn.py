"""Re-learning the rigid back-of-hand set's shape from an unlabelled take (issue 14).

When the rigid markers' distances changed (a marker stuck back on a few
millimetres away, another glove or subject), the trained :class:`RigidSet`
no longer finds the hand frame. :func:`rigid_from_take` estimates the shape
from the take itself: every frame's triangles of points whose distances are
near the trained ones (within ``width``) are pooled; the triangle shape that
recurs in most frames (within the trained tolerance) is the rigid set,
re-learned. A triangle recurs as often whichever of its corners is taken for
which marker, so every naming within ``width`` is a candidate, and the spatial
model tells them apart. :func:`largest_change` measures how far a re-learned
set is from the trained one.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from handcap.labeling.frame import (
    anchor_triangles,
    complete_pose,
    padded_distances,
    triangles_within,
)
from handcap.labeling.rigid_set import RigidSet
from handcap.labeling.spatial import SpatialModel
from handcap.objects.rigid import canonical_from_markers, kabsch


def rigid_from_take(rigid: RigidSet, frames, *, spatial: SpatialModel | None = None, width: float = 0.01,
                    min_share: float = 0.3, max_frames: int = 400, current: RigidSet | None = None) -> RigidSet | None:
    """The rigid set's shape as an unlabelled take shows it, or None when no shape recurs.

    Parameters
    ----------
    rigid : RigidSet
        The trained set (its tolerance is kept: it is the within-take spread).
    frames : sequence of ndarray (K, 3)
        Unlabelled points per frame, metres.
    spatial : SpatialModel, optional
        The trained spatial model. Other markers rigid with the back of the hand
        (a knuckle marker beside a back marker) make look-alike triangles that
        recur as often as the set's own; with the model, the shape (the
        trained one among them) in whose hand frame the other points fit the
        model best wins. Without it, the recurring shape nearest the trained one.
    width : float
        How far (metres) each distance of the anchor triangle may be from the
        trained one.
    min_share : float
        A shape must be seen in at least this share of the frames searched.
    max_frames : int
        Frames searched (evenly spread over the take).
    current : RigidSet, optional
        A set re-learned before and in use (the online labeler's): judged by the spatial fit with the shapes
        found, which are still searched for near the trained set. Searched for near the set in use instead, one
        wrong set re-learned from a take's first few frames led the next search further off (seed 45 of
        ``benchmarks/labeling.py`` section 9: 7 mm from the trained shape, then 12, then 21).

    Returns
    -------
    RigidSet or None
        The re-learned set (possibly the trained one), its canonical positions
        turned onto the trained ones (so the hand frame moves as little as
        possible).
    """
    frames = [np.asarray(f, dtype=np.float64) for f in frames]
    frames = [f[~np.isnan(f).any(axis=1)] for f in frames]
    step = max(1, len(frames) // max_frames)
    use = [f for f in frames[::step] if len(f) >= 3]
    if len(use) < 3:
        return None
    candidates = _recurring_shapes(rigid, use, width, min_share)
    if not candidates:
        return None
    if spatial is None:
        return candidates[0]
    every = candidates + [rigid] + ([current] if current is not None and current is not rigid else [])
    return every[int(np.argmax(_fits_in_frames(spatial, every, use)))]


#: How far (metres) each side of the rigid set's anchor triangle is searched for from the trained one, when its
#: tolerance is tighter: a marker stuck on again a few millimetres away, another glove or subject. Searched 20 mm
#: wide, a look-alike triangle of finger and knuckle markers won on seed 27 of section 9 of benchmarks/labeling.py
#: (its triad 7.5 mm off: 48 -> 7,948 points labelled wrong online), and seeds 31 and 35 were labelled worse.
RELEARN_WIDTH = 0.01

#: Recurring shapes judged by the spatial fit. In a short stretch of frames the fingers keep their shape too, and
#: triangles of finger and knuckle markers recur as often as the rigid set's own: with 5, a triad 8 % larger
#: re-learned online from its first frames was missed among them (taken for a look-alike, labels withheld for
#: 200 frames); with 20 it was found from the second try on (frame 30).
CANDIDATES = 20


def _anchor(canonical):
    """The largest triangle (a, b, e) of a set and its side lengths (ab, ae, be)."""
    c = canonical
    n = len(c)
    tri = np.array([(i, j, k) for i in range(n) for j in range(i + 1, n) for k in range(j + 1, n)])
    area = np.linalg.norm(np.cross(c[tri[:, 1]] - c[tri[:, 0]], c[tri[:, 2]] - c[tri[:, 0]]), axis=1)
    a, b, e = tri[int(np.argmax(area))]
    sides = np.array([np.linalg.norm(c[a] - c[b]), np.linalg.norm(c[a] - c[e]), np.linalg.norm(c[b] - c[e])])
    return (a, b, e), sides


def _recurring_shapes(rigid: RigidSet, use, width, min_share, most: int = CANDIDATES) -> list:
    """Shapes of the rigid set that recur in the frames ``use``: most frequent first (at most ``most`` triangles,
    each seen in at least 80 % as many frames as the first, in each naming of its corners within ``width`` of the
    trained sides), each a RigidSet."""
    c, tol = rigid.canonical, rigid.tolerance
    (a, b, e), trained = _anchor(c)
    points, dist = padded_distances(use)
    found = triangles_within(dist, trained, width)  # (n, 4): the frame, then the points a, b, e
    if not len(found):
        return []
    owner, where = found[:, 0], found[:, 1:]
    sides = np.stack([dist[owner, where[:, 0], where[:, 1]], dist[owner, where[:, 0], where[:, 2]],
                      dist[owner, where[:, 1], where[:, 2]]], axis=1)
    # For every candidate shape, in how many frames a triangle of that shape (within the tolerance) appears.
    probe = np.linspace(0, len(sides) - 1, min(len(sides), 300)).astype(int)
    near = cKDTree(sides).query_ball_point(sides[probe], r=tol, p=np.inf)  # the shapes within tol, side by side
    frames_with = np.zeros(len(probe), int)
    for i, (q, row) in enumerate(zip(probe, near)):
        row = np.asarray(row, dtype=int)
        frames_with[i] = len(np.unique(owner[row[(np.abs(sides[row] - sides[q]) < tol).all(axis=1)]]))
    if frames_with.max() < min_share * len(use):
        return []
    out, chosen = [], []
    # Most frequent first; among shapes seen as often (a short stretch of frames, where fingers keep their
    # shape too), the nearest the trained shape first.
    offset = np.abs(sides[probe] - trained).max(axis=1)
    triangles = 0
    for p in np.lexsort((offset, -frames_with)):
        if frames_with[p] < 0.8 * frames_with.max() or triangles == most:
            break
        if any((np.abs(sides[probe[p]] - other) < tol).all() for other in chosen):
            continue
        triangles += 1
        # The same triangle with its corners named otherwise recurs as often: the spatial fit tells them apart.
        for shape in _orderings(sides[probe[p]], trained, width):
            if any((np.abs(shape - other) < tol).all() for other in chosen):
                continue
            found = _shape_in_frames(rigid, use, points, sides, owner, where, shape, (a, b, e), width)
            if found is not None:
                chosen.append(shape)
                out.append(found)
    if not out:
        return []
    # Every shape's markers estimated at once (each as alone), then turned onto the trained shape.
    shapes = canonical_from_markers(np.stack(out))
    return [RigidSet(rigid.names, new @ rot.T + trans, tol) for new in shapes for rot, trans in [kabsch(new, c)]]


def _orderings(shape, trained, width) -> list:
    """A triangle's side lengths (ab, ae, be) for each naming of its corners whose sides lie within ``width`` of
    ``trained``'s, the given naming first."""
    length = {(0, 1): shape[0], (0, 2): shape[1], (1, 2): shape[2]}
    out = []
    for x, y, z in ((0, 1, 2), (0, 2, 1), (1, 0, 2), (1, 2, 0), (2, 0, 1), (2, 1, 0)):
        named = np.array([length[tuple(sorted(pair))] for pair in ((x, y), (x, z), (y, z))])
        if (np.abs(named - trained) < width).all():
            out.append(named)
    return out


def _shape_in_frames(rigid, use, points, sides, owner, where, shape, anchor, width) -> np.ndarray | None:
    """The rigid set's markers (T, R, 3) in each frame of ``use`` (``points``: the same, padded) from the triangles
    of one shape, one per frame (and the other markers near their places), NaN where not seen. None when fewer
    than three frames show the shape or some marker is never seen."""
    c, tol = rigid.canonical, rigid.tolerance
    n = len(c)
    a, b, e = anchor
    rows = np.flatnonzero((np.abs(sides - shape) < tol).all(axis=-1))
    if len(np.unique(owner[rows])) < 3:
        return None
    err = np.abs(sides[rows] - shape).max(axis=1)
    rows = rows[np.lexsort((err, owner[rows]))]  # by frame, then error (ties in row order: lexsort is stable)
    rows = rows[np.r_[True, owner[rows][1:] != owner[rows][:-1]]]  # each frame's closest triangle
    positions = np.full((len(use), n, 3), np.nan)
    positions[owner[rows][:, None], [a, b, e]] = points[owner[rows][:, None], where[rows]]
    for t, (i, j, k) in zip(owner[rows], where[rows]) if n > 3 else ():
        # The other markers: the point nearest where the trained shape puts them.
        pts = use[t]
        rot, trans = kabsch(c[[a, b, e]], pts[[i, j, k]])
        taken = {int(i), int(j), int(k)}
        for r in range(n):
            if r in (a, b, e):
                continue
            d = np.linalg.norm(pts - (rot @ c[r] + trans), axis=1)
            d[list(taken)] = np.inf
            p = int(np.argmin(d))
            if d[p] < width:
                positions[t, r] = pts[p]
                taken.add(p)
    if not (~np.isnan(positions[..., 0])).any(axis=0).all():
        return None
    return positions


def _fits_in_frames(spatial: SpatialModel, sets, use, *, most: int = 20, floor: float = -2.0) -> np.ndarray:
    """How well the other points of frames ``use`` fit the spatial model in the hand frame each of ``sets``
    gives: the mean over points of the best label's log-likelihood (at least ``floor``), frames without the set
    counting every point at the floor; -inf for a set found in none. No label-free registration first: the
    candidates' shapes are turned onto the trained one, and a registration lets a wrong frame fit too. Every
    ``len(use) // most``-th frame is judged (all of 10 to 39 frames: with at most 20 of 35, seed 37 of
    ``benchmarks/labeling.py`` section 9 re-learned a look-alike, 345 -> 7,166 points labelled wrong)."""
    frames = use[:: max(1, len(use) // most)]
    padded = padded_distances(frames)
    poses = [(s, f, pose) for s, row in enumerate(search_frames(sets, frames, padded))
             for f, pose in enumerate(row) if pose is not None]
    sizes = np.array([len(pts) for pts in frames])
    fits = np.full(len(sets), -np.inf)
    if not poses:
        return fits
    owner, frame = (np.array(column) for column in list(zip(*poses))[:2])
    missing = sizes.sum() - np.bincount(owner, weights=sizes[frame], minlength=len(sets))
    rot = np.stack([pose.rotation for _, _, pose in poses])
    trans = np.stack([pose.translation for _, _, pose in poses])
    local = np.einsum("pkj,pji->pki", padded[0][frame] - trans[:, None], rot)  # every pose's points, hand frame
    others = ~np.isnan(local[..., 0])
    used = np.stack([pose.points for _, _, pose in poses])  # the set's own markers are not judged
    row, column = np.nonzero(used >= 0)
    others[row, used[row, column]] = False
    best = np.maximum(spatial.log_likelihood(local[others]).max(axis=0), floor)  # every set's at once
    point_owner = np.broadcast_to(owner[:, None], others.shape)[others]
    for s in np.unique(owner):
        mine = best[point_owner == s]
        fits[s] = (mine.sum() + floor * missing[s]) / (len(mine) + missing[s])
    return fits


def search_frames(rigids, frames, padded=None) -> list:
    """Each rigid set's pose in each frame searched afresh (as :meth:`handcap.labeling.frame.HandFrameFinder.find`
    gives it after a reset, without a fit: anchor triangles by distances, scored by their fit and support), batched
    over the sets and the frames: re-learning the rigid set judges many candidate sets in the same frames.

    Parameters
    ----------
    rigids : sequence of RigidSet
        Sets of the same number of markers.
    frames : sequence of ndarray (K, 3)
        Points per frame (no NaN), metres.
    padded : tuple, optional
        :func:`handcap.labeling.frame.padded_distances` of ``frames``, when the caller has it.

    Returns
    -------
    list of list of HandPose or None
        Per set, one per frame; None where the set is not found.
    """
    out: list = [[None] * len(frames) for _ in rigids]
    sizes = np.array([len(f) for f in frames], dtype=int)
    if not len(frames) or not len(rigids) or sizes.max() < 3:
        return out
    pts, dist = padded_distances(frames) if padded is None else padded  # NaN: never within a tolerance
    few = (sizes < 3)[:, None, None]
    if few.any():  # (a frame of fewer than 3 points is not searched)
        pts, dist = np.where(few, np.nan, pts), np.where(few, np.nan, dist)
    canon = np.stack([r.canonical for r in rigids])  # (S, R, 3)
    tol = np.array([r.tolerance for r in rigids])
    found, anchor, owner = [], [], []
    for s, c in enumerate(canon):
        sides = np.linalg.norm(c[:, None] - c[None], axis=-1)
        for a, b, d in anchor_triangles(c):
            found.append(triangles_within(dist, sides[[a, a, b], [b, d, d]], tol[s]))  # frame, points for a, b, d
            anchor.append(np.broadcast_to((a, b, d), (len(found[-1]), 3)))
            owner.append(np.full(len(found[-1]), s))
    cand, anchor, owner = np.concatenate(found), np.concatenate(anchor), np.concatenate(owner)
    if not len(cand):
        return out
    order = np.lexsort((cand[:, 0], owner))  # set by set, frame by frame, each in the finder's order (stable)
    cand, anchor, owner = cand[order], anchor[order], owner[order]
    frame, cand = cand[:, 0], cand[:, 1:]
    target, src, t = pts[frame[:, None], cand], canon[owner[:, None], anchor], tol[owner]
    rot, trans = kabsch(src, target)
    resid = np.linalg.norm(np.einsum("nij,nrj->nri", rot, src) + trans[:, None] - target, axis=-1)
    score = (resid**2).sum(axis=1) / t**2
    score[resid.max(axis=1) > t] = np.inf
    # Each candidate's markers where it puts them: how many have a point there (its support).
    placed = np.einsum("nij,nrj->nri", rot, canon[owner]) + trans[:, None]
    gap = np.linalg.norm(placed[:, :, None] - pts[frame][:, None], axis=-1)
    support = (np.where(np.isnan(gap), np.inf, gap).min(axis=2) < t[:, None]).sum(axis=1)
    score[support < (3 if canon.shape[1] <= 4 else 4)] = np.inf
    score -= 2.0 * support
    key = owner * len(frames) + frame
    first = np.lexsort((np.arange(len(score)), score, key))  # each set's and frame's lowest score, first of ties
    first = first[np.r_[True, key[first][1:] != key[first][:-1]]]
    for m in first[np.isfinite(score[first])]:
        index = np.full(canon.shape[1], -1)
        index[anchor[m]] = cand[m]
        out[owner[m]][frame[m]] = complete_pose(frames[frame[m]], rigids[owner[m]], rot[m], trans[m], index)
    return out


def largest_change(a: RigidSet, b: RigidSet) -> float:
    """Largest difference between the two sets' marker distances.

    Parameters
    ----------
    a, b : RigidSet
        Two shapes of the same markers (same names, same order), canonical positions (R, 3) in metres.

    Returns
    -------
    float
        The largest change of a pairwise distance, metres.
    """
    i, j = np.triu_indices(len(a.names), 1)
    return float(np.abs(np.linalg.norm(a.canonical[i] - a.canonical[j], axis=1)
                        - np.linalg.norm(b.canonical[i] - b.canonical[j], axis=1)).max())
