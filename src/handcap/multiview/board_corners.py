"""Calibration boards found in one image: the board's corners, in an order every camera shares.

A checkerboard's corners are put in one canonical order, so every camera
names the same physical corner alike (needed for a rig): the image
orientation of (x, y) is that of a board seen from its printed side, and the
square between corners 0, 1, COLS and COLS + 1 is the dark one. That is
unambiguous only when COLS + ROWS is odd (a 9 x 6 board, not 8 x 6), which
:func:`handcap.multiview.calibration.calibrate_rig` therefore requires.
ChArUco corners carry their identity in the markers; a board seen from behind
through a transparent backing (one of caliscope's cameras) is found by
looking again in the mirrored image.

Corners are pixels ``(N, 2)`` (OpenCV's convention, the centre of the top-left
pixel at (0, 0)), N corners of the board (see :mod:`~handcap.multiview.board_spec`
for the board frame), NaN where a corner was not found. A view counts only
with at least ``min_corners`` corners (all of them for a checkerboard, 6 for a
ChArUco board) not all on one line; otherwise the whole view is NaN.
"""

from __future__ import annotations

import cv2
import numpy as np

from handcap.core.errors import HandcapError
from handcap.multiview.board_spec import Board, parse_board

# Checkerboards are searched for in a copy no larger than this (pixels along
# the longer side) and refined at full resolution: the search costs seconds on
# a 2-megapixel photo and a tenth of that on the copy.
_COARSE_SIDE = 1000
_SUBPIX_CRITERIA = (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 50, 1e-3)


def detect_board(image, board: Board, *, mirrored: bool = True) -> np.ndarray:
    """Find the board's corners in one image.

    Parameters
    ----------
    image : ndarray of shape (H, W) or (H, W, 3)
        8-bit grey or BGR image (as :func:`cv2.imread` gives it).
    board : Board or str
    mirrored : bool
        ChArUco only: when the board is not found, look in the mirrored image
        too (a board seen from behind through a transparent backing).

    Returns
    -------
    pixels : ndarray of shape (N, 2)
        Corner pixels, NaN for corners not found; all NaN when the board is
        not seen (fewer than ``board.min_corners`` corners, or all on a line).
    """
    board = parse_board(board)
    return find_corners(gray_image(image), board, mirrored=mirrored)


def gray_image(image) -> np.ndarray:
    """The image as OpenCV's detectors take it: 8-bit grey.

    Parameters
    ----------
    image : ndarray of shape (H, W), (H, W, 1), (H, W, 3) or (H, W, 4)
        8-bit (or 16-bit, whose high byte is kept) grey, BGR or BGRA image.

    Returns
    -------
    gray : ndarray of uint8, shape (H, W)

    Raises
    ------
    HandcapError
        If the image is not 8- or 16-bit, or not of one of these shapes.
    """
    image = np.asarray(image)
    if image.dtype != np.uint8 and image.size:
        if image.dtype == np.uint16:
            image = (image >> 8).astype(np.uint8)
        else:
            raise HandcapError(f"images must be 8-bit, got {image.dtype}")
    if image.ndim == 3 and image.shape[2] == 3:
        return cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)
    if image.ndim == 3 and image.shape[2] == 4:
        return cv2.cvtColor(image, cv2.COLOR_BGRA2GRAY)
    if image.ndim == 3 and image.shape[2] == 1:
        return image[..., 0]
    if image.ndim != 2:
        raise HandcapError(f"an image must be (H, W) grey or (H, W, 3) colour, got shape {image.shape}")
    return image


def _checkerboard(gray: np.ndarray, board: Board) -> np.ndarray:
    out = np.full((board.n_corners, 2), np.nan)
    h, w = gray.shape
    scale = min(1.0, _COARSE_SIDE / max(h, w))
    small = gray if scale == 1.0 else cv2.resize(gray, (round(w * scale), round(h * scale)),
                                                 interpolation=cv2.INTER_AREA)
    pattern = board.grid
    found, corners = cv2.findChessboardCorners(small, pattern,
                                               flags=cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE)
    if not found:  # the sector-based detector is slower but finds harder views
        found, corners = cv2.findChessboardCornersSB(small, pattern, flags=cv2.CALIB_CB_NORMALIZE_IMAGE
                                                     | cv2.CALIB_CB_EXHAUSTIVE | cv2.CALIB_CB_ACCURACY)
    if not found:
        return out
    corners = corners.reshape(-1, 2).astype(np.float64)
    if small is not gray:  # pixel centres: u_full + 0.5 = (u_small + 0.5) * w / w_small
        corners = (corners + 0.5) * np.array([w / small.shape[1], h / small.shape[0]]) - 0.5
    # Refine at full resolution in a window smaller than half a square.
    grid = corners.reshape(pattern[1], pattern[0], 2)
    spacing = min(np.linalg.norm(np.diff(grid, axis=0), axis=-1).min(),
                  np.linalg.norm(np.diff(grid, axis=1), axis=-1).min())
    half = int(np.clip(spacing / 3.0, 2, 15))
    # A window reaching past the image's edge pulls the corner towards it, so
    # corners near the edge get a smaller one (or are dropped with the view).
    border = np.minimum(corners, np.array([w - 1, h - 1]) - corners).min(axis=1)
    halves = np.minimum(half, np.floor(border - 1.0)).astype(int)
    if halves.min() < 2:
        return out
    refined = corners.copy()
    for size in np.unique(halves):
        chosen = halves == size
        refined[chosen] = cv2.cornerSubPix(gray, corners[chosen].astype(np.float32).reshape(-1, 1, 2),
                                           (int(size), int(size)), (-1, -1), _SUBPIX_CRITERIA).reshape(-1, 2)
    return _canonical_checkerboard(gray, refined, pattern)


def _canonical_checkerboard(gray: np.ndarray, corners: np.ndarray, pattern: tuple[int, int]) -> np.ndarray:
    """Reorder checkerboard corners (N, 2) so every view names the corners alike (module docstring)."""
    cols, rows = pattern
    grid = corners.reshape(rows, cols, 2)
    # Seen from the printed side, x (along a row) turns clockwise onto y in the
    # image (u right, v down); OpenCV may return the mirrored order.
    dx, dy = grid[0, -1] - grid[0, 0], grid[-1, 0] - grid[0, 0]
    if dx[0] * dy[1] - dx[1] * dy[0] < 0:
        grid = grid[:, ::-1]
    # The square between corners 0, 1, COLS, COLS + 1 is dark: compare the mean
    # grey of the squares of its parity with that of the others.
    centres = (grid[:-1, :-1] + grid[:-1, 1:] + grid[1:, :-1] + grid[1:, 1:]) / 4.0
    blurred = cv2.blur(gray, (3, 3))
    u = np.clip(np.round(centres[..., 0]).astype(int), 0, gray.shape[1] - 1)
    v = np.clip(np.round(centres[..., 1]).astype(int), 0, gray.shape[0] - 1)
    grey = blurred[v, u].astype(np.float64)
    parity = (np.add.outer(np.arange(rows - 1), np.arange(cols - 1)) % 2) == 0
    if grey[parity].mean() > grey[~parity].mean():
        grid = grid[::-1, ::-1]
    return grid.reshape(-1, 2).copy()


def find_corners(gray: np.ndarray, board: Board, *, mirrored: bool = True, detector=None) -> np.ndarray:
    """Find the corners of a parsed board in one grey image (:func:`detect_board` without the checks).

    Parameters
    ----------
    gray : ndarray of uint8, shape (H, W)
        8-bit grey image (see :func:`gray_image`).
    board : Board
    mirrored : bool
        See :func:`detect_board`.
    detector : cv2.aruco.CharucoDetector, optional
        ChArUco only: from :func:`charuco_detector`, made once for many frames (default: a new one).

    Returns
    -------
    pixels : ndarray of shape (N, 2)
        Corner pixels, NaN for corners not found; all NaN when the board is not seen.
    """
    if board.kind == "checkerboard":
        return _checkerboard(gray, board)
    return _charuco(gray, board, mirrored=mirrored, detector=detector)


def charuco_detector(board: Board):
    """OpenCV's detector of a ChArUco board, to make once and reuse for every frame.

    Parameters
    ----------
    board : Board
        A ChArUco board.

    Returns
    -------
    cv2.aruco.CharucoDetector

    Raises
    ------
    HandcapError
        If the board is not a ChArUco board.
    """
    return cv2.aruco.CharucoDetector(board.opencv_charuco())


def _charuco(gray: np.ndarray, board: Board, *, mirrored: bool, detector=None) -> np.ndarray:
    detector = charuco_detector(board) if detector is None else detector
    if board.inverted:
        gray = cv2.bitwise_not(gray)
    out = _charuco_once(gray, board, detector)
    if mirrored and np.isnan(out[:, 0]).all():
        flipped = _charuco_once(cv2.flip(gray, 1), board, detector)
        flipped[:, 0] = gray.shape[1] - 1 - flipped[:, 0]  # pixel u of the mirror is w - 1 - u
        out = flipped
    return out


def _charuco_once(gray: np.ndarray, board: Board, detector) -> np.ndarray:
    out = np.full((board.n_corners, 2), np.nan)
    corners, ids, _, _ = detector.detectBoard(gray)
    if ids is None or len(ids) < board.min_corners:
        return out
    ids = ids.reshape(-1)
    if len(np.unique(ids)) != len(ids) or ids.min() < 0 or ids.max() >= board.n_corners:
        return out
    # Corners all on one row or column do not fix a pose.
    points = board.object_points[ids, :2]
    if np.linalg.svd(points - points.mean(axis=0), compute_uv=False)[1] < 0.5 * board.square:
        return out
    out[ids] = corners.reshape(-1, 2)
    return out


__all__ = ["charuco_detector", "detect_board", "find_corners", "gray_image"]
