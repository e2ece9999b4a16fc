"""Bundle adjustment of a camera rig and the board poses (sparse least squares with a robust loss, Triggs
et al. 2000); see :mod:`handcap.multiview.calibration`."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import least_squares
from scipy.sparse import coo_matrix

from handcap.core.cameras import Camera, CameraRig
from handcap.core.errors import HandcapError
from handcap.core.rotations import axis_angle_from_matrix, matrix_from_axis_angle
from handcap.core.transforms import homogeneous, invert_homogeneous
from handcap.multiview.boards import Board

LOSSES = ("linear", "huber", "soft_l1", "cauchy", "arctan")
# Forward-difference step, relative to max(1, |parameter|) (about sqrt of float64's eps).
_FD_STEP = 1.5e-8
# Smallest eigenvalue, relative to the largest, that block whitening inverts.
_WHITENING_FLOOR = 1e-8


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
        return view_rms(self.errors)


def view_rms(errors: np.ndarray) -> np.ndarray:
    """Reprojection RMS of each camera over all its observations.

    Parameters
    ----------
    errors : ndarray of shape (C, ...)
        Reprojection errors, pixels, NaN where unobserved (e.g. (C, T, N)).

    Returns
    -------
    ndarray of shape (C,)
        Pixels; NaN for a camera with no observation.
    """
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
    ref2world = invert_homogeneous(first)
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
    world2camera = homogeneous(cam_rot, -np.einsum("cij,cj->ci", cam_rot, cam[:, 3:])) @ first
    new_cameras = []
    for c, camera in enumerate(cameras):
        fx, fy, cx, cy = intr[c, :4]
        matrix = np.array([[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]])
        new_cameras.append(Camera(camera.name, camera.size, matrix, intr[c, 4:],
                                  axis_angle_from_matrix(world2camera[c, :3, :3]), world2camera[c, :3, 3]))
    board_rot = np.asarray(matrix_from_axis_angle(boards[:, :3]))
    refined = np.full((t_count, 4, 4), np.nan)
    refined[posed] = ref2world @ homogeneous(board_rot, boards[:, 3:] - board_rot @ middle)
    errors = np.full(pixels.shape[:3], np.nan)
    errors[cam_idx, t_idx, n_idx] = np.linalg.norm(residuals(x).reshape(-1, 2), axis=1)
    return BundleAdjustment(CameraRig(new_cameras), refined, errors, bool(result.success))
