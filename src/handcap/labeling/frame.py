"""The hand's local frame from its rigid back-of-hand markers, found among unlabeled points.

The rigid markers (three or more: the triad on the back of a glove, or the
markers of a held object) keep their distances to each other. A set is
tracked from frame to frame: each marker takes the point nearest its place in
the previous pose, and claimed points that break the rigid distances are
dropped (a ghost or a fingertip near a hidden marker's place). When some
marker is missing, the set is also searched for afresh: triangles of points
whose distances match one of a few anchor triangles of markers (the largest,
and for each of its markers the largest without it, so that one hidden marker
hides no object), each candidate pose scored by its distance error, by how
many markers it explains (an object needs four), by how far it moved since
the previous frame and, when the caller gives one, by how well the other
points fit the spatial model in that frame. Kabsch then gives the rotation
and translation that map hand-frame coordinates to the world:
``world = R @ local + t``.

When only two markers can be tracked, they correct the previous transform
(the missing ones are held weakly where they were); with fewer, the previous
transform is kept for a few frames and the frame is reported as lost after
that. :func:`find_objects` finds each rigid object's markers in a frame
(before the hand's, by the labelers).

The rigid set itself (its shape and tolerance, learned from labeled takes)
is :mod:`handcap.labeling.rigid_set`'s.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from handcap.labeling.rigid_set import OBJECT_MIN_TOLERANCE, RigidSet, objects_from_take
from handcap.objects.rigid import kabsch

# RigidSet and its helpers live in handcap.labeling.rigid_set; re-exported here so older imports keep working.
__all__ = ["OBJECT_MIN_TOLERANCE", "HandFrameFinder", "HandPose", "RigidSet", "anchor_triangles", "complete_pose",
           "objects_from_take", "padded_distances", "triangles_within"]


def _kabsch(source, target, weights=None):
    """One frame of :func:`handcap.objects.rigid.kabsch` (N, 3) -> (R, t), without the batch machinery
    (a streaming labeler runs it every frame: few numpy calls, the determinant in plain Python)."""
    if weights is None:
        share = 1.0 / len(source)  # (ndarray.mean costs more than the sum here)
        src_mean, tgt_mean = source.sum(axis=0) * share, target.sum(axis=0) * share
        cov = (target - tgt_mean).T @ (source - src_mean)
    else:
        w = weights / weights.sum()
        src_mean, tgt_mean = w @ source, w @ target
        cov = ((target - tgt_mean) * w[:, None]).T @ (source - src_mean)
    u, _, vt = np.linalg.svd(cov)
    rot = u @ vt
    (a, b, c), (d, e, f), (g, h, i) = rot.tolist()
    if a * (e * i - f * h) - b * (d * i - f * g) + c * (d * h - e * g) < 0:
        u[:, -1] = -u[:, -1]
        rot = u @ vt
    return rot, tgt_mean - rot @ src_mean


@dataclass
class HandPose:
    """Hand frame of one frame: ``world = rotation @ local + translation``; ``points`` (R,) index or -1."""

    rotation: np.ndarray
    translation: np.ndarray
    points: np.ndarray
    found: bool


def triangles_within(dist, sides, tol):
    """Every triangle of points whose side lengths are within ``tol`` of ``sides``.

    Parameters
    ----------
    dist : ndarray (..., K, K)
        Distances between the points (of each frame), metres; NaN never matches.
    sides : sequence of 3 float
        The wanted lengths of sides ab, ad and bd, metres.
    tol : float
        How far each side may be off, metres.

    Returns
    -------
    ndarray (n, dist.ndim + 1) int
        The leading indices (a frame's), then the points a, b, d: in ``np.argwhere``'s order over
        ``(...)[a, b, d]``, as the whole (..., K, K, K) test would list them.
    """
    ab = np.argwhere(np.abs(dist - sides[0]) < tol)  # few pairs: then only their third points are tested
    lead, a, b = tuple(ab[:, :-2].T), ab[:, -2], ab[:, -1]
    third = (np.abs(dist[(*lead, a)] - sides[1]) < tol) & (np.abs(dist[(*lead, b)] - sides[2]) < tol)
    row, d = np.nonzero(third)
    return np.column_stack([ab[row], d])


def padded_distances(frames):
    """The frames' points side by side, padded with NaN, and the distances between each frame's points.

    Parameters
    ----------
    frames : sequence of ndarray (K, 3)
        Points per frame, metres (at least one frame).

    Returns
    -------
    points : ndarray (F, K_max, 3)
        NaN past each frame's own points.
    dist : ndarray (F, K_max, K_max)
        Metres; NaN where either point is padding.
    """
    points = np.full((len(frames), max(len(f) for f in frames), 3), np.nan)
    for f, pts in enumerate(frames):
        points[f, :len(pts)] = pts
    return points, np.linalg.norm(points[:, :, None] - points[:, None], axis=-1)


def anchor_triangles(canonical) -> np.ndarray:
    """The triangles (A, 3) of a rigid set's markers (R, 3) that anchor the search: the largest, then for each of
    its markers the largest without it, so that one hidden marker does not hide an object."""
    c = np.asarray(canonical, dtype=np.float64)
    n = len(c)
    tri = np.array([(i, j, k) for i in range(n) for j in range(i + 1, n) for k in range(j + 1, n)])
    order = tri[np.argsort(-np.linalg.norm(np.cross(c[tri[:, 1]] - c[tri[:, 0]], c[tri[:, 2]] - c[tri[:, 0]]),
                                           axis=1), kind="stable")]
    anchors = [order[0]] + [order[~(order == m).any(axis=1)][0] for m in order[0] if n > 3]
    return np.unique(np.array(anchors), axis=0)


def complete_pose(points, rigid: RigidSet, rot, trans, index) -> HandPose:
    """A pose found from an anchor triangle, with the set's other markers added near their predicted places
    (within the tolerance, a point each) and refitted on all found.

    Parameters
    ----------
    points : ndarray (K, 3)
        The frame's points, metres.
    rigid : RigidSet
    rot, trans : ndarray (3, 3), ndarray (3,)
        The anchor's pose, ``world = rot @ local + trans``.
    index : ndarray (R,) int
        Each marker's point, -1 where not yet placed (changed in place).
    """
    c = rigid.canonical
    predicted = c @ rot.T + trans
    taken = set(index[index >= 0].tolist())
    for r in np.flatnonzero(index < 0):
        d = np.linalg.norm(points - predicted[r], axis=1)
        for p in np.argsort(d):
            if d[p] > rigid.tolerance:
                break
            if p not in taken:
                index[r] = p
                taken.add(int(p))
                break
    found = index >= 0
    if found.sum() > 3:
        rot, trans = _kabsch(c[found], points[index[found]])
    return HandPose(rot, trans, index, True)

class HandFrameFinder:
    """Finds a hand's rigid markers frame after frame (keeps the previous pose).

    Parameters
    ----------
    rigid : RigidSet
    max_hold : int
        Frames the previous transform is kept when the rigid markers cannot be found.
    search_radius : float
        How far from their predicted place markers are looked for when fewer
        than three are found, metres.
    jump_scale : float
        A candidate whose markers moved this far (mean, metres) since the
        previous frame pays as much as one at the distance tolerance. Soft: a
        wrong previous frame must not lock the right one out.
    max_jump : float
        While the previous pose is known (or held), a set found further
        than this per frame (mean, metres) is refused.

    Attributes
    ----------
    suspect : bool
        Set by the caller when the last frame fitted poorly: the next frame is
        searched afresh even when every marker is where it was, and the
        candidates are ranked without regard to the previous pose.
    """

    def __init__(self, rigid: RigidSet, *, max_hold: int = 10, search_radius: float = 0.02,
                 jump_scale: float = 0.02, max_jump: float = 0.1):
        self.rigid = rigid
        self.max_hold = max_hold
        self.search_radius = search_radius
        self.jump_scale = jump_scale
        self.max_jump = max_jump
        self.full_set_bonus = 3.0  # log-likelihood a full set found by distances is preferred by
        self.previous: HandPose | None = None
        self.held = 0
        self.suspect = False
        c = rigid.canonical
        n = len(c)
        self._canon_dist = np.linalg.norm(c[:, None] - c[None], axis=-1)
        self._rows = np.arange(n)
        self._pair_i, self._pair_j = np.triu_indices(n, 1)
        self._pair_dist = self._canon_dist[self._pair_i, self._pair_j]
        self._anchors = anchor_triangles(c)
        self.min_found = 3 if n <= 4 else 4  # markers a candidate must explain

    def reset(self) -> None:
        """Forget the previous pose: the next frame is searched afresh."""
        self.previous = None
        self.held = 0

    def find(self, points, fit=None) -> HandPose | None:
        """The hand pose in a frame of points (K, 3); None when it is lost.

        Parameters
        ----------
        points : ndarray (K, 3)
        fit : callable (rotation, translation, used) -> float, optional
            How well the other points fit in a candidate frame (log-likelihood,
            higher is better; ``used`` is the (R,) point index of the rigid
            markers); a tenth of it counts against a squared tolerance of
            distance error.

        Returns
        -------
        HandPose or None
            ``found`` is False when the pose was carried over from an earlier frame.
        """
        points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        tracked = self._from_previous(points) if self.previous is not None and self.held == 0 else None
        if tracked is not None and (tracked.points >= 0).all() and not self.suspect:
            pose = tracked  # every rigid marker where the previous frame puts it
        else:
            pose = self._search(points, fit)
            if pose is None:
                pose = tracked
            elif tracked is not None and not np.array_equal(tracked.points, pose.points):
                # Markers tracked, or a set found elsewhere by distances (which may have borrowed another
                # marker for a missing one): keep whichever explains more markers, or, for a hand, the
                # other points better.
                if fit is not None:
                    # The search's own ranking: a tenth of the fit against the squared jump.
                    def cost(p):
                        jump = 0.0 if self.suspect else (self._moved(p) / self.jump_scale) ** 2
                        return -0.1 * fit(p.rotation, p.translation, p.points) + jump
                    if cost(tracked) < cost(pose) - 0.1 * self.full_set_bonus:
                        pose = tracked
                elif (tracked.points >= 0).sum() >= (pose.points >= 0).sum() or \
                        self._moved(pose) > self.search_radius:
                    pose = tracked
        if pose is not None:
            self.previous, self.held = pose, 0
            return pose
        if self.previous is not None and self.held < self.max_hold:
            self.held += 1
            prev = self.previous
            return HandPose(prev.rotation, prev.translation, np.full(len(self.rigid.names), -1), False)
        self.previous = None
        return None

    def _moved(self, pose: HandPose) -> float:
        """Mean distance (metres) the rigid markers moved from the previous pose to ``pose``."""
        c, prev = self.rigid.canonical, self.previous
        return float(np.linalg.norm(c @ (pose.rotation - prev.rotation).T + pose.translation - prev.translation,
                                    axis=1).mean())

    def _search(self, points, fit=None) -> HandPose | None:
        """Anchor triangles of rigid markers by distance matching, then the other markers near their places."""
        k = len(points)
        if k < 3:
            return None
        c, tol = self.rigid.canonical, self.rigid.tolerance
        dist = np.linalg.norm(points[:, None] - points[None], axis=-1)
        cands, anchors = [], []
        for a, b, d in self._anchors:
            found = triangles_within(dist, self._canon_dist[[a, a, b], [b, d, d]], tol)  # points for a, b, d
            cands.append(found)
            anchors.append(np.broadcast_to((a, b, d), found.shape))
        cand, anchor = np.concatenate(cands), np.concatenate(anchors)
        if not len(cand):
            return None
        src = c[anchor]  # (n, 3, 3)
        rot, trans = kabsch(src, points[cand])
        # Every distance within tolerance can still leave a poor fit; refuse those.
        resid = np.linalg.norm(np.einsum("nij,nrj->nri", rot, src) + trans[:, None] - points[cand], axis=-1)
        score = (resid**2).sum(axis=1) / tol**2
        score[resid.max(axis=1) > tol] = np.inf
        # Each candidate's markers where it puts them: how many have a point there (its support).
        placed = np.einsum("nij,rj->nri", rot, c) + trans[:, None]  # (n, R, 3)
        near = np.linalg.norm(placed[:, :, None] - points[None, None], axis=-1).min(axis=2)  # (n, R)
        support = (near < tol).sum(axis=1)
        score[support < min(self.min_found, len(c))] = np.inf
        score -= 2.0 * support
        if self.previous is not None and not self.suspect:  # held frames since: it may have gone further
            moved = np.linalg.norm(placed - (c @ self.previous.rotation.T + self.previous.translation),
                                   axis=-1).mean(axis=1) / (1 + self.held)
            score += (moved / self.jump_scale) ** 2
            # Further than max_jump per frame is another set of the same shape (the other hand's, or a
            # look-alike), never this one: it is lost rather than taken for that.
            score[moved > self.max_jump] = np.inf
        if fit is not None:
            for n in np.flatnonzero(np.isfinite(score)):
                used = np.full(len(c), -1)
                used[anchor[n]] = cand[n]
                score[n] -= 0.1 * fit(rot[n], trans[n], used)
        best = int(np.argmin(score))
        if not np.isfinite(score[best]):
            return None
        index = np.full(len(c), -1)
        index[anchor[best]] = cand[best]
        return self._complete(points, rot[best], trans[best], index)

    def _complete(self, points, rot, trans, index) -> HandPose:
        """Add the other rigid markers near their predicted places and refit on all found."""
        return complete_pose(points, self.rigid, rot, trans, index)

    def _from_previous(self, points) -> HandPose | None:
        """Two or more rigid markers near their previous places: correct the previous transform."""
        prev = self.previous
        c, tol = self.rigid.canonical, self.rigid.tolerance
        predicted = c @ prev.rotation.T + prev.translation
        if not len(points):
            return None
        diff = points[None] - predicted[:, None]
        d = np.sqrt(np.einsum("rkx,rkx->rk", diff, diff))  # (R, K)
        nearest = d.argmin(axis=1)
        if d[self._rows, nearest].max() < self.search_radius and len(set(nearest.tolist())) == len(c):
            # The usual frame: every marker has its own point near its place, at the rigid distances.
            p = points[nearest]
            e = p[self._pair_i] - p[self._pair_j]
            if (np.abs(np.sqrt(np.einsum("px,px->p", e, e)) - self._pair_dist) <= tol).all():
                rot, trans = _kabsch(c, p)
                return HandPose(rot, trans, nearest, True)
        index = np.full(len(c), -1)
        taken = set()
        for r in np.argsort(d.min(axis=1)):
            p = int(np.argmin(d[r]))
            if d[r, p] < self.search_radius and p not in taken:
                index[r] = p
                taken.add(p)
        # Another point that came near a hidden marker's old place (a ghost, a fingertip) must not be taken
        # for it: the claimed points have to keep the rigid distances among themselves.
        index = self._consistent(points, index, d)
        found = index >= 0
        if found.sum() < 2:
            return None
        if found.all():
            rot, trans = _kabsch(c, points[index])
            return HandPose(rot, trans, index, True)
        # Found markers at full weight; the missing ones where the previous frame put them, weakly.
        target = np.where(found[:, None], points[np.maximum(index, 0)], predicted)
        rot, trans = _kabsch(c, target, np.where(found, 1.0, 0.05))
        # A missing marker may be a point that was further from its old place than another one.
        now = c @ rot.T + trans
        for r in np.flatnonzero(~found):
            near = np.linalg.norm(points - now[r], axis=1)
            near[index[found]] = np.inf
            p = int(np.argmin(near))
            if near[p] < tol:
                index[r] = p
        if (index >= 0).sum() > found.sum():
            index = self._consistent(points, index, d)
            found = index >= 0
            target = np.where(found[:, None], points[np.maximum(index, 0)], predicted)
            rot, trans = _kabsch(c, target, np.where(found, 1.0, 0.05))
        return HandPose(rot, trans, index, True)

    def _consistent(self, points, index, dist) -> np.ndarray:
        """Drop claimed points (index (R,), -1 none) until their pairwise distances match the rigid ones;
        the marker with the most mismatches goes first, then the one further from its old place
        (``dist`` (R, K))."""
        index = index.copy()
        tol = self.rigid.tolerance
        while (index >= 0).sum() >= 2:
            f = np.flatnonzero(index >= 0)
            p = points[index[f]]
            err = np.abs(np.linalg.norm(p[:, None] - p[None], axis=-1) - self._canon_dist[np.ix_(f, f)])
            bad = err > tol
            if not bad.any():
                break
            key = bad.sum(axis=1) + np.tanh(dist[f, index[f]] / self.search_radius)  # count, then distance
            index[f[np.argmax(key)]] = -1
        return index


def find_objects(finders, points, n_markers):
    """Each rigid object's markers among the points.

    Parameters
    ----------
    finders : sequence of HandFrameFinder
        One per rigid object, in the order of the object labels.
    points : ndarray (K, 3)
        The frame's points, metres.
    n_markers : int
        Object labels in all (the sum of the objects' marker counts).

    Returns
    -------
    rest : ndarray (R,) int
        Indices of the points that no object took.
    object_points : ndarray (n_markers,) int
        The point of every object label, -1 where not found.
    """
    rest = np.arange(len(points))
    object_points = np.full(n_markers, -1)
    at = 0
    for finder in finders:
        found = finder.find(points[rest])
        n = len(finder.rigid.names)
        if found is not None and found.found:
            got = found.points >= 0
            object_points[at:at + n][got] = rest[found.points[got]]
            rest = np.delete(rest, found.points[got])
        at += n
    return rest, object_points
