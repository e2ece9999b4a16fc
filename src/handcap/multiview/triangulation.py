"""Triangulation of markers seen by several calibrated cameras (DexterCap section 3.1.1).

Linear triangulation (DLT) from every view, RANSAC over views that keeps the
*best* inlier set (most inliers, then least reprojection error; the research
code kept the last one), and a Gauss-Newton refinement of the reprojection
error over the inliers. Everything is vectorised over points: the candidate
pairs of views of all points are solved as one batch.

Pixels here are *undistorted* (``CameraRig.undistort_pixels``) and the
projection matrices map the world (metres) to them (``CameraRig.projections``).
"""

from __future__ import annotations

from dataclasses import dataclass
from itertools import combinations

import numpy as np

from handcap.core.errors import HandcapError


def _check(pixels, projections):
    pixels = np.asarray(pixels, dtype=np.float64)
    projections = np.asarray(projections, dtype=np.float64)
    if projections.ndim != 3 or projections.shape[1:] != (3, 4):
        raise HandcapError(f"projections must have shape (C, 3, 4), got {projections.shape}")
    if pixels.ndim != 3 or pixels.shape[0] != len(projections) or pixels.shape[2] != 2:
        raise HandcapError(f"pixels must have shape (C, N, 2) with C = {len(projections)}, got {pixels.shape}")
    return pixels, projections


def triangulate_linear(pixels, projections, weights=None) -> np.ndarray:
    """Linear (DLT) triangulation of points seen by several cameras.

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
    xy = np.where(seen[..., None], pixels, 0.0)
    # Rows x P3 - P1 and y P3 - P2 of every view: (N, 2C, 4).
    rows = np.concatenate([xy[..., 0:1, None] * projections[:, None, 2:3] - projections[:, None, 0:1],
                           xy[..., 1:2, None] * projections[:, None, 2:3] - projections[:, None, 1:2]], axis=2)
    rows = rows / np.maximum(np.linalg.norm(rows, axis=-1, keepdims=True), 1e-300)  # condition
    rows = rows * w[..., None, None]
    a = np.swapaxes(rows, 0, 1).reshape(pixels.shape[1], -1, 4)
    _, _, vt = np.linalg.svd(a)
    h = vt[:, -1]
    points = h[:, :3] / h[:, 3:4]
    points[np.count_nonzero(w > 0, axis=0) < 2] = np.nan
    return points


def project(points, projections) -> np.ndarray:
    """Undistorted pixels (C, N, 2) of points (N, 3); NaN behind a camera."""
    h = np.einsum("cij,nj->cni", projections[:, :, :3], points) + projections[:, None, :, 3]
    with np.errstate(invalid="ignore", divide="ignore"):
        out = h[..., :2] / h[..., 2:3]
    out[h[..., 2] <= 0] = np.nan
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
        Mean reprojection error over the inliers, pixels.
    views : ndarray (N,) int
        Number of inlier views.
    """

    points: np.ndarray
    inliers: np.ndarray
    error: np.ndarray
    views: np.ndarray


def triangulate_ransac(pixels, projections, *, min_views: int = 3, threshold_px: float = 5.0,
                       iterations: int = 3) -> Triangulation:
    """Robust triangulation: every pair of views as a hypothesis, the best inlier set kept, then refined.

    Parameters
    ----------
    pixels : ndarray of shape (C, N, 2)
        Undistorted pixels, NaN where unseen.
    projections : ndarray of shape (C, 3, 4)
    min_views : int
        Inlier views a point needs (at least 2).
    threshold_px : float
        Reprojection error below which a view is an inlier, pixels.
    iterations : int
        Gauss-Newton steps of the final refinement.

    Returns
    -------
    Triangulation
    """
    pixels, projections = _check(pixels, projections)
    if min_views < 2:
        raise HandcapError(f"min_views must be at least 2, got {min_views}")
    if not threshold_px > 0:
        raise HandcapError(f"threshold_px must be positive, got {threshold_px}")
    c, n = pixels.shape[:2]
    seen = ~np.isnan(pixels).any(axis=-1)
    pairs = np.array(list(combinations(range(c), 2)), dtype=np.int64).reshape(-1, 2)
    best_count = np.zeros(n, np.int64)
    best_cost = np.full(n, np.inf)
    best_inliers = np.zeros((c, n), bool)
    for i, j in pairs:  # C(C-1)/2 batches, each over every point
        both = seen[i] & seen[j]
        if not both.any():
            continue
        idx = np.flatnonzero(both)
        candidate = triangulate_linear(pixels[[i, j]][:, idx], projections[[i, j]])
        error = np.linalg.norm(project(candidate, projections) - pixels[:, idx], axis=-1)  # (C, K)
        inlier = seen[:, idx] & (error < threshold_px)
        count = inlier.sum(axis=0)
        cost = np.where(inlier, error, 0.0).sum(axis=0)
        better = (count > best_count[idx]) | ((count == best_count[idx]) & (cost < best_cost[idx]))
        take = idx[better]
        best_count[take], best_cost[take] = count[better], cost[better]
        best_inliers[:, take] = inlier[:, better]
    ok = best_count >= min_views
    best_inliers[:, ~ok] = False
    points = triangulate_linear(pixels, projections, weights=best_inliers.astype(np.float64))
    points[~ok] = np.nan
    points = refine(points, pixels, projections, best_inliers, iterations=iterations)
    error = np.linalg.norm(project(points, projections) - pixels, axis=-1)
    with np.errstate(invalid="ignore"):
        mean_error = np.where(best_inliers, error, 0.0).sum(axis=0) / best_inliers.sum(axis=0)
    mean_error[~ok] = np.nan
    return Triangulation(points, best_inliers, mean_error, best_inliers.sum(axis=0))


def refine(points, pixels, projections, inliers, *, iterations: int = 3) -> np.ndarray:
    """Gauss-Newton on the reprojection error over each point's inlier views, vectorised.

    Parameters
    ----------
    points : ndarray (N, 3)
        Starting positions (NaN rows are left alone).
    pixels : ndarray (C, N, 2)
    projections : ndarray (C, 3, 4)
    inliers : ndarray (C, N) bool
    iterations : int
    """
    points = points.copy()
    live = ~np.isnan(points).any(axis=1)
    x = points[live]
    obs = pixels[:, live]
    w = inliers[:, live].astype(np.float64)
    p3, t = projections[:, :, :3], projections[:, :, 3]
    for _ in range(iterations):
        h = np.einsum("cij,nj->cni", p3, x) + t[:, None]  # (C, K, 3)
        z = h[..., 2:3]
        uv = h[..., :2] / z
        residual = np.where(w[..., None] > 0, np.nan_to_num(uv - obs), 0.0)  # (C, K, 2)
        # d(uv)/dX = (P[:2] - uv P[2]) / z
        jac = (p3[:, None, :2, :] - uv[..., None] * p3[:, None, 2:3, :]) / z[..., None]  # (C, K, 2, 3)
        jac = jac * w[..., None, None]
        jtj = np.einsum("cnai,cnaj->nij", jac, jac)
        jtr = np.einsum("cnai,cna->ni", jac, residual)
        step = np.linalg.solve(jtj + 1e-12 * np.eye(3), jtr[..., None])[..., 0]
        x = x - step
    points[live] = x
    return points
