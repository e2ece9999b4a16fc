"""A rigid body nobody named: an object's markers found among the points a labelling leaves.

A hand-object take whose object was not given to the labeler (``objects=``) has the object's markers among the
candidates of the fingers: a synthetic glove-13 grasp of a cylinder was 0.83 % labelled wrong (object markers
taken for fingertips) where it is 0 % with the cylinder known. The object keeps its markers' distances, as no
set of the hand's leftover points or ghosts does over a whole take. :func:`find_rigid_body` finds it:

1. in frames spread over the take, every triangle of leftover points (sides
   :data:`MIN_SIDE`-:data:`MAX_SIDE`, at least half :data:`MIN_SIDE` high over its longest side, no two sides
   within 2 :data:`SIDE_TOLERANCE`, so its corners are told apart by the sides opposite them) is pooled by its
   sorted sides;
2. the shape seen (within :data:`SIDE_TOLERANCE` on each side) in most frames, at least ``min_share`` of them,
   and once in a frame (:data:`AMBIGUOUS`), anchors the body;
3. in the frame of that triangle, the other leftover points that sit at one spot (within
   :data:`SPOT_RADIUS`) in at least ``min_share`` of the anchored frames are the body's other markers.

Its shape is then a :class:`RigidSet` (:meth:`RigidSet.for_object`), which the labeler finds like a known
object's.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from handcap.labeling.rigid_set import RigidSet

#: Shortest and longest triangle side searched (metres): marker clusters on objects and tools.
MIN_SIDE, MAX_SIDE = 0.01, 0.3
#: How much a side may differ between frames (metres): a rigid body's distances within the reconstruction noise.
SIDE_TOLERANCE = 0.001
#: How near its spot a further marker must be in the anchor triangle's frame (metres).
SPOT_RADIUS = 0.002
#: A shape matched by more than one triangle in more than this share of its frames (congruent triangles of a body
#: partly symmetric, such as markers round a cylinder) may be anchored on other markers from frame to frame, and the
#: body's other markers found in its frame then come out doubled: such a shape anchors the body only where every
#: shape seen as often is (a body symmetric as a whole, whose other markers fall on one another).
AMBIGUOUS = 0.1
#: Frames with more leftover points than this are not searched (their triangles grow as the cube of the count).
MOST_POINTS = 30
#: Most triangles pooled (fewer frames are searched where they hold many points): about a second's search.
TRIANGLE_BUDGET = 60_000


def find_rigid_body(frames, *, min_share: float = 0.3, max_frames: int = 300, name: str = "object") -> RigidSet | None:
    """The rigid body among leftover points (see the module docstring), or None when no shape recurs.

    Parameters
    ----------
    frames : sequence of ndarray (K, 3)
        Each frame's points no label was given, metres.
    min_share : float
        Share of the frames searched that must show the body's anchor triangle (and of those, each further marker).
    max_frames : int
        Frames searched, evenly spread over the take.
    name : str
        The body's marker names are ``name:0``, ``name:1``, ...

    Returns
    -------
    RigidSet or None
        Its markers in their own frame (metres), tolerance :meth:`RigidSet.for_object`'s.
    """
    frames = [np.asarray(f, dtype=np.float64).reshape(-1, 3) for f in frames]
    frames = [f[np.isfinite(f).all(axis=1)] for f in frames]
    pick = np.unique(np.linspace(0, len(frames) - 1, min(max_frames, len(frames))).astype(int)) if frames else []
    searched = [frames[i] for i in pick if 3 <= len(frames[i]) <= MOST_POINTS]
    if not searched or len(searched) < min_share * len(pick):
        return None
    counts = np.array([len(f) for f in searched])
    total = int((counts * (counts - 1) * (counts - 2) // 6).sum())
    if total > TRIANGLE_BUDGET:  # every k-th frame: the share a shape is seen in stays what it was
        searched = searched[::-(-total // TRIANGLE_BUDGET)]
        pick = pick[::-(-total // TRIANGLE_BUDGET)]
    shapes, owners, corners = _triangles(searched)
    if not len(shapes):
        return None
    candidates = []  # (centre, members, ambiguous) of the shapes seen in enough frames, the most first
    for centre in _most_frames(shapes, owners):
        members = np.flatnonzero(np.abs(shapes - centre).max(axis=1) <= SIDE_TOLERANCE)
        held, times = np.unique(owners[members], return_counts=True)
        if len(held) >= min_share * len(pick):
            candidates.append((centre, members, (times > 1).mean() > AMBIGUOUS))
    if not candidates:
        return None
    # The first seen once a frame; else (a body symmetric as a whole, every triangle twice) the first.
    centre, members, _ = next((c for c in candidates if not c[2]), candidates[0])
    # One matching triangle per frame (the nearest shape), its corners in a fixed order.
    order = np.argsort(np.abs(shapes[members] - centre).max(axis=1), kind="stable")
    _, first = np.unique(owners[members[order]], return_index=True)
    chosen = members[order[first]]
    local, spots = [], []
    for k in chosen:
        pts = searched[owners[k]]
        rot, origin = _triangle_frame(pts[corners[k]])
        others = np.delete(pts, corners[k], axis=0)
        local.append((pts[corners[k]] - origin) @ rot)
        spots.append((others - origin) @ rot)
    anchor = np.mean(local, axis=0)  # (3, 3)
    extra = _recurring_spots(spots, min_share * len(chosen))
    canonical = np.vstack([anchor, extra])
    canonical -= canonical.mean(axis=0)
    return RigidSet.for_object([f"{name}:{i}" for i in range(len(canonical))], canonical)


def _triangles(frames):
    """Every frame's triangles with sides in range and told apart: sorted sides (N, 3), frame (N,), corners (N, 3)
    (corner j opposite side j)."""
    shapes, owners, corners = [], [], []
    for f, pts in enumerate(frames):
        i, j, k = (a.ravel() for a in np.meshgrid(*(np.arange(len(pts)),) * 3, indexing="ij"))
        keep = (i < j) & (j < k)
        tri = np.stack([i[keep], j[keep], k[keep]], axis=1)  # (n, 3)
        p = pts[tri]
        sides = np.stack([np.linalg.norm(p[:, 1] - p[:, 2], axis=1), np.linalg.norm(p[:, 0] - p[:, 2], axis=1),
                          np.linalg.norm(p[:, 0] - p[:, 1], axis=1)], axis=1)  # side c opposite corner c
        order = np.argsort(sides, axis=1)
        sides = np.take_along_axis(sides, order, axis=1)
        height = np.linalg.norm(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), axis=1) / np.maximum(sides[:, 2],
                                                                                                      1e-12)
        ok = ((sides[:, 0] >= MIN_SIDE) & (sides[:, 2] <= MAX_SIDE) & (height >= 0.5 * MIN_SIDE)
              & (np.diff(sides, axis=1).min(axis=1) > 2 * SIDE_TOLERANCE))
        shapes.append(sides[ok])
        corners.append(np.take_along_axis(tri, order, axis=1)[ok])
        owners.append(np.full(int(ok.sum()), f))
    return np.concatenate(shapes), np.concatenate(owners), np.concatenate(corners)


def _most_frames(shapes, owners, most: int = 10) -> list:
    """The shapes (3,) seen in most frames, the most first: on a grid of :data:`SIDE_TOLERANCE` cells, the ``most``
    cells whose blocks of 3 x 3 x 3 cells hold shapes of most frames; the median of each block's shapes."""
    cells = np.floor(shapes / SIDE_TOLERANCE).astype(np.int64) + 1  # 1 .. side / tolerance + 1
    size, frames = int(cells.max()) + 2, int(owners.max()) + 1
    offsets = np.stack(np.meshgrid(*([np.arange(-1, 2)] * 3), indexing="ij"), axis=-1).reshape(-1, 3)
    block = ((cells[:, None] + offsets[None]) @ np.array([size * size, size, 1])).ravel()  # each block a shape is in
    pairs = np.sort(block * frames + np.repeat(owners, len(offsets)))
    pairs = pairs[np.r_[True, pairs[1:] != pairs[:-1]]] // frames  # each (block, frame) once: its block
    starts = np.flatnonzero(np.r_[True, pairs[1:] != pairs[:-1]])  # pairs are sorted by block
    seen = np.diff(np.r_[starts, len(pairs)])
    out = []
    for k in np.argsort(-seen, kind="stable")[:most]:
        best = np.array(np.unravel_index(int(pairs[starts[k]]), (size, size, size)))
        out.append(np.median(shapes[(np.abs(cells - best) <= 1).all(axis=1)], axis=0))
    return out


def _triangle_frame(corners):
    """Rotation (3, 3) and origin (3,) of a triangle's own frame: origin its first corner, x towards the second,
    z normal to its plane."""
    x = corners[1] - corners[0]
    x /= np.linalg.norm(x)
    z = np.cross(x, corners[2] - corners[0])
    z /= np.linalg.norm(z)
    return np.stack([x, np.cross(z, x), z], axis=1), corners[0]


def _recurring_spots(spots, least: float) -> np.ndarray:
    """Spots (S, 3) where points of at least ``least`` frames sit within :data:`SPOT_RADIUS` (one point a frame),
    from each frame's points in the anchor's frame; the most frequent first, each spot's points taken once."""
    points = np.concatenate(spots) if spots else np.zeros((0, 3))
    owner = np.concatenate([np.full(len(s), i) for i, s in enumerate(spots)]) if spots else np.zeros(0, int)
    found = []
    free = np.ones(len(points), dtype=bool)
    tree = cKDTree(points) if len(points) else None
    while free.any():
        near = [np.array([m for m in tree.query_ball_point(points[i], SPOT_RADIUS) if free[m]], dtype=int)
                for i in np.flatnonzero(free)]
        counts = np.array([len(np.unique(owner[n])) for n in near])
        best = int(np.argmax(counts))
        if counts[best] < least:
            break
        members = near[best]
        found.append(np.median(points[members], axis=0))
        free[members] = False
    return np.array(found).reshape(-1, 3)
