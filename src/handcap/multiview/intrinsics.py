"""Intrinsics of one camera from views of a planar board (OpenCV's calibrateCamera, Zhang 2000), and
the board's pose in each view (solvePnP); see :mod:`handcap.multiview.calibration`."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from handcap.core.cameras import Camera
from handcap.core.errors import HandcapError
from handcap.core.rotations import matrix_from_axis_angle
from handcap.core.transforms import homogeneous
from handcap.multiview.boards import BoardDetections

# A view reprojecting worse than this many times the median view (and worse
# than _MIN_OUTLIER_RMS_PX) is dropped from an intrinsic calibration.
_OUTLIER_FACTOR = 3.0
_MIN_OUTLIER_RMS_PX = 0.5
# Fewest views an intrinsic calibration takes (Zhang's method needs 3 planes
# for a full camera matrix).
MIN_VIEWS = 3


@dataclass(frozen=True, eq=False)
class Intrinsics:
    """A camera calibrated from board views, and how well each view fits.

    Attributes
    ----------
    camera : Camera
        Matrix and distortions; at the origin (its extrinsics are zero).
    rms : float
        Reprojection RMS over the views kept, pixels.
    view_rms : ndarray of shape (V,)
        Reprojection RMS of each view kept, pixels.
    views : ndarray of int, shape (V,)
        Positions (into the detections' T frames) of the views kept.
    rejected : ndarray of int
        Positions of the views dropped as outliers.
    labels : tuple of str
        Names of the views kept (file names or video frames).
    board2camera : ndarray of shape (V, 4, 4)
        Board pose in each view kept, metres.
    """

    camera: Camera
    rms: float
    view_rms: np.ndarray
    views: np.ndarray
    rejected: np.ndarray
    labels: tuple[str, ...]
    board2camera: np.ndarray

    def __repr__(self) -> str:
        return (f"Intrinsics({self.camera!r}, RMS {self.rms:.3f} px over {len(self.views)} views, "
                f"{len(self.rejected)} rejected)")

    def summary(self) -> str:
        """One line: the camera's size, focal lengths, principal point and distortion."""
        camera = self.camera
        (fx, fy), (cx, cy) = camera.matrix[[0, 1], [0, 1]], camera.matrix[:2, 2]
        return (f"camera {camera.name}, {camera.size[0]}x{camera.size[1]} px, f = {fx:.2f}, {fy:.2f} px, principal "
                f"point ({cx:.1f}, {cy:.1f}) px, k1 k2 p1 p2 k3 = {' '.join(f'{k:.4g}' for k in camera.distortions)}")


def _view_arrays(detections: BoardDetections, views):
    points = detections.board.object_points
    objects, images = [], []
    for t in views:
        seen = np.isfinite(detections.pixels[t, :, 0])
        objects.append(points[seen].astype(np.float32))
        images.append(detections.pixels[t, seen].astype(np.float32).reshape(-1, 1, 2))
    return objects, images


def _opencv_calibrate(detections: BoardDetections, views, flags: int):
    objects, images = _view_arrays(detections, views)
    try:
        rms, matrix, distortions, rvecs, tvecs, _, _, view_rms = cv2.calibrateCameraExtended(
            objects, images, detections.size, None, None, flags=flags)
    except cv2.error as err:
        raise HandcapError(f"{detections.source}: OpenCV could not calibrate from {len(views)} views "
                           f"({str(err).strip().splitlines()[-1]})") from None
    return float(rms), matrix, distortions.ravel()[:5], np.asarray(rvecs).reshape(-1, 3), \
        np.asarray(tvecs).reshape(-1, 3), view_rms.ravel()


def calibrate_intrinsics(detections: BoardDetections, *, name: str | None = None, fix_k3: bool = False,
                         reject_outliers: bool = True, max_views: int = 80) -> Intrinsics:
    """Calibrate one camera's matrix and lens distortion from its board views.

    Parameters
    ----------
    detections : BoardDetections
        The board found in this camera's images or video frames.
    name : str, optional
        Name of the camera (default: the source's file or folder name).
    fix_k3 : bool
        Keep k3 = 0 (fewer than about ten views rarely determine it).
    reject_outliers : bool
        Drop views whose RMS exceeds 3 times the median view's (and 0.5 px),
        the worst first, and calibrate again, keeping at least 3 views.
    max_views : int
        Use at most this many views, spread evenly over the frames (a long
        video holds many near-duplicates and :func:`cv2.calibrateCamera` slows).

    Returns
    -------
    Intrinsics

    Raises
    ------
    HandcapError
        If the board is never seen (the message names the source), or seen in
        fewer than 3 frames, or OpenCV fails.
    """
    if not isinstance(detections, BoardDetections):
        raise HandcapError(f"calibrate_intrinsics needs BoardDetections, got {type(detections).__name__}")
    name = Path(detections.source).stem if name is None else name
    found = np.flatnonzero(detections.found)
    if len(found) == 0:
        raise HandcapError(f"{detections.source}: the board {detections.board.spec} is never seen in its "
                           f"{detections.n_frames} frames; check the board spec (size, inverted) and the images")
    if len(found) < MIN_VIEWS:
        raise HandcapError(f"{detections.source}: the board is seen in only {len(found)} of "
                           f"{detections.n_frames} frames; calibration needs at least {MIN_VIEWS} views")
    if len(found) > max_views:
        found = found[np.unique(np.round(np.linspace(0, len(found) - 1, max_views)).astype(int))]
    flags = cv2.CALIB_FIX_K3 if fix_k3 else 0
    views = list(found)
    rejected = []
    while True:
        rms, matrix, distortions, rvecs, tvecs, view_rms = _opencv_calibrate(detections, views, flags)
        if not reject_outliers or len(views) <= MIN_VIEWS:
            break
        limit = max(_OUTLIER_FACTOR * np.median(view_rms), _MIN_OUTLIER_RMS_PX)
        worst = int(np.argmax(view_rms))
        if view_rms[worst] <= limit:
            break
        rejected.append(views.pop(worst))
    matrix[0, 1] = 0.0  # calibrateCamera fits no skew, but keep the zero exact
    camera = Camera(name, detections.size, matrix, distortions)
    board2camera = homogeneous(np.asarray(matrix_from_axis_angle(rvecs)), tvecs)
    return Intrinsics(camera, rms, view_rms, np.array(views), np.array(sorted(rejected), dtype=np.int64),
                      tuple(detections.labels[t] for t in views), board2camera)


# -- board poses -----------------------------------------------------------------------
def board_poses(detections: BoardDetections, camera: Camera, *, views=None) -> tuple[np.ndarray, np.ndarray]:
    """Pose of the board in each view of a calibrated camera (:func:`cv2.solvePnP`).

    Parameters
    ----------
    detections : BoardDetections
    camera : Camera
        Its matrix and distortions are used; its extrinsics are not.
    views : sequence of int, optional
        Positions of the frames to solve (default: every frame with the board).

    Returns
    -------
    board2camera : ndarray of shape (T, 4, 4)
        Board-to-camera transforms in metres; NaN where not solved.
    rms : ndarray of shape (T,)
        Reprojection RMS of each solved view in pixels, NaN elsewhere.
    """
    t_count = detections.n_frames
    board2camera = np.full((t_count, 4, 4), np.nan)
    rms = np.full(t_count, np.nan)
    views = np.flatnonzero(detections.found) if views is None else views
    points = detections.board.object_points
    for t in views:
        seen = np.isfinite(detections.pixels[t, :, 0])
        if seen.sum() < 4:
            continue
        objects, pixels = points[seen], detections.pixels[t, seen].reshape(-1, 1, 2)
        # IPPE gives both poses a planar target allows; keep the better one.
        count, rvecs, tvecs, errors = cv2.solvePnPGeneric(objects, pixels, camera.matrix, camera.distortions,
                                                          flags=cv2.SOLVEPNP_IPPE)
        if not count:
            continue
        best = int(np.argmin(np.asarray(errors).ravel()))
        rvec, tvec = cv2.solvePnPRefineLM(objects, pixels, camera.matrix, camera.distortions,
                                          rvecs[best].copy(), tvecs[best].copy())
        projected, _ = cv2.projectPoints(objects, rvec, tvec, camera.matrix, camera.distortions)
        rms[t] = np.sqrt(np.mean(np.sum((projected.reshape(-1, 2) - pixels.reshape(-1, 2)) ** 2, axis=1)))
        board2camera[t] = homogeneous(cv2.Rodrigues(rvec)[0], tvec.ravel())
    return board2camera, rms
