"""Camera calibration from a planar board: intrinsics per camera, then the whole rig.

DexterCap (section 3.1.1) calibrates its cameras "using the standard procedure
with the OpenCV library". That is what this module does, in two stages:

1. **Intrinsics** (:func:`calibrate_intrinsics`): :func:`cv2.calibrateCamera`
   on the board views of one camera (Zhang's method, OpenCV's five distortion
   terms ``k1 k2 p1 p2 k3``), dropping views that reproject much worse than
   the others and calibrating again.
2. **Rig** (:func:`calibrate_rig`): every camera films the same board at the
   same instants (synchronised recordings; frame index = time). Each view's
   board pose comes from :func:`cv2.solvePnP`; two cameras that saw the board
   at the same instant know their relative pose, and chaining those over a
   maximum spanning tree of the cameras (weighted by shared views) places every
   camera. :func:`bundle_adjust` then refines every camera pose and every board
   pose together (and optionally the intrinsics) by minimising the reprojection
   error of all corners with :func:`scipy.optimize.least_squares`, a sparse
   Jacobian and a robust loss.

World frame of a rig (written down once)
----------------------------------------
``origin="board"`` (default): the board as it lay at ``origin_frame`` (by
default the first frame in which the first camera sees it). The origin is the
board frame's origin (corner 0 of a checkerboard, the outer corner of a
ChArUco board, see :mod:`handcap.multiview.boards`), x runs along the board's
rows, and z points out of the printed face, towards the cameras that see it;
y = z x x. A board lying face up on the floor thus gives z up, as DESIGN.md
wants. ``origin="camera"``: the first camera's frame (OpenCV's: x right, y
down, z along its optical axis), that camera at the origin. Either way the
unit is the metre, fixed by the board's square size.

References
----------
Zhang Z. (2000), A flexible new technique for camera calibration, IEEE TPAMI
22(11), doi:10.1109/34.888718.
Triggs B. et al. (2000), Bundle adjustment -- a modern synthesis, Vision
Algorithms: Theory and Practice, doi:10.1007/3-540-44480-7_21.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
from scipy.optimize import least_squares
from scipy.sparse import coo_matrix

from handcap.core.cameras import Camera, CameraRig
from handcap.core.errors import HandcapError
from handcap.core.rotations import axis_angle_from_matrix, matrix_from_axis_angle
from handcap.multiview.boards import Board, BoardDetections

ORIGINS = ("board", "camera")
LOSSES = ("linear", "huber", "soft_l1", "cauchy", "arctan")
# A view reprojecting worse than this many times the median view (and worse
# than _MIN_OUTLIER_RMS_PX) is dropped from an intrinsic calibration.
_OUTLIER_FACTOR = 3.0
_MIN_OUTLIER_RMS_PX = 0.5
# Fewest views an intrinsic calibration takes (Zhang's method needs 3 planes
# for a full camera matrix).
MIN_VIEWS = 3
# A board pose from solvePnP that reprojects worse than this is not trusted
# to start the bundle adjustment from (the view still enters it).
_PNP_START_RMS_PX = 5.0
# Forward-difference step, relative to max(1, |parameter|) (about sqrt of float64's eps).
_FD_STEP = 1.5e-8
# Smallest eigenvalue, relative to the largest, that block whitening inverts.
_WHITENING_FLOOR = 1e-8


# -- small geometry helpers ------------------------------------------------------------
def _transform(rotation: np.ndarray, translation: np.ndarray) -> np.ndarray:
    out = np.zeros(rotation.shape[:-2] + (4, 4))
    out[..., :3, :3] = rotation
    out[..., :3, 3] = translation
    out[..., 3, 3] = 1.0
    return out


def _invert(transform: np.ndarray) -> np.ndarray:
    rotation = np.swapaxes(transform[..., :3, :3], -1, -2)
    return _transform(rotation, -np.einsum("...ij,...j->...i", rotation, transform[..., :3, 3]))


def _mean_rotation(rotations: np.ndarray) -> np.ndarray:
    """Chordal L2 mean of rotations (n, 3, 3)."""
    u, _, vt = np.linalg.svd(rotations.sum(axis=0))
    fix = np.diag([1.0, 1.0, np.sign(np.linalg.det(u @ vt))])
    return u @ fix @ vt


def _robust_mean_pose(transforms: np.ndarray) -> np.ndarray:
    """A pose (4, 4) summarising many estimates (n, 4, 4) of it, ignoring the wild ones.

    The medoid rotation (least total angle to the others) and the per-axis
    median translation pick the inliers: within 3 times the median deviation
    (at least 2 degrees and 2 cm) of both; the result is their mean.
    """
    rotations, translations = transforms[:, :3, :3], transforms[:, :3, 3]
    relative = np.einsum("aji,bjk->abik", rotations, rotations)
    cos = np.clip((np.trace(relative, axis1=-2, axis2=-1) - 1.0) / 2.0, -1.0, 1.0)
    angles = np.arccos(cos)
    medoid = rotations[np.argmin(angles.sum(axis=1))]
    angle = angles[np.argmin(angles.sum(axis=1))]
    distance = np.linalg.norm(translations - np.median(translations, axis=0), axis=1)
    keep = (angle <= max(3.0 * np.median(angle), np.radians(2.0))) & (distance <= max(3.0 * np.median(distance), 0.02))
    if not keep.any():
        return _transform(medoid, np.median(translations, axis=0))
    return _transform(_mean_rotation(rotations[keep]), translations[keep].mean(axis=0))


# -- intrinsics ------------------------------------------------------------------------
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
    board2camera = _transform(np.asarray(matrix_from_axis_angle(rvecs)), tvecs)
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
        board2camera[t] = _transform(cv2.Rodrigues(rvec)[0], tvec.ravel())
    return board2camera, rms


# -- bundle adjustment -----------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class BundleAdjustment:
    """Cameras and board poses after a bundle adjustment.

    Attributes
    ----------
    rig : CameraRig
        Refined cameras, in the frame of the first camera's start pose.
    board2world : ndarray of shape (T, 4, 4)
        Refined board poses, NaN for frames without observations.
    errors : ndarray of shape (C, T, N)
        Reprojection error of each observed corner, pixels; NaN where unobserved.
    success : bool
        Whether :func:`scipy.optimize.least_squares` converged.
    """

    rig: CameraRig
    board2world: np.ndarray
    errors: np.ndarray
    success: bool

    @property
    def rms(self) -> np.ndarray:
        """Reprojection RMS of each camera, pixels (C,)."""
        return _rms(self.errors)


def _rms(errors: np.ndarray) -> np.ndarray:
    c_count = errors.shape[0]
    flat = errors.reshape(c_count, -1)
    seen = np.isfinite(flat)
    with np.errstate(invalid="ignore"):
        return np.sqrt(np.nansum(flat ** 2, axis=1) / seen.sum(axis=1))


def _project(points_camera: np.ndarray, intrinsics: np.ndarray) -> np.ndarray:
    """OpenCV's projection of camera-frame points (K, 3) with per-point intrinsics (K, 9)."""
    fx, fy, cx, cy, k1, k2, p1, p2, k3 = intrinsics.T
    z = points_camera[:, 2]
    x, y = points_camera[:, 0] / z, points_camera[:, 1] / z
    r2 = x * x + y * y
    radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
    xy2 = 2.0 * x * y
    xd = x * radial + p1 * xy2 + p2 * (r2 + 2.0 * x * x)
    yd = y * radial + p1 * (r2 + 2.0 * y * y) + p2 * xy2
    return np.stack([fx * xd + cx, fy * yd + cy], axis=1)


def _intrinsic_vector(camera: Camera) -> np.ndarray:
    m = camera.matrix
    return np.concatenate([[m[0, 0], m[1, 1], m[0, 2], m[1, 2]], camera.distortions])


def _jacobian(residuals, x: np.ndarray, columns: np.ndarray, valid: np.ndarray):
    """Forward-difference Jacobian (sparse CSR) of residual pairs at ``x``.

    ``columns`` (K, S) holds, for each residual pair k, the parameter it
    depends on in each of S slots (where ``valid``); the parameters of one
    slot never share a pair, so one evaluation per slot gives them all.
    """
    f0 = residuals(x).reshape(-1, 2)
    data = np.zeros(columns.shape + (2,))
    for slot in range(columns.shape[1]):
        chosen = np.unique(columns[valid[:, slot], slot])
        stepped = x.copy()
        stepped[chosen] += _FD_STEP * np.maximum(1.0, np.abs(x[chosen]))
        step = (stepped - x)[columns[:, slot]]  # the steps as represented
        with np.errstate(divide="ignore", invalid="ignore"):
            data[:, slot] = (residuals(stepped).reshape(-1, 2) - f0) / step[:, None]
    rows = np.broadcast_to(np.arange(len(columns))[:, None], columns.shape)[valid]
    return coo_matrix((np.concatenate([data[valid][:, 0], data[valid][:, 1]]),
                       (np.concatenate([2 * rows, 2 * rows + 1]), np.tile(columns[valid], 2))),
                      shape=(2 * len(columns), len(x))).tocsr()


def _block_whitening(jacobian, blocks) -> tuple:
    """Block-diagonal ``P`` with ``P_b = (J_b^T J_b)^(-1/2)`` for each block b of columns, and its inverse (CSR)."""
    jacobian = jacobian.tocsc()
    rows, columns, values, inverse = [], [], [], []
    for block in blocks:
        if len(block) == 0:
            continue
        part = jacobian[:, block]
        eigenvalues, vectors = np.linalg.eigh((part.T @ part).toarray())
        # Directions the data hardly constrain are not blown up past 1e4 x the best one.
        root = np.sqrt(np.maximum(eigenvalues, max(eigenvalues.max(), 1e-300) * _WHITENING_FLOOR))
        values.append(((vectors / root) @ vectors.T).ravel())
        inverse.append(((vectors * root) @ vectors.T).ravel())
        rows.append(np.repeat(block, len(block)))
        columns.append(np.tile(block, len(block)))
    size = jacobian.shape[1]
    index = (np.concatenate(rows), np.concatenate(columns))
    return (coo_matrix((np.concatenate(values), index), shape=(size, size)).tocsr(),
            coo_matrix((np.concatenate(inverse), index), shape=(size, size)).tocsr())


def bundle_adjust(pixels, board: Board, rig: CameraRig, board2world, *, refine_intrinsics: bool = False,
                  fix_k3: bool = False, loss: str = "soft_l1", f_scale: float = 1.0,
                  max_nfev: int | None = None) -> BundleAdjustment:
    """Refine camera poses and board poses together (and optionally the intrinsics).

    Minimises the reprojection error of every observed corner over the 6
    extrinsic parameters of each camera but the first (which fixes the frame;
    the board's square size fixes the scale), the 6 parameters of each board
    pose and, with ``refine_intrinsics``, the 9 intrinsics ``fx fy cx cy k1 k2
    p1 p2 k3`` of each camera, with :func:`scipy.optimize.least_squares`: a
    robust loss, and a sparse Jacobian by finite differences over its pattern
    (each residual depends on one camera and one board pose), its variables
    whitened block by block so that lsmr converges quickly. When the starting
    errors are many times ``f_scale``, a first pass runs at their scale.

    Parameters
    ----------
    pixels : array_like of shape (C, T, N, 2)
        Detected corners per camera and frame, distorted pixels; NaN where unseen.
    board : Board
    rig : CameraRig
        Starting cameras (C).
    board2world : array_like of shape (T, 4, 4)
        Starting board poses; NaN for frames to leave out.
    refine_intrinsics : bool
        Refine each camera's matrix and distortions too.
    fix_k3 : bool
        With ``refine_intrinsics``, keep each camera's k3 as it is.
    loss : str
        Robust loss of :func:`scipy.optimize.least_squares` (``soft_l1`` by default).
    f_scale : float
        Pixel error at which the robust loss starts to discount, pixels.
    max_nfev : int, optional
        Most function evaluations (default: scipy's).

    Returns
    -------
    BundleAdjustment

    Raises
    ------
    HandcapError
        If shapes disagree, ``loss`` is unknown, or no corner is observed.
    """
    pixels = np.asarray(pixels, dtype=np.float64)
    board2world = np.asarray(board2world, dtype=np.float64)
    c_count = len(rig)
    if pixels.ndim != 4 or pixels.shape[0] != c_count or pixels.shape[2:] != (board.n_corners, 2):
        raise HandcapError(f"pixels must have shape (C={c_count}, T, N={board.n_corners}, 2), got {pixels.shape}")
    t_count = pixels.shape[1]
    if board2world.shape != (t_count, 4, 4):
        raise HandcapError(f"board2world must have shape (T={t_count}, 4, 4), got {board2world.shape}")
    if loss not in LOSSES:
        raise HandcapError(f"loss must be one of {', '.join(LOSSES)}, got {loss!r}")
    if not (np.isfinite(f_scale) and f_scale > 0):
        raise HandcapError(f"f_scale must be a positive number of pixels, got {f_scale!r}")

    # A board pose no camera saw stays out (it would be free); it comes back NaN.
    posed = np.isfinite(board2world).all(axis=(1, 2)) & np.isfinite(pixels[..., 0]).any(axis=(0, 2))
    frame_of = -np.ones(t_count, dtype=np.int64)
    frame_of[posed] = np.arange(posed.sum())
    cam_idx, t_idx, n_idx = np.nonzero(np.isfinite(pixels[..., 0]) & posed[None, :, None])
    observed = pixels[cam_idx, t_idx, n_idx]
    board_idx = frame_of[t_idx]
    k_count, f_count = len(cam_idx), int(posed.sum())
    if k_count == 0:
        raise HandcapError("no corner is seen in a frame with a board pose: nothing to adjust")

    # Work in the frame of the first camera, whose pose stays fixed. A camera is
    # (rotation vector, centre) with x_camera = R (x - centre), a board pose
    # (rotation vector, position of the board's middle): turning either then
    # moves no centre, which keeps the problem well conditioned.
    cameras = list(rig)
    first = cameras[0].world2camera
    ref2world = _invert(first)
    middle = board.object_points.mean(axis=0)
    local = board.object_points - middle
    others = np.array([c.world2camera @ ref2world for c in cameras[1:]]).reshape(-1, 4, 4)
    camera_start = np.concatenate([axis_angle_from_matrix(others[:, :3, :3]),
                                   -np.einsum("cji,cj->ci", others[:, :3, :3], others[:, :3, 3])], axis=1)
    boards_ref = first @ board2world[posed]
    board_start = np.concatenate([axis_angle_from_matrix(boards_ref[:, :3, :3]),
                                  boards_ref[:, :3, :3] @ middle + boards_ref[:, :3, 3]], axis=1)
    intrinsic_start = np.array([_intrinsic_vector(c) for c in cameras])
    free = np.ones(9, dtype=bool)
    free[8] = not fix_k3
    per = int(free.sum()) if refine_intrinsics else 0
    n_cam, n_board = 6 * (c_count - 1), 6 * f_count
    x0 = np.concatenate([camera_start.ravel(), board_start.ravel(),
                         intrinsic_start[:, free].ravel() if refine_intrinsics else []])

    def unpack(x):
        cam = np.vstack([np.zeros((1, 6)), x[:n_cam].reshape(-1, 6)])
        boards = x[n_cam:n_cam + n_board].reshape(-1, 6)
        intr = intrinsic_start.copy()
        if refine_intrinsics:
            intr[:, free] = x[n_cam + n_board:].reshape(c_count, per)
        return cam, boards, intr

    def residuals(x):
        cam, boards, intr = unpack(x)
        cam_rot = np.asarray(matrix_from_axis_angle(cam[:, :3]))
        board_rot = np.asarray(matrix_from_axis_angle(boards[:, :3]))
        world = np.einsum("kij,kj->ki", board_rot[board_idx], local[n_idx]) + boards[board_idx, 3:]
        camera_points = np.einsum("kij,kj->ki", cam_rot[cam_idx], world - cam[cam_idx, 3:])
        return (_project(camera_points, intr[cam_idx]) - observed).ravel()

    # Each residual pair depends on one camera's pose (none for the first
    # camera), one board pose and that camera's intrinsics.
    columns = [6 * (cam_idx[:, None] - 1) + np.arange(6), n_cam + 6 * board_idx[:, None] + np.arange(6)]
    if refine_intrinsics:
        columns.append(n_cam + n_board + per * cam_idx[:, None] + np.arange(per))
    columns = np.concatenate(columns, axis=1)
    valid = np.ones(columns.shape, dtype=bool)
    valid[:, :6] = cam_idx[:, None] > 0
    columns[~valid] = 0
    rows = np.broadcast_to(np.arange(k_count)[:, None], columns.shape)[valid]
    sparsity = coo_matrix((np.ones(2 * len(rows), dtype=np.int8),
                           (np.concatenate([2 * rows, 2 * rows + 1]), np.tile(columns[valid], 2))),
                          shape=(2 * k_count, len(x0))).tocsr()
    # With a sparse Jacobian the steps come from lsmr, an iterative solver that
    # is slow on this ill-conditioned problem (focal length against distance,
    # rotation against principal point, a board's turn against its shift).
    # Whitening each camera's parameters and each board pose by its own block
    # of the starting Jacobian (block-Jacobi preconditioning, a fixed linear
    # change of variables x = P z) makes it converge in far fewer iterations.
    blocks = [np.arange(n_cam + 6 * f, n_cam + 6 * f + 6) for f in range(f_count)]
    for c in range(c_count):
        pose = np.arange(6 * (c - 1), 6 * c) if c else np.arange(0)
        blocks.append(np.concatenate([pose, n_cam + n_board + per * c + np.arange(per)]))
    precondition, condition = _block_whitening(_jacobian(residuals, x0, columns, valid), blocks)
    # Far from the solution (errors of many f_scale) a robust loss is close to
    # L1 and the trust region crawls; a first pass at the scale of the starting
    # errors brings the errors down, the second uses the scale asked for.
    start_scale = float(np.median(np.abs(residuals(x0)))) if k_count else 0.0
    z = condition @ x0  # x = P z; a nonzero start also sizes the first trust region
    for scale in ([4.0 * start_scale] if start_scale > 4.0 * f_scale else []) + [f_scale]:
        result = least_squares(lambda z: residuals(precondition @ z), z, jac_sparsity=sparsity, loss=loss,
                               f_scale=scale, method="trf", tr_solver="lsmr", max_nfev=max_nfev,
                               tr_options={"atol": 1e-8, "btol": 1e-8, "maxiter": 10 * len(x0)})
        z = result.x
    x = precondition @ z

    cam, boards, intr = unpack(x)
    cam_rot = np.asarray(matrix_from_axis_angle(cam[:, :3]))
    world2camera = _transform(cam_rot, -np.einsum("cij,cj->ci", cam_rot, cam[:, 3:])) @ first
    new_cameras = []
    for c, camera in enumerate(cameras):
        fx, fy, cx, cy = intr[c, :4]
        matrix = np.array([[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]])
        new_cameras.append(Camera(camera.name, camera.size, matrix, intr[c, 4:],
                                  axis_angle_from_matrix(world2camera[c, :3, :3]), world2camera[c, :3, 3]))
    board_rot = np.asarray(matrix_from_axis_angle(boards[:, :3]))
    refined = np.full((t_count, 4, 4), np.nan)
    refined[posed] = ref2world @ _transform(board_rot, boards[:, 3:] - board_rot @ middle)
    errors = np.full(pixels.shape[:3], np.nan)
    errors[cam_idx, t_idx, n_idx] = np.linalg.norm(residuals(x).reshape(-1, 2), axis=1)
    return BundleAdjustment(CameraRig(new_cameras), refined, errors, bool(result.success))


# -- the rig ---------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class RigCalibration:
    """A calibrated rig and the numbers that say how good it is.

    Attributes
    ----------
    rig : CameraRig
        The cameras in the world frame chosen by ``origin`` (module docstring).
    board2world : ndarray of shape (T, 4, 4)
        Board pose at each frame, metres; NaN where no camera saw it.
    errors : ndarray of shape (C, T, N)
        Final reprojection error of every corner used, pixels; NaN elsewhere.
    rms : ndarray of shape (C,)
        Final reprojection RMS per camera, pixels.
    start_rms : ndarray of shape (C,)
        Reprojection RMS per camera before the bundle adjustment, pixels.
    intrinsic_rms : ndarray of shape (C,)
        RMS of each camera's own intrinsic calibration (NaN for given cameras).
    views : ndarray of int, shape (C,)
        Frames in which each camera saw the board and the view was used.
    shared_views : ndarray of int, shape (C, C)
        Frames in which both cameras of a pair saw the board.
    tree : tuple of (int, int)
        The (parent, child) camera pairs whose relative poses placed the cameras.
    origin : str
        The world frame, in words.
    frames : ndarray of int, shape (T,)
        The frame numbers (of the first camera's source).
    """

    rig: CameraRig
    board2world: np.ndarray
    errors: np.ndarray
    rms: np.ndarray
    start_rms: np.ndarray
    intrinsic_rms: np.ndarray
    views: np.ndarray
    shared_views: np.ndarray
    tree: tuple[tuple[int, int], ...]
    origin: str
    frames: np.ndarray

    @property
    def names(self) -> tuple[str, ...]:
        return self.rig.names

    def summary(self) -> str:
        """A few lines for a person: per camera views, focal length, intrinsic and rig RMS."""
        names = self.names
        width = max(6, *(len(n) for n in names))
        lines = [f"{len(names)} cameras, board seen at {int(np.isfinite(self.board2world[:, 0, 0]).sum())} of "
                 f"{len(self.frames)} instants; world: {self.origin}",
                 f"{'camera':<{width}}  views  f (px)   intrinsic RMS  start RMS  rig RMS (px)  placed from"]
        parent = {child: p for p, child in self.tree}
        for c, camera in enumerate(self.rig):
            placed = "origin" if c not in parent else f"{names[parent[c]]} ({self.shared_views[parent[c], c]} shared)"
            intrinsic = "given" if np.isnan(self.intrinsic_rms[c]) else f"{self.intrinsic_rms[c]:.3f}"
            lines.append(f"{names[c]:<{width}}  {self.views[c]:5d}  {camera.matrix[0, 0]:7.1f}  {intrinsic:>13}  "
                         f"{self.start_rms[c]:9.3f}  {self.rms[c]:12.3f}  {placed}")
        return "\n".join(lines)

    def __repr__(self) -> str:
        return f"RigCalibration({', '.join(f'{n}: {r:.2f} px' for n, r in zip(self.names, self.rms))})"


def _camera_names(detections, names) -> list[str]:
    if names is not None:
        names = [str(n) for n in names]
        if len(names) != len(detections):
            raise HandcapError(f"{len(names)} camera names for {len(detections)} cameras; give one name per camera")
        return names
    stems = [Path(d.source).stem or f"cam_{i}" for i, d in enumerate(detections)]
    return stems if len(set(stems)) == len(stems) else [f"cam_{i}" for i in range(len(detections))]


def _spanning_tree(shared: np.ndarray, root: int = 0) -> tuple[list[tuple[int, int]], list[int]]:
    """Maximum spanning tree (Prim) over cameras weighted by shared views; returns edges and unreached cameras."""
    c_count = len(shared)
    placed = {root}
    edges = []
    while True:
        best = (0, None, None)
        for p in placed:
            for c in range(c_count):
                if c not in placed and shared[p, c] > best[0]:
                    best = (shared[p, c], p, c)
        if best[1] is None:
            break
        edges.append((best[1], best[2]))
        placed.add(best[2])
    return edges, [c for c in range(c_count) if c not in placed]


def calibrate_rig(detections: Sequence[BoardDetections], *, names: Sequence[str] | None = None,
                  cameras: Sequence[Camera] | CameraRig | None = None, refine_intrinsics: bool | None = None,
                  fix_k3: bool = False, origin: str = "board", origin_frame: int | None = None,
                  loss: str = "soft_l1", f_scale: float = 1.0) -> RigCalibration:
    """Calibrate a rig of cameras that filmed the same board at the same instants.

    Parameters
    ----------
    detections : sequence of BoardDetections
        One per camera (C >= 2), from synchronised recordings: frame ``t`` of
        every camera shows the same instant, so all have the same frames.
    names : sequence of str, optional
        Camera names (default: the sources' file names, or ``cam_0``, ...).
    cameras : sequence of Camera or CameraRig, optional
        Known intrinsics (matrix, distortions), one camera per detections; by
        default each camera is calibrated from its own views first
        (:func:`calibrate_intrinsics`). Their extrinsics are not used.
    refine_intrinsics : bool, optional
        Refine every camera's intrinsics in the bundle adjustment too. By
        default they are refined when calibrated here (a board filmed for the
        rig seldom fills the image as an intrinsic calibration should; every
        camera seeing the same board poses pins them far better) and kept
        when ``cameras`` gives them.
    fix_k3 : bool
        Keep k3 = 0 in the intrinsic calibrations (and fixed in the adjustment).
    origin : {"board", "camera"}
        The world frame (module docstring).
    origin_frame : int, optional
        With ``origin="board"``: the frame number (as in ``detections[0].frames``)
        whose board pose is the world; default the first frame in which the
        first camera sees the board.
    loss, f_scale
        Robust loss and its scale in pixels, see :func:`bundle_adjust`.

    Returns
    -------
    RigCalibration

    Raises
    ------
    HandcapError
        Fewer than two cameras; different boards or frame counts (the cameras
        are named with their counts); a camera that never sees the board (named
        with its source); cameras that share no board view with the first one,
        directly or through others (all named); a checkerboard whose
        orientation is ambiguous; a bad option.
    """
    detections = list(detections)
    if len(detections) < 2:
        raise HandcapError(f"a rig needs at least two cameras, got {len(detections)}")
    for d in detections:
        if not isinstance(d, BoardDetections):
            raise HandcapError(f"calibrate_rig needs BoardDetections per camera, got {type(d).__name__}")
    if origin not in ORIGINS:
        raise HandcapError(f"origin must be one of {', '.join(ORIGINS)}, got {origin!r}")
    names = _camera_names(detections, names)
    if len(set(names)) != len(names):
        raise HandcapError(f"camera names must be unique, got {', '.join(names)}")
    board = detections[0].board
    for name, d in zip(names, detections):
        if d.board != board:
            raise HandcapError(f"camera {name} ({d.source}) looked for {d.board.spec}, the first camera for "
                               f"{board.spec}; all cameras must look for the same board")
    if board.kind == "checkerboard" and (board.columns + board.rows) % 2 == 0:
        raise HandcapError(f"a {board.columns}x{board.rows} checkerboard looks the same turned half round, so "
                           f"cameras could number its corners differently; use a board with an odd and an even "
                           f"number of inner corners (e.g. 9x6) or a charuco board")
    counts = [d.n_frames for d in detections]
    if len(set(counts)) > 1 or any(not np.array_equal(d.frames, detections[0].frames) for d in detections):
        listing = ", ".join(f"{n} ({d.source}) {c}" for n, d, c in zip(names, detections, counts))
        raise HandcapError(f"cameras have different frame counts: {listing}; synchronised recordings need the "
                           f"same frames from every camera")
    never = [f"{n} ({d.source})" for n, d in zip(names, detections) if not d.found.any()]
    if never:
        raise HandcapError(f"the board {board.spec} is never seen by camera {', '.join(never)}; check the board "
                           f"spec and that the camera films it")
    if refine_intrinsics is None:
        refine_intrinsics = cameras is None
    if cameras is not None:
        cameras = list(cameras)
        if len(cameras) != len(detections):
            raise HandcapError(f"{len(cameras)} cameras given for {len(detections)} recordings; give one per camera")
    c_count, t_count = len(detections), counts[0]

    # 1. intrinsics of each camera and the views they keep
    used = np.zeros((c_count, t_count), dtype=bool)
    intrinsic_rms = np.full(c_count, np.nan)
    start = []
    for c, (name, d) in enumerate(zip(names, detections)):
        if cameras is None:
            intrinsics = calibrate_intrinsics(d, name=name, fix_k3=fix_k3)
            intrinsic_rms[c] = intrinsics.rms
            used[c] = d.found
            used[c, intrinsics.rejected] = False
            camera = intrinsics.camera
        else:
            given = cameras[c]
            if not isinstance(given, Camera):
                raise HandcapError(f"cameras must be Camera objects, got {type(given).__name__}")
            if tuple(given.size) != tuple(d.size):
                raise HandcapError(f"camera {name}: given intrinsics are for {given.size[0]}x{given.size[1]} px "
                                   f"but {d.source} is {d.size[0]}x{d.size[1]}")
            camera = given
            used[c] = d.found
        start.append(Camera(name, camera.size, camera.matrix, camera.distortions))

    # 2. board pose in every used view
    board2camera = np.full((c_count, t_count, 4, 4), np.nan)
    pnp_rms = np.full((c_count, t_count), np.nan)
    for c, d in enumerate(detections):
        board2camera[c], pnp_rms[c] = board_poses(d, start[c], views=np.flatnonzero(used[c]))
    used &= np.isfinite(pnp_rms)
    good = used & (pnp_rms < _PNP_START_RMS_PX)
    lost = [f"{names[c]} ({detections[c].source})" for c in range(c_count) if not used[c].any()]
    if lost:
        raise HandcapError(f"no usable board view in camera {', '.join(lost)}")

    # 3. relative poses of camera pairs and a spanning tree from the first camera
    shared = (good[:, None, :] & good[None, :, :]).sum(axis=2)
    np.fill_diagonal(shared, 0)
    edges, unreached = _spanning_tree(shared)
    if unreached:
        connected = [names[c] for c in range(c_count) if c not in unreached]
        which = ", ".join(names[c] for c in unreached)
        raise HandcapError(f"{'camera ' + which + ' shares' if len(unreached) == 1 else 'cameras ' + which + ' share'}"
                           f" no board view with {', '.join(connected)} (directly or through other cameras), so "
                           f"{'it' if len(unreached) == 1 else 'they'} cannot be placed; film the board where the "
                           f"cameras overlap")
    world2camera = np.full((c_count, 4, 4), np.nan)
    world2camera[0] = np.eye(4)  # start in the first camera's frame
    for parent, child in edges:
        both = np.flatnonzero(good[parent] & good[child])
        child2parent = board2camera[parent, both] @ _invert(board2camera[child, both])
        world2camera[child] = _invert(_robust_mean_pose(child2parent)) @ world2camera[parent]

    # 4. board pose at each instant from the camera that sees most corners
    seen = np.isfinite(np.stack([d.pixels[..., 0] for d in detections])).sum(axis=2) * good
    board2ref = np.full((t_count, 4, 4), np.nan)
    for t in np.flatnonzero(seen.max(axis=0) > 0):
        c = int(np.argmax(seen[:, t]))
        board2ref[t] = _invert(world2camera[c]) @ board2camera[c, t]

    pixels = np.stack([d.pixels for d in detections])
    pixels = np.where(used[..., None, None], pixels, np.nan)
    rig = CameraRig([Camera(s.name, s.size, s.matrix, s.distortions, axis_angle_from_matrix(w[:3, :3]), w[:3, 3])
                     for s, w in zip(start, world2camera)])
    start_errors = _reprojection_errors(pixels, board, rig, board2ref)

    # 5. bundle adjustment of everything
    adjusted = bundle_adjust(pixels, board, rig, board2ref, refine_intrinsics=refine_intrinsics,
                             fix_k3=fix_k3, loss=loss, f_scale=f_scale)

    # 6. the world frame
    if origin == "camera":
        description = f"camera {names[0]} (x right, y down, z along its optical axis)"
        ref2world = np.eye(4)
    else:
        posed = np.isfinite(adjusted.board2world[:, 0, 0])
        frames = detections[0].frames
        if origin_frame is None:
            candidates = np.flatnonzero(used[0] & posed)
            position = int(candidates[0]) if len(candidates) else int(np.flatnonzero(posed)[0])
        else:
            matches = np.flatnonzero(frames == origin_frame) if isinstance(origin_frame, (int, np.integer)) \
                and not isinstance(origin_frame, bool) else []
            if len(matches) == 0 or not posed[matches[0]]:
                seen = frames[posed]
                raise HandcapError(f"origin_frame {origin_frame!r} is not a frame in which a camera sees the board; "
                                   f"those are {_ranges(seen)}")
            position = int(matches[0])
        # x along the board, z out of its printed face: the board frame turned half round about x.
        flip = np.diag([1.0, -1.0, -1.0, 1.0])
        ref2world = flip @ _invert(adjusted.board2world[position])
        description = f"the board at frame {int(frames[position])} (x along the board, z out of its printed face)"
    world2ref = _invert(ref2world)
    final = CameraRig([Camera(c.name, c.size, c.matrix, c.distortions,
                              axis_angle_from_matrix((c.world2camera @ world2ref)[:3, :3]),
                              (c.world2camera @ world2ref)[:3, 3]) for c in adjusted.rig])
    board2world = ref2world @ adjusted.board2world
    views = np.isfinite(adjusted.errors).any(axis=2).sum(axis=1)
    return RigCalibration(final, board2world, adjusted.errors, adjusted.rms, _rms(start_errors), intrinsic_rms,
                          views, shared, tuple(edges), description, detections[0].frames.copy())


def _ranges(frames) -> str:
    """'0-12, 15, 20-31' for sorted frame numbers."""
    frames = [int(f) for f in frames]
    parts, begin = [], None
    for i, f in enumerate(frames):
        begin = f if begin is None else begin
        if i + 1 == len(frames) or frames[i + 1] != f + 1:
            parts.append(str(f) if begin == f else f"{begin}-{f}")
            begin = None
    return ", ".join(parts) if parts else "none"


def _reprojection_errors(pixels: np.ndarray, board: Board, rig: CameraRig, board2world: np.ndarray) -> np.ndarray:
    """Pixel distance (C, T, N) between detected corners and the board projected through the rig."""
    points = np.einsum("tij,nj->tni", board2world[:, :3, :3], board.object_points) + board2world[:, None, :3, 3]
    projected, _ = rig.project(points)
    return np.linalg.norm(projected - pixels, axis=-1)


__all__ = ["BundleAdjustment", "Intrinsics", "RigCalibration", "board_poses", "bundle_adjust",
           "calibrate_intrinsics", "calibrate_rig"]
