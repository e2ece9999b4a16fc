"""Rigid bodies from markers: Kabsch/Umeyama alignment, RANSAC, 6-DoF tracking.

Eq. (5) of DexterCap: per frame, the rotation R and translation t that best
map an object's canonical marker positions onto the observed ones,

    min_{R, t} sum_i w_i |x_i - (R c_i + t)|^2,

solved in closed form by the SVD of the weighted cross-covariance (Kabsch
1976, doi:10.1107/S0567739476001873; Umeyama 1991,
doi:10.1109/34.88573). Outlier markers (mislabels, ghosts) are rejected by
RANSAC over minimal triples, keeping the largest consensus set and refitting on
it; canonical positions can be estimated from the data (generalised
Procrustes: align every frame to the current mean shape, average, repeat).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from handcap.core.errors import HandcapError
from handcap.core.markers import MarkerSequence
from handcap.core.motion import ObjectMotion
from handcap.core.rotations import axis_angle_from_matrix


def kabsch(source, target, weights=None):
    """Best rotation and translation from ``source`` to ``target`` points, batched.

    Parameters
    ----------
    source, target : ndarray (..., N, 3)
        Corresponding points, metres.
    weights : ndarray (..., N), optional
        Non-negative weights (0 drops a point, e.g. a missing marker).

    Returns
    -------
    rotation : ndarray (..., 3, 3)
        Proper rotation (det +1), ``target ~ rotation @ source + translation``.
    translation : ndarray (..., 3)
    """
    source = np.asarray(source, dtype=np.float64)
    target = np.asarray(target, dtype=np.float64)
    w = np.ones(source.shape[:-1]) if weights is None else np.asarray(weights, dtype=np.float64)
    w = w / np.maximum(w.sum(axis=-1, keepdims=True), 1e-300)
    src_mean = np.einsum("...n,...ni->...i", w, source)
    tgt_mean = np.einsum("...n,...ni->...i", w, target)
    src = np.where(w[..., None] > 0, source - src_mean[..., None, :], 0.0)
    tgt = np.where(w[..., None] > 0, target - tgt_mean[..., None, :], 0.0)
    cov = np.einsum("...n,...ni,...nj->...ij", w, tgt, src)
    u, _, vt = np.linalg.svd(cov)
    d = np.sign(np.linalg.det(u @ vt))
    fix = np.ones(u.shape[:-1])
    fix[..., -1] = d
    rotation = (u * fix[..., None, :]) @ vt
    translation = tgt_mean - np.einsum("...ij,...j->...i", rotation, src_mean)
    return rotation, translation


def kabsch_refit(source, target, weights, outlier: float, most: int | None = None):
    """Kabsch of ``source`` (M, 3) onto every frame's ``target`` (T, M, 3), robust to swapped or misplaced labels:
    while the farthest point is more than ``outlier`` metres from the fit and more than 3 points weigh, it is
    dropped (with any as far as half of it) and the fit repeated, up to a quarter of the points (a body that bends
    is not cut down to a rigid part).

    The farthest first: a label 30 mm off pulls the first fit of a few points so far that good points lie
    beyond ``outlier`` too (dropping them all at once left fewer than 3, and the spoilt fit).

    Parameters
    ----------
    source : ndarray (M, 3)
    target : ndarray (T, M, 3)
        Metres; finite (weight 0 where not seen).
    weights : ndarray (T, M)
        Non-negative; 0 drops a point.
    outlier : float
        Metres.
    most : int, optional
        At most this many points dropped in a frame (default: a quarter of those that weigh, at least 1).

    Returns
    -------
    rotation : ndarray (T, 3, 3)
    translation : ndarray (T, 3)
        NaN in frames where fewer than 3 points weigh, or where those that weigh lie within
        :data:`MIN_SPREAD` of a line (the turn about it is free: one row of a patch's corners), or (``most``
        not given) where 3 points are left and one is still off.
    """
    weights = np.array(weights, dtype=np.float64)
    rot, trans = kabsch(np.broadcast_to(source, target.shape), target, weights)
    allowed = np.maximum((weights > 0).sum(axis=1) // 4, 1) if most is None else np.full(len(target), most)
    active = np.flatnonzero(allowed > 0)  # frames still being refitted
    while len(active):
        off = np.linalg.norm(np.einsum("tij,mj->tmi", rot[active], source) + trans[active, None] - target[active],
                             axis=-1)
        off = np.where(weights[active] > 0, off, -1.0)
        # the farthest, and with it any as far as half of it (a few rounds, not one per point)
        far = off > np.maximum(outlier, 0.5 * off.max(axis=1, keepdims=True))
        count = np.minimum(np.minimum(far.sum(axis=1), allowed[active]), (weights[active] > 0).sum(axis=1) - 3)
        keep = count > 0
        active, off, count = active[keep], off[keep], count[keep]
        if not len(active):
            break
        rank = np.argsort(np.argsort(-off, axis=1), axis=1)  # 0 for the farthest
        weights[active] = np.where(rank < count[:, None], 0.0, weights[active])
        allowed[active] -= count
        rot[active], trans[active] = kabsch(np.broadcast_to(source, target[active].shape), target[active],
                                            weights[active])
        active = active[allowed[active] > 0]
    bad = ((weights > 0).sum(axis=1) < 3) | (line_spread(source, weights > 0) < MIN_SPREAD)
    tight = np.flatnonzero((weights > 0).sum(axis=1) == 3) if most is None else []
    if len(tight):  # down to 3 points and one still off: no pose fits them
        off = np.linalg.norm(np.einsum("tij,mj->tmi", rot[tight], source) + trans[tight, None] - target[tight], axis=-1)
        bad[tight] |= ((weights[tight] > 0) & (off > outlier)).any(axis=1)
    rot[bad], trans[bad] = np.nan, np.nan
    return rot, trans


#: Least spread of a fit's points off their best line, metres (RMS distance): below it the turn about the line is
#: left to the noise (one row of a patch's corners, or three markers nearly in a row).
MIN_SPREAD = 0.001


def line_spread(points, used) -> np.ndarray:
    """RMS distance of the ``used`` points from their best line, per frame.

    Parameters
    ----------
    points : ndarray (M, 3)
        Metres.
    used : ndarray (T, M) bool

    Returns
    -------
    ndarray (T,)
        Metres; 0 where fewer than 2 points are used.
    """
    points, used = np.asarray(points, dtype=np.float64), np.asarray(used, dtype=np.float64)
    count = used.sum(axis=1)
    mean = used @ points / np.maximum(count, 1)[:, None]
    second = np.einsum("tm,mi,mj->tij", used, points, points) / np.maximum(count, 1)[:, None, None]
    spread = np.linalg.eigvalsh(second - np.einsum("ti,tj->tij", mean, mean))  # ascending
    return np.sqrt(np.clip(spread[:, 0] + spread[:, 1], 0.0, None)) * (count >= 2)


def ransac_kabsch(source, target, *, threshold: float = 0.005, iterations: int = 64, rng=None):
    """Kabsch with RANSAC over triples: (rotation, translation, inliers) for one frame.

    Parameters
    ----------
    source, target : ndarray (N, 3)
        N >= 3 corresponding points.
    threshold : float
        A point is an inlier when the fit moves it within this distance, metres.
    iterations : int
        Random triples tried (all triples when there are fewer).
    """
    n = len(source)
    if n < 3:
        raise HandcapError(f"a rigid fit needs at least 3 points, got {n}")
    rng = np.random.default_rng(0) if rng is None else rng
    from itertools import combinations
    triples = list(combinations(range(n), 3))
    if len(triples) > iterations:
        triples = [tuple(rng.choice(n, 3, replace=False)) for _ in range(iterations)]
    triples = np.array(triples)
    rot, trans = kabsch(source[triples], target[triples])  # (K, 3, 3), (K, 3)
    moved = np.einsum("kij,nj->kni", rot, source) + trans[:, None]
    err = np.linalg.norm(moved - target[None], axis=2)
    inliers = err < threshold
    # Largest consensus set; ties broken by the smallest inlier error.
    score = inliers.sum(axis=1) - np.where(inliers, err, 0).sum(axis=1) / (threshold * n + 1e-12)
    best = inliers[np.argmax(score)]
    if best.sum() < 3:
        best = np.ones(n, bool) if n == 3 else best
    rot, trans = kabsch(source[best], target[best])
    final = np.linalg.norm(source @ rot.T + trans - target, axis=1) < threshold
    if final.sum() >= 3:
        rot, trans = kabsch(source[final], target[final])
        best = final
    return rot, trans, best


def _chained_shape(positions, seen, counts) -> np.ndarray:
    """A first shape (M, 3) for :func:`canonical_from_markers`: the frame with most markers, then frame after frame
    (the one sharing most markers with those placed, at least 3) aligned on the placed markers, its new ones placed.

    Markers no such chain reaches take their mean position over the take. (That mean, for every marker the first
    frame lacks, was the whole start once: on an object that moves, a place it never was, and the refinement
    settled 1-3 mm off the true shape where frames share few markers.)
    """
    ref = int(np.argmax(counts))
    shape = np.where(seen[ref][:, None], positions[ref], np.nanmean(positions, axis=0))
    placed = seen[ref].copy()
    todo = np.flatnonzero(counts >= 3)
    while not placed.all():
        overlap = (seen[todo] & placed).sum(axis=1)
        new = (seen[todo] & ~placed).sum(axis=1)
        candidates = np.flatnonzero((overlap >= 3) & (new > 0))
        if not len(candidates):
            break
        f = todo[candidates[np.argmax(overlap[candidates])]]
        both, fresh = seen[f] & placed, seen[f] & ~placed
        rot, trans = kabsch(shape[both], positions[f, both])
        shape[fresh] = (positions[f, fresh] - trans) @ rot
        placed |= fresh
    return shape


def canonical_from_markers(positions, *, iterations: int = 10) -> np.ndarray:
    """Marker positions (M, 3) in a body frame, estimated from a take (generalised Procrustes).

    Parameters
    ----------
    positions : ndarray (..., T, M, 3)
        NaN where missing; leading axes hold several takes (or candidate sets) estimated side by side, each as
        if alone.
    iterations : int
        Rounds of aligning every frame onto the shape and averaging.

    Returns
    -------
    canonical : ndarray (..., M, 3)
        Centred on the mean marker position; axes along the first frame with
        all markers seen (or most markers seen).
    """
    positions = np.asarray(positions, dtype=np.float64)
    lead = positions.shape[:-3]
    positions = positions.reshape((-1,) + positions.shape[-3:])
    seen = ~np.isnan(positions[..., 0])
    counts = seen.sum(axis=-1)
    if (counts.max(axis=-1) < 3).any():
        raise HandcapError("no frame sees 3 or more of the object's markers; cannot estimate its shape")
    never = ~seen.any(axis=-2)
    if never.any():
        raise HandcapError(f"markers {np.flatnonzero(never.any(axis=0)).tolist()} are never seen; "
                           "cannot place them on the object")
    shape = np.stack([_chained_shape(*item) for item in zip(positions, seen, counts)])
    shape = shape - shape.mean(axis=-2, keepdims=True)
    data = np.where(seen[..., None], positions, 0.0)
    weights = (seen & (counts >= 3)[..., None]).astype(float)  # frames of fewer than 3 markers weigh nothing
    for _ in range(iterations):
        rot, trans = kabsch(np.broadcast_to(shape[:, None], data.shape), data, weights)
        local = np.einsum("btji,btnj->btni", rot, data - trans[:, :, None])  # R^T (x - t)
        total = (local * weights[..., None]).sum(axis=1)
        shape = total / weights.sum(axis=1)[..., None]
        shape -= shape.mean(axis=-2, keepdims=True)
    return shape.reshape(lead + shape.shape[-2:])


@dataclass(frozen=True)
class RigidTrack:
    """Result of :func:`track_rigid`.

    Attributes
    ----------
    motion : ObjectMotion
        NaN rotation/translation in frames that could not be solved.
    residuals : ndarray (T, M)
        Distance of each inlier marker from its fitted position, metres (NaN otherwise).
    inliers : ndarray (T, M) bool
    unsolved : ndarray (F,) int
        Frames with fewer than 3 (inlier) markers: reported, not guessed.
    observed : ndarray (T, M) bool or None
        Which samples the input held (an observed sample that is not an inlier is an outlier).
    left_out : tuple of str
        Markers asked for that the take never shows, so no shape estimated from it places them (not in ``motion``).
    """

    motion: ObjectMotion
    residuals: np.ndarray
    inliers: np.ndarray
    unsolved: np.ndarray
    observed: np.ndarray | None = None
    left_out: tuple[str, ...] = ()

    @property
    def mean_residual(self) -> float:
        """Mean distance of the inlier markers from their fitted positions over the take, metres (NaN if none)."""
        return float(np.nanmean(self.residuals)) if np.isfinite(self.residuals).any() else float("nan")

    def summary(self) -> str:
        """One line: frames, mean residual, outlier samples and the frames left unsolved (the first ten named)."""
        listed = ", ".join(map(str, self.unsolved[:10])) + (" ..." if len(self.unsolved) > 10 else "")
        outliers = int(np.sum(~self.inliers & self.observed)) if self.observed is not None else 0
        return (f"{self.motion.n_frames} frames, mean residual {1000 * self.mean_residual:.2f} mm, {outliers} outlier "
                f"samples, {len(self.unsolved)} frames with fewer than 3 markers"
                + (f": {listed}" if len(self.unsolved) else ""))


def track_rigid(markers: MarkerSequence, names=None, canonical=None, *, name: str = "object",
                threshold: float = 0.005, seed: int = 0) -> RigidTrack:
    """6-DoF pose per frame of a rigid body carrying markers.

    Parameters
    ----------
    markers : MarkerSequence
    names : sequence of str, optional
        The body's markers (default: all of ``markers``).
    canonical : ndarray (M, 3), optional
        Their positions in the body frame, metres; estimated from the take when omitted (markers the take never
        shows are then left out, and named in the track's ``left_out``: a patch's corners that no camera pair saw).
    name : str
    threshold : float
        RANSAC inlier distance, metres.
    seed : int
        For the RANSAC draws.

    Returns
    -------
    RigidTrack
    """
    body = markers.select(list(names)) if names is not None else markers
    if body.n_markers < 3:
        raise HandcapError(f"a rigid body needs at least 3 markers, got {body.n_markers}: {', '.join(body.names)}")
    left_out = ()
    if canonical is None:
        shown = np.isfinite(body.positions).all(axis=-1).any(axis=0)
        if shown.sum() < 3:
            raise HandcapError(f"the take shows {int(shown.sum())} of the object's {body.n_markers} markers "
                               f"({', '.join(body.names[:4])}{' ...' if body.n_markers > 4 else ''}); a rigid body "
                               "needs 3 or more seen to be tracked")
        left_out = tuple(n for n, s in zip(body.names, shown) if not s)
        if left_out:
            body = body.select([n for n, s in zip(body.names, shown) if s])
    positions = body.positions
    canonical = canonical_from_markers(positions) if canonical is None else np.asarray(canonical, dtype=np.float64)
    if canonical.shape != (body.n_markers, 3):
        raise HandcapError(f"canonical positions must have shape ({body.n_markers}, 3), got {canonical.shape}")
    rng = np.random.default_rng(seed)
    n = body.n_frames
    rotation = np.full((n, 3), np.nan)
    translation = np.full((n, 3), np.nan)
    residuals = np.full((n, body.n_markers), np.nan)
    inliers = np.zeros((n, body.n_markers), bool)
    unsolved = []
    for t in range(n):
        seen = np.flatnonzero(~np.isnan(positions[t, :, 0]))
        if len(seen) < 3:
            unsolved.append(t)
            continue
        rot, trans, ok = ransac_kabsch(canonical[seen], positions[t, seen], threshold=threshold, rng=rng)
        if ok.sum() < 3:
            unsolved.append(t)
            continue
        rotation[t] = axis_angle_from_matrix(rot)
        translation[t] = trans
        used = seen[ok]
        inliers[t, used] = True
        residuals[t, used] = np.linalg.norm(canonical[used] @ rot.T + trans - positions[t, used], axis=1)
    motion = ObjectMotion(rotation, translation, markers.rate, name, body.names, canonical)
    return RigidTrack(motion, residuals, inliers, np.array(unsolved, dtype=int), ~np.isnan(positions[..., 0]),
                      left_out)


def _runs(ok):
    """(start, stop) of every run of True in ``ok`` (T,) bool."""
    edges = np.flatnonzero(np.diff(np.r_[0, ok.astype(np.int8), 0]))
    return edges.reshape(-1, 2)


def smooth_pose(rotation, translation, window: int) -> tuple[np.ndarray, np.ndarray]:
    """A pose track smoothed by a quadratic Savitzky-Golay filter over ``window`` frames, run by run (NaN
    frames split runs; runs shorter than ``window`` are left alone).

    Parameters
    ----------
    rotation : ndarray (T, 3, 3)
    translation : ndarray (T, 3)
        Metres; NaN where the pose is unknown.
    window : int
        Odd number of frames; below 5 returns the inputs.

    Returns
    -------
    rotation, translation : ndarrays (T, 3, 3), (T, 3)
    """
    from scipy.signal import savgol_filter  # here: every triangulation worker imports this module, not the filter

    rotation, translation = rotation.copy(), translation.copy()
    if window < 5:
        return rotation, translation
    for a, b in _runs(np.isfinite(translation).all(axis=1)):
        if b - a < window:
            continue
        q = Rotation.from_matrix(rotation[a:b]).as_quat()
        q *= np.where(np.cumprod(np.r_[1.0, np.sign(np.sum(q[1:] * q[:-1], axis=1))]) < 0, -1.0, 1.0)[:, None]
        q = savgol_filter(q, window, 2, axis=0)
        rotation[a:b] = Rotation.from_quat(q).as_matrix()
        translation[a:b] = savgol_filter(translation[a:b], window, 2, axis=0)
    return rotation, translation
