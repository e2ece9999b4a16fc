"""Triangulation of markers seen by several calibrated cameras (DexterCap section 3.1.1).

Linear triangulation from every view, RANSAC over views that keeps the *best*
inlier set (most inliers, then least reprojection error; the research code kept
the last one it tried), and a Gauss-Newton refinement of the reprojection error
over the inliers.

Everything is vectorised over points. Each view contributes two linear
equations ``(u P3 - P1) X = 0`` and ``(v P3 - P2) X = 0``; their normal
equations (a 3 x 3 matrix and a 3-vector per view and point) are computed once,
so the solution from any subset of views, a pair of them for a RANSAC
hypothesis or the inliers for the final fit, is a sum and a batched 3 x 3 solve.
Points whose linear solution from all views already reprojects within half the
threshold in every view take that set (no smaller set can have more inliers);
only the others, the few with a wrong detection among their views, try every
pair of views as a hypothesis.

Pixels here are *undistorted* (``CameraRig.undistort_pixels``) and the
projection matrices map the world (metres) to them (``CameraRig.projections``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from handcap.core.errors import HandcapError

# Hypotheses scored in one batch in RANSAC (bounds the memory of the
# (hypotheses, cameras, 2) projections to some tens of MB).
_HYPOTHESES_PER_BATCH = 200_000
# Points solved together (see triangulate_ransac).
_POINTS_PER_BLOCK = 4096


def _check(pixels, projections):
    pixels = np.asarray(pixels, dtype=np.float64)
    projections = np.asarray(projections, dtype=np.float64)
    if projections.ndim != 3 or projections.shape[1:] != (3, 4):
        raise HandcapError(f"projections must have shape (C, 3, 4), got {projections.shape}")
    if pixels.ndim != 3 or pixels.shape[0] != len(projections) or pixels.shape[2] != 2:
        raise HandcapError(f"pixels must have shape (C, N, 2) with C = {len(projections)}, got {pixels.shape}")
    if not np.isfinite(projections).all():
        raise HandcapError("projections must be finite")
    return pixels, projections


# The six distinct entries of a symmetric 3 x 3 matrix, in this order, along the first axis.
_I = np.array([0, 0, 0, 1, 1, 2])
_J = np.array([0, 1, 2, 1, 2, 2])


def _normal_equations(u, v, projections, seen):
    """Per view and point, the normal equations of its two linear equations.

    Parameters
    ----------
    u, v : ndarray (C, N)
        Undistorted pixels (anything where unseen).
    projections : ndarray (C, 3, 4)
    seen : ndarray (C, N) bool

    Returns
    -------
    a : ndarray (6, C, N)
        Distinct entries (``_I``, ``_J``) of each view's symmetric 3 x 3 matrix.
    b : ndarray (3, C, N)
        Right-hand sides: the solution from a set S of views solves
        ``sum_S a @ X = sum_S b``. Each equation is scaled to unit norm in X, so
        every view weighs about the same whatever its distance. Zero where unseen.
    """
    p = projections[:, :, :, None]  # (C, 3, 4, 1)
    u = np.where(seen, u, 0.0)[:, None]
    v = np.where(seen, v, 0.0)[:, None]
    ru = u * p[:, 2] - p[:, 0]  # (C, 4, N)
    rv = v * p[:, 2] - p[:, 1]
    ru *= seen[:, None] / np.maximum(np.sqrt((ru[:, :3] ** 2).sum(axis=1, keepdims=True)), 1e-300)
    rv *= seen[:, None] / np.maximum(np.sqrt((rv[:, :3] ** 2).sum(axis=1, keepdims=True)), 1e-300)
    ru, rv = ru.swapaxes(0, 1), rv.swapaxes(0, 1)  # (4, C, N)
    a = ru[_I] * ru[_J] + rv[_I] * rv[_J]
    b = -(ru[:3] * ru[3] + rv[:3] * rv[3])
    return a, b


def _solve(a, b, enough):
    """Batched solves of symmetric 3 x 3 systems by their adjugate.

    Parameters
    ----------
    a : ndarray (6, N)
        Distinct entries in the order of ``_I``, ``_J``.
    b : ndarray (3, N)
    enough : ndarray (N,) bool
        Where to solve; NaN elsewhere and where the matrix is singular.

    Returns
    -------
    ndarray (3, N)
    """
    a00, a01, a02, a11, a12, a22 = a
    c00 = a11 * a22 - a12 * a12
    c01 = a02 * a12 - a01 * a22
    c02 = a01 * a12 - a02 * a11
    c11 = a00 * a22 - a02 * a02
    c12 = a01 * a02 - a00 * a12
    c22 = a00 * a11 - a01 * a01
    det = a00 * c00 + a01 * c01 + a02 * c02
    scale = np.abs(a00) + np.abs(a11) + np.abs(a22)
    good = enough & (np.abs(det) > 1e-12 * scale ** 3)
    with np.errstate(invalid="ignore", divide="ignore"):
        inv = np.where(good, 1.0 / det, np.nan)
    b0, b1, b2 = b
    return np.stack([(c00 * b0 + c01 * b1 + c02 * b2) * inv,
                     (c01 * b0 + c11 * b1 + c12 * b2) * inv,
                     (c02 * b0 + c12 * b1 + c22 * b2) * inv])


def project_undistorted(x, projections):
    """Undistorted pixels u, v (C, N) and depth-like z (C, N) of points x (3, N) through projection matrices.

    Parameters
    ----------
    x : ndarray (3, N)
        Points as columns, metres (world frame).
    projections : ndarray (C, 3, 4)
        Projection matrices from the world (metres) to undistorted pixels.

    Returns
    -------
    u, v : ndarray (C, N)
        Undistorted pixels; NaN or infinite where ``z`` is 0.
    z : ndarray (C, N)
        Third homogeneous coordinate: the depth in metres when a projection is ``K [R | t]``
        (positive in front of the camera).
    """
    # Written out rather than a matrix product: BLAS kernels may round differently with the
    # number of points, and a point's result must not depend on which block it was solved in.
    p = projections[:, :, :, None]  # (C, 3, 4, 1)
    h = p[:, :, 0] * x[0] + p[:, :, 1] * x[1] + p[:, :, 2] * x[2] + p[:, :, 3]  # (C, 3, N)
    z = h[:, 2]
    with np.errstate(invalid="ignore", divide="ignore"):
        return h[:, 0] / z, h[:, 1] / z, z


def _errors(x, u, v, projections):
    """Reprojection errors (C, N) in pixels; inf where unseen or behind a camera."""
    pu, pv, z = project_undistorted(x, projections)
    error = np.hypot(pu - u, pv - v)
    return np.where(np.isnan(error) | ~(z > 0), np.inf, error)


def triangulate_linear(pixels, projections, weights=None) -> np.ndarray:
    """Linear triangulation of points seen by several cameras.

    Parameters
    ----------
    pixels : ndarray of shape (C, N, 2)
        Undistorted pixel coordinates, NaN where camera c misses point n.
    projections : ndarray of shape (C, 3, 4)
        Projection matrices; the world frame is in metres.
    weights : ndarray of shape (C, N), optional
        Weight of each view (0 drops it); default 1 where seen.

    Returns
    -------
    points : ndarray of shape (N, 3)
        Positions in metres, NaN where fewer than two views count.
    """
    pixels, projections = _check(pixels, projections)
    seen = ~np.isnan(pixels).any(axis=-1)
    w = seen.astype(np.float64) if weights is None else np.where(seen, np.asarray(weights, np.float64), 0.0)
    a, b = _normal_equations(pixels[..., 0], pixels[..., 1], projections, seen)
    enough = np.count_nonzero(w > 0, axis=0) >= 2
    return _solve((a * w).sum(axis=1), (b * w).sum(axis=1), enough).T


def project(points, projections) -> np.ndarray:
    """Undistorted pixels (C, N, 2) of points (N, 3) in metres; NaN behind a camera.

    Parameters
    ----------
    points : array_like (N, 3)
        World points, metres.
    projections : array_like (C, 3, 4)
        Projection matrices from the world (metres) to undistorted pixels.

    Returns
    -------
    ndarray (C, N, 2)
        Undistorted pixels; NaN where the point is not in front of the camera (``z <= 0``) or is NaN.
    """
    u, v, z = project_undistorted(np.asarray(points, np.float64).T, np.asarray(projections, np.float64))
    out = np.stack([u, v], axis=-1)
    out[~(z > 0)] = np.nan
    return out


@dataclass(frozen=True)
class Triangulation:
    """Result of :func:`triangulate_ransac`.

    Attributes
    ----------
    points : ndarray (N, 3)
        Metres, NaN where no inlier set of ``min_views`` views was found.
    inliers : ndarray (C, N) bool
        The views kept for each point.
    error : ndarray (N,)
        Mean reprojection error over the inliers, pixels; NaN where no point.
    views : ndarray (N,) int
        Number of inlier views (0 where no point).
    """

    points: np.ndarray
    inliers: np.ndarray
    error: np.ndarray
    views: np.ndarray


def triangulate_ransac(pixels, projections, *, min_views: int = 3, threshold_px: float = 5.0,
                       iterations: int = 2) -> Triangulation:
    """Robust triangulation: every pair of views as a hypothesis, the best inlier set kept, then refined.

    Parameters
    ----------
    pixels : ndarray of shape (C, N, 2)
        Undistorted pixels, NaN where unseen.
    projections : ndarray of shape (C, 3, 4)
        Projection matrices to undistorted pixels; the world in metres.
    min_views : int
        Inlier views a point needs (at least 2).
    threshold_px : float
        Reprojection error below which a view is an inlier, pixels.
    iterations : int
        Gauss-Newton steps of the final refinement.

    Returns
    -------
    Triangulation

    Notes
    -----
    The best hypothesis has the most inliers, ties broken by the least summed
    reprojection error of its inliers. After the refinement the inlier set is
    taken once more as every view within the threshold of the refined point
    (a view a two-view hypothesis missed by a hair comes back, one that drifted
    out goes) and the points whose set changed are refined again.
    """
    pixels, projections = _check(pixels, projections)
    if isinstance(min_views, bool) or not isinstance(min_views, (int, np.integer)) or min_views < 2:
        raise HandcapError(f"min_views must be a whole number of at least 2, got {min_views!r}")
    if not threshold_px > 0 or not np.isfinite(threshold_px):
        raise HandcapError(f"threshold_px must be a positive number of pixels, got {threshold_px!r}")
    # Blocks of points small enough for the working arrays to stay in the CPU's cache (3x faster
    # than one pass over 100,000 points); every point is solved on its own, so blocks change nothing.
    parts = [_ransac(pixels[:, s:s + _POINTS_PER_BLOCK], projections, min_views, threshold_px, iterations)
             for s in range(0, pixels.shape[1], _POINTS_PER_BLOCK)]
    if len(parts) == 1:
        return parts[0]
    return Triangulation(*(np.concatenate([getattr(p, key) for p in parts], axis=axis)
                           for key, axis in (("points", 0), ("inliers", 1), ("error", 0), ("views", 0))))


def _ransac(pixels, projections, min_views, threshold_px, iterations) -> Triangulation:
    u, v = pixels[..., 0], pixels[..., 1]
    seen = ~(np.isnan(u) | np.isnan(v))
    a, b = _normal_equations(u, v, projections, seen)
    candidates = seen.sum(axis=0) >= min_views

    # 1. Every view at once; accepted where all views agree to half the threshold.
    x = _solve(a.sum(axis=1), b.sum(axis=1), candidates)
    error = _errors(x, u, v, projections)
    agree = candidates & np.all(~seen | (error < 0.5 * threshold_px), axis=0)
    inliers = seen & agree

    # 2. RANSAC over pairs of views for the others.
    rest = np.flatnonzero(candidates & ~agree)
    if rest.size:
        inliers[:, rest] = _best_pairs(u[:, rest], v[:, rest], projections, seen[:, rest],
                                       a[:, :, rest], b[:, :, rest], threshold_px)

    # 3. Fit on the inliers and refine; take the inliers again and refine those that changed.
    ok = inliers.sum(axis=0) >= min_views
    inliers &= ok
    x = _solve((a * inliers).sum(axis=1), (b * inliers).sum(axis=1), ok)
    x = _refine(x, u, v, projections, inliers, iterations)
    error = _errors(x, u, v, projections)
    again = seen & (error < threshold_px) & ok
    changed = np.flatnonzero(np.any(again != inliers, axis=0))
    if changed.size:
        w = again[:, changed]
        redo = w.sum(axis=0) >= min_views
        w &= redo
        xc = _solve((a[:, :, changed] * w).sum(axis=1), (b[:, :, changed] * w).sum(axis=1), redo)
        x[:, changed] = _refine(xc, u[:, changed], v[:, changed], projections, w, iterations)
        inliers[:, changed] = w
        ok[changed] = redo
        error[:, changed] = _errors(x[:, changed], u[:, changed], v[:, changed], projections)
    views = inliers.sum(axis=0)
    x[:, ~ok] = np.nan
    with np.errstate(invalid="ignore"):
        mean_error = np.where(inliers, error, 0.0).sum(axis=0) / views
    mean_error[~ok] = np.nan
    return Triangulation(x.T.copy(), inliers, mean_error, views)


def _best_pairs(u, v, projections, seen, a, b, threshold_px):
    """Inliers (C, K) of the best two-view hypothesis of each of K points."""
    c, k = seen.shape
    i, j = np.triu_indices(c, 1)
    pair, point = np.nonzero(seen[i] & seen[j])  # every pair of views that both see a point
    best_key = np.full(k, -np.inf)
    best = np.zeros((c, k), bool)
    scale = 1.0 / (c * threshold_px + 1.0)  # the summed error of the inliers is below c * threshold
    for start in range(0, len(pair), _HYPOTHESES_PER_BATCH):
        p, q = pair[start:start + _HYPOTHESES_PER_BATCH], point[start:start + _HYPOTHESES_PER_BATCH]
        ip, jp = i[p], j[p]
        x = _solve(a[:, ip, q] + a[:, jp, q], b[:, ip, q] + b[:, jp, q], np.ones(len(p), bool))
        error = _errors(x, u[:, q], v[:, q], projections)  # (C, H)
        inlier = seen[:, q] & (error < threshold_px)
        key = inlier.sum(axis=0) - scale * np.where(inlier, error, 0.0).sum(axis=0)
        # The best hypothesis of each point in this batch, then against the batches before.
        order = np.lexsort((-key, q))
        first = np.ones(len(order), bool)
        first[1:] = q[order[1:]] != q[order[:-1]]
        top = order[first]
        top = top[key[top] > best_key[q[top]]]
        best_key[q[top]] = key[top]
        best[:, q[top]] = inlier[:, top]
    return best


def _refine(x, u, v, projections, inliers, iterations):
    """Gauss-Newton on the reprojection error; x (3, N), u v inliers (C, N)."""
    live = ~np.isnan(x).any(axis=0) & (inliers.sum(axis=0) >= 2)
    if not live.any():
        return x
    x = x.copy()
    xl, w = x[:, live], inliers[:, live]
    ul, vl = np.where(w, u[:, live], 0.0), np.where(w, v[:, live], 0.0)
    p3 = projections[:, :, :3, None]  # (C, 3, 3, 1)
    for _ in range(iterations):
        pu, pv, z = project_undistorted(xl, projections)
        z = np.where(w, z, 1.0)
        ru, rv = np.where(w, pu - ul, 0.0), np.where(w, pv - vl, 0.0)
        # d(u, v)/dX = (P[0:2] - (u, v) P[2]) / z, rows zero outside the inliers: (3, C, K) each.
        ju = ((p3[:, 0] - pu[:, None] * p3[:, 2]) * (w / z)[:, None]).swapaxes(0, 1)
        jv = ((p3[:, 1] - pv[:, None] * p3[:, 2]) * (w / z)[:, None]).swapaxes(0, 1)
        jtj = (ju[_I] * ju[_J] + jv[_I] * jv[_J]).sum(axis=1)
        jtr = (ju * ru + jv * rv).sum(axis=1)
        step = _solve(jtj, jtr, np.ones(xl.shape[1], bool))
        xl = xl - np.nan_to_num(step)
    x[:, live] = xl
    return x


def refine(points, pixels, projections, inliers, *, iterations: int = 2) -> np.ndarray:
    """Gauss-Newton on the reprojection error over each point's inlier views, vectorised.

    Parameters
    ----------
    points : ndarray (N, 3)
        Starting positions in metres (NaN rows are left alone).
    pixels : ndarray (C, N, 2)
        Undistorted pixels.
    projections : ndarray (C, 3, 4)
    inliers : ndarray (C, N) bool
        Views that count.
    iterations : int

    Returns
    -------
    ndarray (N, 3)
    """
    pixels, projections = _check(pixels, projections)
    inliers = np.asarray(inliers, bool) & ~np.isnan(pixels).any(axis=-1)
    x = np.asarray(points, np.float64).T
    return _refine(x, pixels[..., 0], pixels[..., 1], projections, inliers, iterations).T.copy()
