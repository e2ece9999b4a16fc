"""Re-aligning a labeling model to the take it labels (issue 14).

A spatial model learned on one take is wrong for a take of another day when
the back-of-hand markers sit differently relative to the fingers (a glove put
on again: 13 degrees / 13 mm), when the rigid markers' distances changed (a
marker stuck back on a few millimetres away) or when the hand is another
subject's. Three corrections, each estimated from the take itself:

1. :func:`rigid_from_take`: the rigid set's shape as the take shows it. Every
   frame's triangles of points whose distances are near the trained ones
   (within ``width``) are pooled; the triangle shape that recurs in most
   frames (within the trained tolerance) is the rigid set, re-learned.
2. :func:`register_to_model`: the rigid transform that takes the take's
   hand-frame points onto the spatial model, by EM on the Gaussian mixtures
   with a uniform outlier term (rigid CPD, Myronenko & Song 2010,
   doi:10.1109/TPAMI.2010.46). Without labels every point may belong to any
   label's mixture, and the mixtures are widened at first and narrowed over
   the iterations (deterministic annealing) so that a misalignment of several
   centimetres at the fingertips is caught; with labels each point is pulled
   by its own label's mixture only, with Cauchy weights against wrong labels.
3. :func:`adapt_means`: the mixture means moved toward the take's labelled
   points, maximum a posteriori with a relevance factor (Reynolds, Quatieri &
   Dunn 2000, doi:10.1006/dspr.1999.0361): a component that sees ``n`` points
   moves ``n / (n + relevance)`` of the way to their mean.

:meth:`SpatialModel.moved` then expresses the model in the take's hand frame.
"""

from __future__ import annotations

import numpy as np

from collections import deque

from handcap.labeling.frame import HandFrameFinder, RigidSet
from handcap.labeling.spatial import SpatialModel
from handcap.objects.rigid import canonical_from_markers, kabsch

#: Outlier share of the registration (ghosts, wrong labels), and the volume its uniform density spreads over.
OUTLIER_SHARE = 0.1
OUTLIER_VOLUME = 0.2**3
#: The most a label-free registration may turn (degrees) and shift (metres) the hand frame: back-of-hand
#: markers put on again sit within a few centimetres and a few tens of degrees of where they were (issue 14:
#: 13 degrees / 13 mm); a registration further than that has found another pose of the fingers, not the hand.
MAX_TURN_DEG = 30.0
MAX_SHIFT = 0.03


def _covariances(spatial: SpatialModel) -> np.ndarray:
    """(M, L, 3, 3) covariances of every component, m^2."""
    p = spatial.precision_chol
    return np.linalg.inv(p @ np.swapaxes(p, -1, -2))


def register_to_model(spatial: SpatialModel, local, labels=None, *, weights=None, anneal: float = 0.02,
                      iterations: int = 30, start=None):
    """Rigid transform from the take's hand frame to the model's, by EM.

    Parameters
    ----------
    spatial : SpatialModel
    local : ndarray (N, 3)
        Points in the take's hand frame, metres (the rigid markers left out).
    labels : ndarray (N,) int, optional
        Free-label index of each point (into ``spatial.names``); -1 or absent:
        any label (label-free registration).
    weights : ndarray (N,), optional
        Weight of each point (e.g. older points less).
    anneal : float
        Standard deviation (metres) added to every component at the first
        iteration, shrinking to zero by 60 % of the iterations.
    iterations : int
    start : (ndarray (3, 3), ndarray (3,)), optional
        Initial transform (default identity).

    Returns
    -------
    rotation : ndarray (3, 3)
    translation : ndarray (3,)
        ``model_local = rotation @ take_local + translation``.
    """
    local = np.asarray(local, dtype=np.float64).reshape(-1, 3)
    rot, trans = (np.eye(3), np.zeros(3)) if start is None else (np.asarray(start[0]), np.asarray(start[1]))
    weights = np.ones(len(local)) if weights is None else np.asarray(weights, dtype=np.float64)
    if len(local) < 10:
        return rot, trans
    m, n_comp = spatial.weights.shape
    cov = _covariances(spatial).reshape(-1, 3, 3)  # (M L, 3, 3)
    labelled = labels is not None
    if labelled:
        labels = np.asarray(labels)
        keep = labels >= 0
        local, labels, weights = local[keep], labels[keep], weights[keep]
        pick = labels[:, None] * n_comp + np.arange(n_comp)  # (N, L): each point's own label's components
        logw = np.log(np.maximum(spatial.weights[labels], 1e-300))  # (N, L)
    else:
        w = spatial.weights.ravel() / m
        pick = np.flatnonzero(w > 0)[None]  # (1, K): every label's components
        logw = np.log(w[pick])
    mu = spatial.means.reshape(-1, 3)[pick]  # (N or 1, K, 3)
    eye = np.eye(3)
    cut = max(1, int(0.6 * iterations))
    for it in range(iterations):
        extra = (anneal * max(0.0, 1.0 - it / cut)) ** 2
        if extra > 0:
            comp = np.linalg.cholesky(np.linalg.inv(cov + extra * eye))  # W W^T = C^-1 per component
        else:
            comp = spatial.precision_chol.reshape(-1, 3, 3)
        whiten = comp[pick]  # (N or 1, K, 3, 3)
        y = local @ rot.T  # (N, 3) turned points
        d = (y + trans)[:, None] - mu  # (N, K, 3)
        r = np.matmul(d[:, :, None, :], whiten)[:, :, 0, :]  # whitened residuals W^T d
        m2 = (r**2).sum(axis=-1)
        logp = logw + np.log(np.abs(np.diagonal(whiten, axis1=-2, axis2=-1))).sum(axis=-1) \
            - 1.5 * np.log(2 * np.pi) - 0.5 * m2
        top = logp.max(axis=1, keepdims=True)
        p = np.exp(logp - top)
        total = p.sum(axis=1, keepdims=True)
        if labelled:
            # Cauchy weights: a wrongly labelled point (far from every component of its label) counts little.
            gamma = p / total
            gamma = gamma / (1.0 + (gamma * m2).sum(axis=1, keepdims=True) / 9.0)
        else:
            outlier = np.exp(np.minimum(np.log(OUTLIER_SHARE / OUTLIER_VOLUME) - top, 700.0))
            gamma = p / (total + outlier)
        gamma = gamma * weights[:, None]
        if gamma.sum() <= 0:
            break
        # M-step: one Gauss-Newton step on sum gamma |W^T (R x + t - mu)|^2 over a small turn w and shift dt
        # (R x + t ~ y + w x y + t + dt), the full covariances kept (isotropic weights would pull points
        # on a curved finger arc toward its chord).
        skew = np.zeros(y.shape + (3,))  # d(w x y)/dw = -[y]x
        skew[:, 0, 1], skew[:, 0, 2], skew[:, 1, 2] = y[:, 2], -y[:, 1], y[:, 0]
        skew[:, 1, 0], skew[:, 2, 0], skew[:, 2, 1] = -y[:, 2], y[:, 1], -y[:, 0]
        wt = np.swapaxes(whiten, -1, -2)
        jac = np.concatenate([np.matmul(wt, skew[:, None]), np.broadcast_to(wt, d.shape + (3,))], axis=-1)
        root = np.sqrt(gamma)[..., None]
        a = (jac * root[..., None]).reshape(-1, 6)  # (N K 3, 6)
        h = a.T @ a + 1e-12 * np.eye(6)
        g = a.T @ (r * root).reshape(-1)
        step = -np.linalg.solve(h, g)
        turn = step[:3]
        angle = np.linalg.norm(turn)
        if angle > 0:
            k = turn / angle
            kx = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
            dr = eye + np.sin(angle) * kx + (1 - np.cos(angle)) * kx @ kx
        else:
            dr = eye
        rot = dr @ rot
        trans = dr @ trans + step[3:]
    if not labelled:
        # Annealing widens the basin but does not promise the best optimum: never end worse than the start,
        # nor further from it than markers put on again can be.
        begin = (np.eye(3), np.zeros(3)) if start is None else start
        turn = np.degrees(np.arccos(np.clip((np.trace(rot @ begin[0].T) - 1) / 2, -1.0, 1.0)))
        if (turn > MAX_TURN_DEG or np.linalg.norm(trans - begin[1]) > MAX_SHIFT
                or _mixture_fit(spatial, local, weights, *begin) > _mixture_fit(spatial, local, weights, rot, trans)):
            return begin
    return rot, trans


def _mixture_fit(spatial, local, weights, rot, trans) -> float:
    """Weighted log-likelihood of points (N, 3) moved by (rot, trans) under the mixture of every label's
    mixture and the uniform outlier term (what the label-free registration maximises)."""
    m = len(spatial.names)
    ll = spatial.log_likelihood(local @ rot.T + trans)  # (M, N)
    top = ll.max(axis=0)
    mix = top + np.log(np.exp(ll - top).sum(axis=0) / m)
    total = np.logaddexp(np.log(1 - OUTLIER_SHARE) + mix, np.log(OUTLIER_SHARE / OUTLIER_VOLUME))
    return float(weights @ total)


def adapt_means(spatial: SpatialModel, local, labels, *, weights=None, relevance: float = 20.0,
                max_distance: float = 5.0) -> SpatialModel:
    """Mixture means moved toward labelled points (MAP adaptation with a relevance factor).

    Parameters
    ----------
    spatial : SpatialModel
    local : ndarray (N, 3)
        Points in the model's hand frame, metres.
    labels : ndarray (N,) int
        Free-label index of each point; -1 ignored.
    weights : ndarray (N,), optional
        Weight of each point (how many points it counts for).
    relevance : float
        Points a component must see to move half way to their mean.
    max_distance : float
        Points further than this many standard deviations (Mahalanobis) from
        every component of their label are left out (a wrong label, a ghost).
    """
    local = np.asarray(local, dtype=np.float64).reshape(-1, 3)
    labels = np.asarray(labels)
    weights = np.ones(len(local)) if weights is None else np.asarray(weights, dtype=np.float64)
    keep = labels >= 0
    local, labels, weights = local[keep], labels[keep], weights[keep]
    means = spatial.means.copy()
    if not len(local):
        return spatial
    d = local[:, None] - spatial.means[labels]  # (N, L, 3)
    y = np.einsum("nli,nlij->nlj", d, spatial.precision_chol[labels])
    m2 = (y**2).sum(axis=-1)
    logp = spatial.log_norm[labels] - 0.5 * m2
    gamma = np.exp(logp - logp.max(axis=1, keepdims=True))
    gamma /= gamma.sum(axis=1, keepdims=True)
    gamma *= ((m2.min(axis=1) < max_distance**2) * weights)[:, None]
    m, n_comp = spatial.weights.shape
    flat = labels[:, None] * n_comp + np.arange(n_comp)  # (N, L) component index
    count = np.bincount(flat.ravel(), gamma.ravel(), minlength=m * n_comp).reshape(m, n_comp)
    sums = np.stack([np.bincount(flat.ravel(), (gamma * local[:, i, None]).ravel(), minlength=m * n_comp)
                     for i in range(3)], axis=-1).reshape(m, n_comp, 3)
    share = count / (count + relevance)
    means = np.where(count[..., None] > 0, (1 - share[..., None]) * means
                     + share[..., None] * sums / np.maximum(count[..., None], 1e-300), means)
    return SpatialModel(spatial.names, spatial.weights, means, spatial.precision_chol, spatial.log_norm)


def rigid_from_take(rigid: RigidSet, frames, *, spatial: SpatialModel | None = None, width: float = 0.01,
                    min_share: float = 0.3, max_frames: int = 400) -> RigidSet | None:
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
    every = candidates + [rigid]
    fits = [_fit_in_frames(spatial, c, use) for c in every]
    return every[int(np.argmax(fits))]


def _anchor(canonical):
    """The largest triangle (a, b, e) of a set and its side lengths (ab, ae, be)."""
    c = canonical
    n = len(c)
    tri = np.array([(i, j, k) for i in range(n) for j in range(i + 1, n) for k in range(j + 1, n)])
    area = np.linalg.norm(np.cross(c[tri[:, 1]] - c[tri[:, 0]], c[tri[:, 2]] - c[tri[:, 0]]), axis=1)
    a, b, e = tri[int(np.argmax(area))]
    sides = np.array([np.linalg.norm(c[a] - c[b]), np.linalg.norm(c[a] - c[e]), np.linalg.norm(c[b] - c[e])])
    return (a, b, e), sides


def _recurring_shapes(rigid: RigidSet, use, width, min_share, most: int = 5) -> list:
    """Shapes of the rigid set that recur in the frames ``use``: most frequent first (at most ``most``, each
    seen in at least 80 % as many frames as the first), each a RigidSet."""
    c, tol = rigid.canonical, rigid.tolerance
    (a, b, e), trained = _anchor(c)
    sides, owner, where = [], [], []
    for t, pts in enumerate(use):
        dist = np.linalg.norm(pts[:, None] - pts[None], axis=-1)
        ok = ((np.abs(dist - trained[0]) < width)[:, :, None] & (np.abs(dist - trained[1]) < width)[:, None, :]
              & (np.abs(dist - trained[2]) < width)[None, :, :])
        found = np.argwhere(ok)
        if not len(found):
            continue
        sides.append(np.stack([dist[found[:, 0], found[:, 1]], dist[found[:, 0], found[:, 2]],
                               dist[found[:, 1], found[:, 2]]], axis=1))
        owner.append(np.full(len(found), t))
        where.append(found)
    if not sides:
        return []
    sides, owner, where = np.concatenate(sides), np.concatenate(owner), np.concatenate(where)
    # For every candidate shape, in how many frames a triangle of that shape (within the tolerance) appears.
    probe = np.linspace(0, len(sides) - 1, min(len(sides), 300)).astype(int)
    close = (np.abs(sides[probe][:, None] - sides[None]) < tol).all(axis=-1)  # (P, S)
    frames_with = np.array([len(np.unique(owner[row])) for row in close])
    if frames_with.max() < min_share * len(use):
        return []
    out, chosen = [], []
    # Most frequent first; among shapes seen as often (a short stretch of frames, where fingers keep their
    # shape too), the nearest the trained shape first.
    offset = np.abs(sides[probe] - trained).max(axis=1)
    for p in np.lexsort((offset, -frames_with)):
        if frames_with[p] < 0.8 * frames_with.max() or len(out) == most:
            break
        shape = sides[probe[p]]
        if any((np.abs(shape - other) < tol).all() for other in chosen):
            continue
        found = _shape_in_frames(rigid, use, sides, owner, where, shape, (a, b, e), width)
        if found is not None:
            chosen.append(shape)
            out.append(found)
    return out


def _shape_in_frames(rigid, use, sides, owner, where, shape, anchor, width) -> RigidSet | None:
    """The rigid set from the triangles of one shape, one per frame (and the other markers near their places)."""
    c, tol = rigid.canonical, rigid.tolerance
    n = len(c)
    a, b, e = anchor
    members = (np.abs(sides - shape) < tol).all(axis=-1)
    err = np.abs(sides - shape).max(axis=1)
    positions = np.full((len(use), n, 3), np.nan)
    for t in np.unique(owner[members]):
        rows = np.flatnonzero(members & (owner == t))
        i, j, k = where[rows[np.argmin(err[rows])]]
        pts = use[t]
        positions[t, [a, b, e]] = pts[[i, j, k]]
        if n > 3:  # the other markers: the point nearest where the trained shape puts them
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
    seen = ~np.isnan(positions[..., 0])
    if (seen.sum(axis=1) >= 3).sum() < 3 or not seen.any(axis=0).all():
        return None
    new = canonical_from_markers(positions[seen.sum(axis=1) >= 3])
    rot, trans = kabsch(new, c)
    return RigidSet(rigid.names, new @ rot.T + trans, rigid.tolerance)


def _fit_in_frames(spatial: SpatialModel, rigid: RigidSet, use, *, most: int = 20,
                   floor: float = -2.0, iterations: int = 0) -> float:
    """How well the other points of frames ``use`` fit the spatial model in the hand frame ``rigid`` gives
    (after ``iterations`` of label-free registration; none by default: the candidates' shapes are turned onto
    the trained one, and a registration lets a wrong frame fit too): the mean over points of the best label's
    log-likelihood (at least ``floor``), frames without the set counting every point at the floor."""
    finder = HandFrameFinder(rigid, max_hold=0)
    local, missing = [], 0
    for pts in use[:: max(1, len(use) // most)]:
        finder.reset()
        pose = finder.find(pts)
        if pose is None or not pose.found:
            missing += len(pts)
            continue
        others = np.delete(pts, pose.points[pose.points >= 0], axis=0)
        local.append((others - pose.translation) @ pose.rotation)
    if not local:
        return -np.inf
    local = np.concatenate(local)
    rot, trans = register_to_model(spatial, local, iterations=iterations) if iterations else (np.eye(3), np.zeros(3))
    ll = spatial.log_likelihood(local @ rot.T + trans)
    best = np.maximum(ll.max(axis=0), floor)
    return float((best.sum() + floor * missing) / (len(best) + missing))


def largest_change(a: RigidSet, b: RigidSet) -> float:
    """Largest difference between the two sets' marker distances, metres."""
    i, j = np.triu_indices(len(a.names), 1)
    return float(np.abs(np.linalg.norm(a.canonical[i] - a.canonical[j], axis=1)
                        - np.linalg.norm(b.canonical[i] - b.canonical[j], axis=1)).max())


class StreamAdaptation:
    """The online labeler's adaptation to the take (see :class:`handcap.labeling.OnlineLabeler`, ``adapt``).

    Keeps the recent frames' points in the take's hand frame and the labels
    the labeler gave them; every ``every`` frames re-estimates the transform
    to the trained model's frame and the mixture means, and sets the
    labeler's ``spatial`` to the result. Also watches the hand frame: when it
    is lost in most recent frames, the rigid set is re-learned from them.
    """

    window = 1000  # frames of labelled points kept
    most_points = 800  # points per re-estimation (spread over the window), so that one stays ~1 ms

    def __init__(self, labeler, every: int, forget: float):
        self.labeler = labeler
        self.every = every
        self.forget = forget
        self.base = labeler.model.spatial
        self.rotation, self.translation = np.eye(3), np.zeros(3)
        n_free = labeler.n_free
        self.local = np.full((self.window, n_free, 3), np.nan)
        self.stamp = np.full(self.window, -1)
        self.count = 0
        self.aligned = False
        self.unlabelled: deque = deque(maxlen=4 * every)  # take-frame points before the first alignment
        self.raw: deque = deque(maxlen=100)  # every frame's points, for re-learning the rigid set
        self.lost: deque = deque(maxlen=20)
        self.last_relearn = -(10**9)
        self.relearned = 0
        self.checked = False

    @property
    def settled(self) -> bool:
        """Whether the take's rigid shape has been checked (with rigid markers) and the model aligned to it:
        until then a point the model filters out may as well mean a wrong hand frame."""
        return self.aligned and (self.checked or self.labeler.finder is None)

    def watch_hand(self, points, found):
        """After the hand-frame finder: keep the frame, and re-learn the rigid set when it is mostly lost."""
        self.raw.append(points)
        self.lost.append(found is None or not found.found)
        lab = self.labeler
        if sum(self.lost) >= 10 and self.count - self.last_relearn >= 20 and len(self.raw) >= 10:
            self.last_relearn = self.count
            if self.relearn_rigid(list(self.raw)[-50:]):
                found = lab.finder.find(points, lab._frame_fit)
                self.lost.clear()
        return found

    def relearn_rigid(self, frames) -> bool:
        """Re-learn the rigid set from ``frames`` (:func:`rigid_from_take`); True when it changed."""
        lab = self.labeler
        rigid = lab.finder.rigid
        new = rigid_from_take(rigid, frames, spatial=self.base, width=max(0.01, 3 * rigid.tolerance),
                              min_share=0.5)
        if new is None or largest_change(new, rigid) <= 0.5 * rigid.tolerance:
            return False
        lab.finder = HandFrameFinder(new, max_hold=lab.finder.max_hold)
        self.relearned += 1
        self._restart()
        return True

    def _restart(self) -> None:
        """The hand frame changed meaning: forget what was gathered in the old one."""
        self.local[:] = np.nan
        self.stamp[:] = -1
        self.unlabelled.clear()
        self.aligned = False
        self.rotation, self.translation = np.eye(3), np.zeros(3)
        self.labeler.spatial = self.base

    def record(self, world, pose, best) -> None:
        """A frame's candidate points (K, 3) in the world, its hand pose or None, and the best hypothesis
        (F,) point per free label (-1 none); re-estimates every ``every`` frames."""
        self.count += 1
        if pose is not None and len(world):
            local = (world - pose[1]) @ pose[0]
            if not self.aligned:
                self.unlabelled.append(local)
            slot = self.count % self.window
            row = np.full((len(best), 3), np.nan)
            seen = best >= 0
            if seen.any():
                ll = self.labeler._last_ll
                ok = seen.copy()
                ok[seen] = ll[np.flatnonzero(seen), best[seen]] >= self.labeler.theta_min
                row[ok] = local[best[ok]]
            self.local[slot] = row
            self.stamp[slot] = self.count
        if self.count % self.every == 0:
            self.update()

    def update(self) -> None:
        """Re-estimate the transform and the means from the frames gathered."""
        if not self.checked and len(self.raw) == self.raw.maxlen and self.labeler.finder is not None:
            # Once, when a second or so of frames shows which shapes recur: is the rigid set the shape it
            # was in training?
            self.checked = True
            if self.relearn_rigid(list(self.raw)):
                return
        if not self.aligned:
            if sum(len(p) for p in self.unlabelled) < 100:
                return
            pts = np.concatenate(list(self.unlabelled))
            if len(pts) > self.most_points:
                pts = pts[np.linspace(0, len(pts) - 1, self.most_points).astype(int)]
            self.rotation, self.translation = register_to_model(self.base, pts)
            self.aligned = True
            self.unlabelled.clear()
            self.local[:] = np.nan  # labels given before the alignment are not trusted
            self.stamp[:] = -1
            self.labeler.spatial = self.base.moved(self.rotation, self.translation)
            self.labeler.restart_tracks()  # tracks begun under the unaligned model may be swapped
            return
        valid = (self.stamp >= 0)[:, None] & ~np.isnan(self.local[..., 0])
        slots, labels = np.nonzero(valid)
        if len(slots) < 50:
            return
        if len(slots) > self.most_points:  # spread over the window: a second of frames is one pose only
            pick = np.linspace(0, len(slots) - 1, self.most_points).astype(int)
            slots, labels = slots[pick], labels[pick]
        local = self.local[slots, labels]
        weights = self.forget ** (self.count - self.stamp[slots])
        self.rotation, self.translation = register_to_model(self.base, local, labels, weights=weights, anneal=0.0,
                                                            iterations=2, start=(self.rotation, self.translation))
        self.labeler.spatial = self.base.moved(self.rotation, self.translation)
