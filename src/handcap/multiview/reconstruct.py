"""From 2D detections to 3D marker trajectories: undistort, triangulate robustly, keep the evidence.

:func:`triangulate_detections` splits the take into blocks of frames and
triangulates each block on its own (``handcap.parallel``: local processes or a
Dask cluster, same results either way). In a block:

1. each camera's pixels are undistorted (OpenCV's iterative inversion);
2. every marker in every frame is a point; a camera that reports one marker id
   twice in a frame (a wrong id landing on a real one) gives the point an extra
   view with the same camera's projection, so RANSAC decides which is right;
3. :func:`handcap.multiview.triangulation.triangulate_ransac` finds each point
   from the best inlier set of views and refines it;
4. the reprojection error, the number of inlier views and a metric residual
   (the mean distance between the point and its inlier rays, as Vicon and
   Qualisys report it) are kept per marker and frame, and every detection is
   flagged used or rejected.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from handcap.core.cameras import CameraRig
from handcap.core.errors import HandcapError
from handcap.core.markers import MarkerSequence
from handcap.core.files import save_npz
from handcap.multiview.detections import Detections
from handcap.multiview.triangulation import project_undistorted, triangulate_ransac
from handcap.parallel import default_workers, idle_workers, map_chunks


@dataclass(frozen=True, eq=False)
class TriangulatedMarkers:
    """Markers triangulated from 2D detections.

    Attributes
    ----------
    positions : ndarray (T, M, 3)
        Metres; NaN where no inlier set of ``min_views`` views was found.
    names : tuple of str, length M
    rate : float
        Frames per second.
    error_px : ndarray (T, M)
        Mean reprojection error over the inlier views, pixels; NaN where no point.
    views : ndarray (T, M) int
        Inlier views; 0 where no point.
    residual : ndarray (T, M)
        Mean distance from the point to its inlier rays, metres; NaN where no point.
    used : ndarray (N,) bool
        Per detection row (in the order of the input): used as an inlier view.
    """

    positions: np.ndarray
    names: tuple
    rate: float
    error_px: np.ndarray
    views: np.ndarray
    residual: np.ndarray
    used: np.ndarray

    def to_markers(self) -> MarkerSequence:
        """A :class:`MarkerSequence` with the metric residuals (what C3D stores)."""
        return MarkerSequence(self.positions, self.names, self.rate, self.residual)

    def summary(self) -> str:
        """One line: frames, markers, points from detections (rejected), mean reprojection error and views."""
        s = self.counts()
        return (f"{s['frames']} frames, {s['markers']} markers, {s['points']} points from {s['detections']} detections "
                f"({s['rejected']} rejected), mean reprojection error {s['mean_error_px']:.2f} px over "
                f"{s['mean_views']:.1f} views")

    def counts(self) -> dict:
        """Counts and mean errors, for reports."""
        found = ~np.isnan(self.positions[..., 0])
        return {"frames": int(self.positions.shape[0]), "markers": len(self.names),
                "points": int(found.sum()), "detections": int(len(self.used)),
                "rejected": int((~self.used).sum()),
                "mean_error_px": float(np.nanmean(self.error_px)) if found.any() else float("nan"),
                "mean_views": float(self.views[found].mean()) if found.any() else float("nan")}


def triangulate_detections(detections: Detections, rig: CameraRig, *, min_views: int = 3,
                           threshold_px: float = 5.0, chunk_frames: int | None = None, scheduler=None,
                           workers: int | None = None, progress: bool | None = None) -> TriangulatedMarkers:
    """Triangulate every marker in every frame from the 2D detections of a calibrated rig.

    Parameters
    ----------
    detections : Detections
        Distorted pixels of named markers by named cameras.
    rig : CameraRig
        Must contain every camera the detections name (the rig may have more).
    min_views : int
        Inlier views a marker needs in a frame (at least 2; default 3).
    threshold_px : float
        Reprojection error below which a view is an inlier, pixels.
    chunk_frames : int, optional
        Frames per block of work (default: the take split evenly over the
        workers, at most 2000 frames per block).
    scheduler : None, str or distributed.Client
        See :func:`handcap.parallel.map_chunks`.
    workers : int, optional
        Local processes. Default: chosen by size: the first frames (about
        :data:`PROBE_DETECTIONS` detections) are triangulated in this process
        and timed, and the rest goes to a pool only when :func:`pool_workers`
        expects it to be faster (a small take stays in this process). Results
        are the same whichever is chosen.
    progress : bool, optional
        Progress bar over blocks; default when standard error is a terminal.

    Returns
    -------
    TriangulatedMarkers

    Raises
    ------
    HandcapError
        Detections of a camera the rig lacks, or bad parameters.
    """
    if not isinstance(detections, Detections):
        raise HandcapError(f"need Detections, got {type(detections).__name__}")
    to_rig = detections.camera_order(rig)
    if isinstance(min_views, bool) or not isinstance(min_views, (int, np.integer)) or min_views < 2:
        raise HandcapError(f"min_views must be a whole number of at least 2, got {min_views!r}")
    if min_views > len(detections.camera_names):
        raise HandcapError(f"min_views is {min_views} but the detections come from "
                           f"{len(detections.camera_names)} cameras")
    try:
        threshold_px = float(threshold_px)
    except (TypeError, ValueError):
        raise HandcapError(f"threshold_px must be a number of pixels, got {threshold_px!r}") from None
    if not (np.isfinite(threshold_px) and threshold_px > 0):
        raise HandcapError(f"threshold_px must be a positive number of pixels, got {threshold_px}")
    n_frames, n_markers = detections.n_frames, len(detections.marker_names)
    if chunk_frames is not None and (isinstance(chunk_frames, bool) or not isinstance(chunk_frames, (int, np.integer))
                                     or chunk_frames < 1):
        raise HandcapError(f"chunk_frames must be a whole number of at least 1, got {chunk_frames!r}")
    if workers is not None and (isinstance(workers, bool) or not isinstance(workers, (int, np.integer)) or workers < 1):
        raise HandcapError(f"workers must be a whole number of at least 1, got {workers!r}")

    order = np.argsort(detections.frame, kind="stable")
    frames = detections.frame[order]
    cameras = tuple(rig[int(i)] for i in to_rig)

    def blocks(first: int, size: int) -> list:
        """Blocks of ``size`` frames from ``first`` to the end, with the rows (into detections) of each."""
        starts = np.arange(first, max(n_frames, first + 1), size)
        bounds = np.searchsorted(frames, np.append(starts, n_frames))
        out = []
        for k, start in enumerate(starts):
            rows = order[bounds[k]:bounds[k + 1]]
            out.append((_Block(cameras, int(start), int(min(start + size, n_frames)) - int(start), n_markers,
                               detections.frame[rows] - start, detections.camera[rows], detections.marker[rows],
                               detections.xy[rows], min_views, threshold_px), rows))
        return out

    done, first = [], 0
    if workers is None and scheduler is None and chunk_frames is None:
        # Size decides (issue 14): time a first block here, and start a pool for the rest only if the rest
        # would take longer in this process than starting the workers costs.
        first = _probe_frames(frames, n_frames)
        (task, rows), = blocks(0, max(first, 1))[:1]
        start = time.perf_counter()
        done.append((task, rows, _triangulate_block(task)))
        seconds = time.perf_counter() - start
        workers = pool_workers(seconds * (len(detections) - len(rows)) / max(len(rows), 1))
    if first < n_frames:
        if chunk_frames is None:
            per_worker = -(-(n_frames - first) // (workers or default_workers())) if scheduler is None else 500
            chunk_frames = int(np.clip(per_worker, 1, 2000))
        tasks = blocks(first, chunk_frames)
        results = map_chunks(_triangulate_block, [task for task, _ in tasks], scheduler=scheduler, workers=workers,
                             progress=progress, desc="triangulate")
        done += [(task, rows, result) for (task, rows), result in zip(tasks, results)]

    positions = np.full((n_frames, n_markers, 3), np.nan)
    error = np.full((n_frames, n_markers), np.nan)
    views = np.zeros((n_frames, n_markers), np.int64)
    residual = np.full((n_frames, n_markers), np.nan)
    used = np.zeros(len(detections), bool)
    for task, rows, result in done:
        span = slice(task.start, task.start + task.n_frames)
        positions[span], error[span], views[span], residual[span] = result[:4]
        used[rows] = result[4]
    return TriangulatedMarkers(positions, detections.marker_names, detections.rate, error, views, residual, used)


#: Detections triangulated in this process to time the work before choosing workers (about 0.3 s).
PROBE_DETECTIONS = 50_000
#: Seconds until a pool of local workers is ready: fresh interpreters importing numpy, scipy and handcap,
#: started side by side. Measured at 3.9-4.4 s for 2 workers (``map_chunks`` of a function that imports
#: this module, 2 cores at load average 7); on an idle machine it is less, so the pool is chosen a little
#: late, never too early. ``benchmarks/triangulate.py --break-even`` shows the choice against both ways.
POOL_START_SECONDS = 4.0


def pool_workers(serial_seconds: float, cores: int | None = None) -> int:
    """Local processes worth using for work that takes ``serial_seconds`` in this process.

    With W workers the work takes about ``serial / W + POOL_START_SECONDS``; the
    pool pays when that is shorter than ``serial``, i.e. above
    ``POOL_START_SECONDS * W / (W - 1)`` seconds of work (8 s on 2 cores).

    Parameters
    ----------
    serial_seconds : float
        Estimated time of the work in this process.
    cores : int, optional
        Cores free for the work (default :func:`handcap.parallel.idle_workers`: on a
        busy machine a pool only adds its start to the time).

    Returns
    -------
    int
        1 (stay in this process) or ``cores``.
    """
    cores = idle_workers() if cores is None else cores
    if cores > 1 and serial_seconds / cores + POOL_START_SECONDS < serial_seconds:
        return cores
    return 1


def _probe_frames(frames: np.ndarray, n_frames: int) -> int:
    """Leading frames holding about :data:`PROBE_DETECTIONS` detections (``frames`` sorted); all if fewer."""
    if len(frames) <= PROBE_DETECTIONS:
        return n_frames
    return int(min(n_frames, frames[PROBE_DETECTIONS] + 1))


@dataclass(frozen=True)
class _Block:
    """One block of frames to triangulate (plain data, picklable)."""

    cameras: tuple
    start: int
    n_frames: int
    n_markers: int
    frame: np.ndarray   # (n,) frames within the block
    camera: np.ndarray  # (n,) index into cameras
    marker: np.ndarray  # (n,)
    xy: np.ndarray      # (n, 2) distorted pixels
    min_views: int
    threshold_px: float


def _triangulate_block(block: _Block):
    """Positions (F, M, 3), error (F, M), views (F, M), residual (F, M), used (n,) of one block."""
    f, m, c = block.n_frames, block.n_markers, len(block.cameras)
    positions = np.full((f, m, 3), np.nan)
    error = np.full((f, m), np.nan)
    views = np.zeros((f, m), np.int64)
    residual = np.full((f, m), np.nan)
    used = np.zeros(len(block.frame), bool)
    if not len(block.frame):
        return positions, error, views, residual, used

    undistorted = np.empty_like(block.xy)
    for i, camera in enumerate(block.cameras):
        mine = block.camera == i
        if mine.any():
            undistorted[mine] = camera.undistort_pixels(block.xy[mine])
    projections = np.stack([camera.projection for camera in block.cameras])
    focal = np.array([camera.matrix[[0, 1], [0, 1]].mean() for camera in block.cameras])

    # Points (frame, marker) with any detection, and each row's slot among its camera's detections of it.
    point_of_row = block.frame * m + block.marker
    points, point_index = np.unique(point_of_row, return_inverse=True)
    key = point_index * c + block.camera
    order = np.lexsort((np.arange(len(key)), key))
    sorted_key = key[order]
    starts = np.flatnonzero(np.r_[True, sorted_key[1:] != sorted_key[:-1]])
    run_start = np.repeat(starts, np.diff(np.r_[starts, len(key)]))
    slot = np.empty(len(key), np.int64)
    slot[order] = np.arange(len(key)) - run_start  # position of each row within its run of equal keys
    view = block.camera + c * slot  # extra views repeat the cameras: view v has camera v % c
    n_views = c * (int(slot.max()) + 1)
    # Points with a repeated id in some camera get the extra views; the others are solved with c views.
    crowded = np.zeros(len(points), bool)
    crowded[point_index[slot > 0]] = True
    for group, width in ((~crowded, c), (crowded, n_views)):
        chosen = np.flatnonzero(group)
        if not chosen.size:
            continue
        local = np.full(len(points), -1)
        local[chosen] = np.arange(chosen.size)
        rows = np.flatnonzero(group[point_index])
        pixels = np.full((width, chosen.size, 2), np.nan)
        pixels[view[rows], local[point_index[rows]]] = undistorted[rows]
        cams = np.arange(width) % c
        result = triangulate_ransac(pixels, projections[cams], min_views=block.min_views,
                                    threshold_px=block.threshold_px)
        # Distinct cameras among the inliers count as views (two slots of one camera are one view).
        inlier_cameras = np.zeros((c, chosen.size), bool)
        np.logical_or.at(inlier_cameras, cams, result.inliers)
        enough = inlier_cameras.sum(axis=0) >= block.min_views
        ok = enough & ~np.isnan(result.points[:, 0])
        t, k = np.divmod(points[chosen], m)
        positions[t[ok], k[ok]] = result.points[ok]
        error[t[ok], k[ok]] = result.error[ok]
        views[t[ok], k[ok]] = inlier_cameras.sum(axis=0)[ok]
        residual[t[ok], k[ok]] = _ray_residual(result.points[ok], pixels[:, ok], projections[cams],
                                               focal[cams], result.inliers[:, ok])
        used[rows] = (result.inliers & ok)[view[rows], local[point_index[rows]]]
    return positions, error, views, residual, used


def _ray_residual(points, pixels, projections, focal, inliers):
    """Mean distance (metres) from each point (N, 3) to its inlier rays: pixel error x depth / focal."""
    u, v, depth = project_undistorted(points.T, projections)
    pixel_error = np.hypot(u - pixels[..., 0], v - pixels[..., 1])
    distance = np.where(inliers, pixel_error * depth / focal[:, None], 0.0)
    return distance.sum(axis=0) / np.maximum(inliers.sum(axis=0), 1)


def quality_path(markers_path) -> Path:
    """Where :func:`write_quality` puts the quality of ``markers_path``: ``STEM.triangulation.npz`` beside it."""
    path = Path(markers_path)
    return path.with_name(path.stem + ".triangulation.npz")


def write_quality(result: TriangulatedMarkers, markers_path, *, sync=None) -> Path:
    """Write the per-marker quality of a triangulation beside its markers file.

    The ``.npz`` holds ``names (M,)``, ``rate``, ``error_px (T, M)`` (mean
    reprojection error of the inlier views, NaN where no point), ``views (T, M)``
    (inlier views), ``residual (T, M)`` (metres) and ``used (N,)`` (per
    detection row of the input, in its order: used as an inlier view); for
    cameras synchronised first, ``sync_cameras (C,)``, ``sync_offsets (C,)``
    and ``sync_drift (C,)`` (frames and frames per frame, see
    :mod:`handcap.multiview.sync`), and ``used`` is per row of the synchronised
    detections.

    Parameters
    ----------
    result : TriangulatedMarkers
        The triangulation (pixels for ``error_px``, metres for ``residual``, frames per second for ``rate``).
    markers_path : str or Path
        The markers file it belongs to; it need not exist.
    sync : Sync or None
        The cameras' offsets, when they were synchronised.

    Returns
    -------
    Path
        The file written (see :func:`quality_path`).
    """
    path = quality_path(markers_path)
    save_npz(path, {"names": np.array(result.names), "rate": np.array(result.rate), "error_px": result.error_px,
                    "views": result.views, "residual": result.residual, "used": result.used,
                    **({} if sync is None else {"sync_cameras": np.array(sync.camera_names),
                                                "sync_offsets": np.asarray(sync.offsets, dtype=np.float64),
                                                "sync_drift": np.zeros(len(sync.offsets)) if sync.drift is None
                                                else np.asarray(sync.drift, dtype=np.float64)})})
    return path


__all__ = ["PROBE_DETECTIONS", "POOL_START_SECONDS", "TriangulatedMarkers", "pool_workers", "quality_path",
           "triangulate_detections", "write_quality"]
