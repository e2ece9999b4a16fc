"""Calibration boards: their specification and their detection in images and videos.

A board is written as one string, as on the command line:

* ``checkerboard:COLSxROWS:SQUARE_M`` -- a chessboard with COLS x ROWS *inner*
  corners (OpenCV's ``patternSize``) and squares of SQUARE_M metres;
* ``charuco:COLSxROWS:SQUARE_M[:MARKER_M][:DICT][:inverted][:legacy]`` -- a
  ChArUco board of COLS x ROWS *squares* (OpenCV's ``CharucoBoard`` size).
  MARKER_M is the side of the ArUco markers, 0.75 x the square by default (the
  ``aruco_scale`` of caliscope's boards); DICT an OpenCV predefined dictionary,
  ``DICT_4X4_1000`` by default (the 4x4 dictionaries of 50, 100 and 250 markers
  are its first markers, so it reads those boards too); ``inverted`` means
  white markers on black, as caliscope prints them (the image is inverted
  before detection); ``legacy`` the pattern of OpenCV before 4.6 (it differs
  for an even number of rows).

Example: caliscope's 4 x 5 board of 5.4 cm squares is
``charuco:4x5:0.054:0.0405:DICT_4X4_1000:inverted``.

Board frame (written down once)
-------------------------------
Corners lie in the plane z = 0, in metres. Corner ``k`` of a checkerboard sits
at ``(k % COLS, k // COLS) * SQUARE``: corner 0 at the origin, x along a row of
COLS corners, y across the rows; seen from the printed side x runs to the right
and y down, so z points into the board (OpenCV's convention). A ChArUco
board's corners are OpenCV's ``getChessboardCorners``: corner ``k`` at
``(k % (COLS - 1) + 1, k // (COLS - 1) + 1) * SQUARE``, measured from the
board's outer corner.

A checkerboard's corners are put in one canonical order, so every camera
names the same physical corner alike (needed for a rig): the image
orientation of (x, y) is that of a board seen from its printed side, and the
square between corners 0, 1, COLS and COLS + 1 is the dark one. That is
unambiguous only when COLS + ROWS is odd (a 9 x 6 board, not 8 x 6), which
:func:`handcap.multiview.calibration.calibrate_rig` therefore requires.
ChArUco corners carry their identity in the markers; a board seen from behind
through a transparent backing (one of caliscope's cameras) is found by
looking again in the mirrored image.

Detections are dense arrays ``(T, N, 2)`` of pixels (OpenCV's convention, the
centre of the top-left pixel at (0, 0)): T frames (images, or video frames),
N corners of the board, NaN where a corner was not found. A view counts only
with at least ``min_corners`` corners (all of them for a checkerboard, 6 for a
ChArUco board) not all on one line; otherwise the whole frame is NaN.
"""

from __future__ import annotations

import os
import re
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from handcap.core.errors import HandcapError
from handcap.core.files import existing_file

KINDS = ("checkerboard", "charuco")
IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff", ".webp", ".pgm", ".ppm")
DEFAULT_DICTIONARY = "DICT_4X4_1000"
DEFAULT_MARKER_SCALE = 0.75
# ChArUco views with fewer corners are dropped (a homography has 8 unknowns;
# six corners not on one line pin a pose well enough to start from).
MIN_CHARUCO_CORNERS = 6
# Checkerboards are searched for in a copy no larger than this (pixels along
# the longer side) and refined at full resolution: the search costs seconds on
# a 2-megapixel photo and a tenth of that on the copy.
_COARSE_SIDE = 1000
_SUBPIX_CRITERIA = (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 50, 1e-3)


# -- the board -------------------------------------------------------------------------
@dataclass(frozen=True)
class Board:
    """A planar calibration board.

    Parameters
    ----------
    kind : {"checkerboard", "charuco"}
    columns, rows : int
        Inner corners along a row and along a column (checkerboard), or squares
        (ChArUco), as in OpenCV.
    square : float
        Side of a square in metres.
    marker : float, optional
        ChArUco only: side of an ArUco marker in metres, less than ``square``;
        0.75 x ``square`` by default.
    dictionary : str
        ChArUco only: name of an OpenCV predefined ArUco dictionary.
    inverted : bool
        ChArUco only: white markers on black (the image is inverted before detection).
    legacy : bool
        ChArUco only: OpenCV's pattern before version 4.6.

    Raises
    ------
    HandcapError
        If a value is out of range or does not fit the kind of board.

    See Also
    --------
    parse_board : the same from a spec string.
    """

    kind: str
    columns: int
    rows: int
    square: float
    marker: float | None = None
    dictionary: str | None = None
    inverted: bool = False
    legacy: bool = False

    def __post_init__(self):
        if self.kind not in KINDS:
            raise HandcapError(f"board kind must be one of {', '.join(KINDS)}, got {self.kind!r}")
        least = 3
        for what, value in (("columns", self.columns), ("rows", self.rows)):
            if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < least:
                unit = "inner corners" if self.kind == "checkerboard" else "squares"
                raise HandcapError(f"{self.kind} {what} must be a whole number of {unit} >= {least}, got {value!r}")
        object.__setattr__(self, "columns", int(self.columns))
        object.__setattr__(self, "rows", int(self.rows))
        if not _positive(self.square):
            raise HandcapError(f"board square size must be a positive number of metres, got {self.square!r}")
        object.__setattr__(self, "square", float(self.square))
        if self.square > 1.0:
            raise HandcapError(f"board square size is {self.square:g} m; give it in metres (e.g. 0.025 for 25 mm)")
        if self.kind == "checkerboard":
            if self.marker is not None or self.dictionary is not None or self.inverted or self.legacy:
                raise HandcapError("a checkerboard has no markers: marker size, dictionary, inverted and legacy "
                                   "are for charuco boards")
            return
        # The default is rounded so that the spec string reads back the same number.
        marker = float(f"{DEFAULT_MARKER_SCALE * self.square:.12g}") if self.marker is None else self.marker
        if not _positive(marker) or marker >= self.square:
            raise HandcapError(f"charuco marker size must be positive and less than the square "
                               f"({self.square:g} m), got {marker!r}")
        object.__setattr__(self, "marker", float(marker))
        name = DEFAULT_DICTIONARY if self.dictionary is None else _dictionary_name(self.dictionary)
        object.__setattr__(self, "dictionary", name)
        needed = self.columns * self.rows // 2
        available = _aruco_dictionary(name).bytesList.shape[0]
        if needed > available:
            raise HandcapError(f"a {self.columns}x{self.rows} charuco board needs {needed} markers but {name} "
                               f"has {available}; choose a larger dictionary")

    @property
    def n_corners(self) -> int:
        """Number N of corners the board has."""
        if self.kind == "checkerboard":
            return self.columns * self.rows
        return (self.columns - 1) * (self.rows - 1)

    @property
    def grid(self) -> tuple[int, int]:
        """Corners along a row and along a column, (columns, rows) of the corner grid."""
        if self.kind == "checkerboard":
            return self.columns, self.rows
        return self.columns - 1, self.rows - 1

    @property
    def object_points(self) -> np.ndarray:
        """Corner positions (N, 3) in the board frame, metres (z = 0)."""
        across, _ = self.grid
        k = np.arange(self.n_corners)
        offset = 0 if self.kind == "checkerboard" else 1
        points = np.zeros((self.n_corners, 3))
        points[:, 0] = (k % across + offset) * self.square
        points[:, 1] = (k // across + offset) * self.square
        return points

    @property
    def min_corners(self) -> int:
        """Fewest corners that make a view: all for a checkerboard, 6 for ChArUco."""
        return self.n_corners if self.kind == "checkerboard" else min(MIN_CHARUCO_CORNERS, self.n_corners)

    @property
    def spec(self) -> str:
        """The spec string that :func:`parse_board` reads back into this board."""
        text = f"{self.kind}:{self.columns}x{self.rows}:{self.square:.12g}"
        if self.kind == "charuco":
            text += f":{self.marker:.12g}:{self.dictionary}" + (":inverted" if self.inverted else "") \
                + (":legacy" if self.legacy else "")
        return text

    def __str__(self) -> str:
        return self.spec

    def opencv_charuco(self):
        """The board as OpenCV's ``cv2.aruco.CharucoBoard`` (ChArUco only)."""
        if self.kind != "charuco":
            raise HandcapError(f"{self.spec} is not a charuco board")
        board = cv2.aruco.CharucoBoard((self.columns, self.rows), self.square, self.marker,
                                       _aruco_dictionary(self.dictionary))
        board.setLegacyPattern(self.legacy)
        return board


def _positive(value) -> bool:
    return (isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(value, bool)
            and np.isfinite(value) and value > 0)


def _dictionary_name(name) -> str:
    if not isinstance(name, str):
        raise HandcapError(f"ArUco dictionary must be a name such as DICT_4X4_50, got {name!r}")
    key = name.upper() if name.upper().startswith("DICT_") else "DICT_" + name.upper()
    if not isinstance(getattr(cv2.aruco, key, None), int):
        known = ", ".join(sorted(n for n in dir(cv2.aruco) if n.startswith("DICT_") and n == n.upper()))
        raise HandcapError(f"unknown ArUco dictionary {name!r}; OpenCV has {known}")
    return key


def _aruco_dictionary(name: str):
    return cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, name))


_SPEC_FORMS = ("checkerboard:COLSxROWS:SQUARE_M (inner corners) or "
               "charuco:COLSxROWS:SQUARE_M[:MARKER_M][:DICT][:inverted][:legacy] (squares)")


def parse_board(spec: str) -> Board:
    """Read a board from its spec string.

    Parameters
    ----------
    spec : str
        ``checkerboard:9x6:0.025`` or ``charuco:4x5:0.054:0.0405:DICT_4X4_1000:inverted``
        (see the module's docstring). The optional charuco fields may come in
        any order: a number is the marker size, a ``DICT_...`` name the
        dictionary (the ``DICT_`` may be left out), and the words ``inverted``
        and ``legacy`` set those flags.

    Returns
    -------
    Board

    Raises
    ------
    HandcapError
        One line saying what in ``spec`` is wrong and what is expected.
    """
    if isinstance(spec, Board):
        return spec
    if not isinstance(spec, str):
        raise HandcapError(f"board spec must be a string such as checkerboard:9x6:0.025, got {spec!r}")
    fields = [f.strip() for f in spec.strip().split(":")]
    if len(fields) < 3:
        raise HandcapError(f"board spec {spec!r} is incomplete; expected {_SPEC_FORMS}")
    kind = fields[0].lower()
    if kind not in KINDS:
        raise HandcapError(f"board spec {spec!r}: unknown kind {fields[0]!r}; expected {_SPEC_FORMS}")
    match = re.fullmatch(r"(\d+)\s*[xX*]\s*(\d+)", fields[1])
    if match is None:
        raise HandcapError(f"board spec {spec!r}: size {fields[1]!r} must be COLSxROWS, e.g. 9x6")
    columns, rows = int(match[1]), int(match[2])
    square = _number(fields[2], spec, "square size")
    options = {}
    for field in fields[3:]:
        if kind == "checkerboard":
            raise HandcapError(f"board spec {spec!r}: a checkerboard takes only COLSxROWS:SQUARE_M, "
                               f"got the extra field {field!r}")
        word = field.lower()
        if word in ("inverted", "legacy"):
            key, value = word, True
        elif word.startswith("dict_") or re.fullmatch(r"\d+x\d+_\d+|aruco_original|apriltag_\w+|aruco_mip_\w+",
                                                      word):
            key, value = "dictionary", field
        else:
            key, value = "marker", _number(field, spec, "marker size")
        if key in options:
            raise HandcapError(f"board spec {spec!r} gives the {key} twice")
        options[key] = value
    try:
        return Board(kind, columns, rows, square, **options)
    except HandcapError as err:
        raise HandcapError(f"board spec {spec!r}: {err}") from None


def _number(text: str, spec: str, what: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise HandcapError(f"board spec {spec!r}: {what} {text!r} is not a number of metres") from None
    if not np.isfinite(value) or value <= 0:
        raise HandcapError(f"board spec {spec!r}: {what} must be a positive number of metres, got {text!r}")
    return value


# -- detections ------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class BoardDetections:
    """The board's corners as found in the frames of one camera.

    Parameters
    ----------
    board : Board
    pixels : ndarray of shape (T, N, 2)
        Corner pixels per frame, NaN where not found (a whole frame where the
        board was not seen).
    size : (int, int)
        Image width and height in pixels.
    source : str
        Where the frames came from (file or folder), for messages.
    labels : tuple of str
        One name per frame: the image's file name, or ``video.mp4 frame 12``.
    frames : ndarray of int, shape (T,)
        Index of each frame in its source (a video's frame number; an image's
        position in the sorted list). Cameras of a rig are matched by it.
    """

    board: Board
    pixels: np.ndarray
    size: tuple[int, int]
    source: str
    labels: tuple[str, ...]
    frames: np.ndarray

    def __post_init__(self):
        pixels = np.array(self.pixels, dtype=np.float64)
        if pixels.ndim != 3 or pixels.shape[1:] != (self.board.n_corners, 2):
            raise HandcapError(f"{self.source}: board pixels must have shape (T, {self.board.n_corners}, 2), "
                               f"got {pixels.shape}")
        frames = np.array(self.frames, dtype=np.int64).reshape(-1)
        labels = tuple(str(label) for label in self.labels)
        if len(frames) != len(pixels) or len(labels) != len(pixels):
            raise HandcapError(f"{self.source}: {len(pixels)} frames of pixels but {len(frames)} frame numbers "
                               f"and {len(labels)} labels")
        pixels.setflags(write=False)
        frames.setflags(write=False)
        object.__setattr__(self, "pixels", pixels)
        object.__setattr__(self, "frames", frames)
        object.__setattr__(self, "labels", labels)
        object.__setattr__(self, "size", (int(self.size[0]), int(self.size[1])))

    @property
    def n_frames(self) -> int:
        """Number T of frames looked at."""
        return len(self.pixels)

    @property
    def found(self) -> np.ndarray:
        """Whether the board was seen in each frame, bool (T,)."""
        return np.isfinite(self.pixels[..., 0]).any(axis=1)

    def __repr__(self) -> str:
        return (f"BoardDetections({self.source!r}: board in {int(self.found.sum())} of {self.n_frames} frames, "
                f"{self.size[0]}x{self.size[1]} px, {self.board.spec})")


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
    gray = _gray(image)
    if board.kind == "checkerboard":
        return _checkerboard(gray, board)
    return _charuco(gray, board, mirrored=mirrored)


def _gray(image) -> np.ndarray:
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


def _charuco_detector(board: Board):
    return cv2.aruco.CharucoDetector(board.opencv_charuco())


def _charuco(gray: np.ndarray, board: Board, *, mirrored: bool, detector=None) -> np.ndarray:
    detector = _charuco_detector(board) if detector is None else detector
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


# -- files -----------------------------------------------------------------------------
def _natural_key(path: Path):
    return [int(part) if part.isdigit() else part.lower() for part in re.split(r"(\d+)", path.name)]


def is_image_file(path) -> bool:
    """Whether ``path`` has an image suffix (the others are read as videos)."""
    return Path(path).suffix.lower() in IMAGE_SUFFIXES


def image_files(folder) -> list[Path]:
    """The images in ``folder``, in natural order of their names (``img2`` before ``img10``).

    Raises
    ------
    HandcapError
        If the folder does not exist or holds no image.
    """
    folder = Path(folder)
    if not folder.is_dir():
        raise HandcapError(f"{folder}: no such folder")
    files = sorted((p for p in folder.iterdir() if p.is_file() and is_image_file(p)), key=_natural_key)
    if not files:
        raise HandcapError(f"{folder}: no images ({', '.join(IMAGE_SUFFIXES)}) in this folder")
    return files


def _progress(iterable, *, total, desc, progress):
    from tqdm import tqdm

    # disable=None hides the bar when not on a terminal.
    hidden = None if progress is None else not progress
    return tqdm(iterable, total=total, desc=desc, unit="frame", disable=hidden, leave=False)


def detect_in_images(paths: Sequence, board, *, source: str | None = None, mirrored: bool = True,
                     progress: bool | None = None) -> BoardDetections:
    """Find the board in image files, one frame per image.

    Parameters
    ----------
    paths : sequence of str or Path
        Image files, in frame order. All must have the same size.
    board : Board or str
    source : str, optional
        Name of the camera's source for messages (default: the first file's folder).
    mirrored : bool
        See :func:`detect_board`.
    progress : bool, optional
        Show a progress bar; by default only on a terminal.

    Returns
    -------
    BoardDetections
        T = ``len(paths)`` frames; ``frames`` counts from 0.

    Raises
    ------
    HandcapError
        If there is no file, a file is missing or not a readable image, or the
        sizes differ.
    """
    board = parse_board(board)
    paths = [Path(p) for p in paths]
    if not paths:
        raise HandcapError("no images given")
    source = str(paths[0].parent if len(paths) > 1 else paths[0]) if source is None else source
    detector = _charuco_detector(board) if board.kind == "charuco" else None
    pixels, size = [], None
    for path in _progress(paths, total=len(paths), desc=f"board in {Path(source).name}", progress=progress):
        existing_file(path)
        image = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)
        if image is None:
            raise HandcapError(f"{path}: not a readable image")
        this = (image.shape[1], image.shape[0])
        if size is not None and this != size:
            raise HandcapError(f"{path}: image is {this[0]}x{this[1]} px but the earlier images of {source} are "
                               f"{size[0]}x{size[1]}; one camera's images must share one size")
        size = this
        pixels.append(_checkerboard(image, board) if detector is None
                      else _charuco(image, board, mirrored=mirrored, detector=detector))
    return BoardDetections(board, np.stack(pixels), size, source, tuple(p.name for p in paths),
                           np.arange(len(paths)))


def detect_in_video(path, board, *, every: int = 1, mirrored: bool = True,
                    progress: bool | None = None) -> BoardDetections:
    """Find the board in the frames of a video.

    Parameters
    ----------
    path : str or Path
        Any video OpenCV's ``VideoCapture`` reads.
    board : Board or str
    every : int
        Look at every ``every``-th frame only (frames 0, every, 2 every, ...).
    mirrored : bool
        See :func:`detect_board`.
    progress : bool, optional
        Show a progress bar; by default only on a terminal.

    Returns
    -------
    BoardDetections
        One frame per frame looked at; ``frames`` are the video's frame numbers.

    Raises
    ------
    HandcapError
        If the file is missing or not a readable video, or ``every`` < 1.
    """
    board = parse_board(board)
    path = existing_file(path)
    if isinstance(every, bool) or not isinstance(every, (int, np.integer)) or every < 1:
        raise HandcapError(f"every must be a whole number of frames >= 1, got {every!r}")
    capture = cv2.VideoCapture(str(path))
    try:
        if not capture.isOpened():
            raise HandcapError(f"{path}: not a readable video (OpenCV cannot open it)")
        total = int(capture.get(cv2.CAP_PROP_FRAME_COUNT)) or None
        detector = _charuco_detector(board) if board.kind == "charuco" else None
        pixels, frames, size = [], [], None
        bar = _progress(None, total=total, desc=f"board in {path.name}", progress=progress)
        index = 0
        while True:
            if index % every:
                ok = capture.grab()  # skip without converting the frame
            else:
                ok, image = capture.read()
                if ok:
                    gray = _gray(image)
                    size = (gray.shape[1], gray.shape[0])
                    pixels.append(_checkerboard(gray, board) if detector is None
                                  else _charuco(gray, board, mirrored=mirrored, detector=detector))
                    frames.append(index)
            if not ok:
                break
            index += 1
            bar.update(1)
        bar.close()
    finally:
        capture.release()
    if not pixels:
        raise HandcapError(f"{path}: not a readable video (no frame could be decoded)")
    return BoardDetections(board, np.stack(pixels), size, str(path),
                           tuple(f"{path.name} frame {i}" for i in frames), np.array(frames))


def detect_in_files(paths, board, *, every: int = 1, mirrored: bool = True,
                    progress: bool | None = None) -> BoardDetections:
    """Find the board in what one camera recorded: a video, a folder of images, or image files.

    Parameters
    ----------
    paths : str, Path or sequence of them
        One video file; or one folder (its images in natural order of their
        names); or image files in frame order. A file whose suffix is not an
        image's (see ``IMAGE_SUFFIXES``) is read as a video.
    board : Board or str
    every : int
        Videos only: look at every ``every``-th frame.
    mirrored, progress
        See :func:`detect_in_video`.

    Returns
    -------
    BoardDetections

    Raises
    ------
    HandcapError
        Nothing given, several videos or a video mixed with images, a folder
        among other paths, or an unreadable file (named).
    """
    if isinstance(paths, (str, os.PathLike)):
        paths = [paths]
    paths = [Path(p) for p in paths]
    if not paths:
        raise HandcapError("no images or video given")
    if any(p.is_dir() for p in paths):
        if len(paths) > 1:
            raise HandcapError(f"give one folder, or image files, per camera; got {len(paths)} paths "
                               f"with a folder among them ({', '.join(str(p) for p in paths if p.is_dir())})")
        return detect_in_images(image_files(paths[0]), board, source=str(paths[0]), mirrored=mirrored,
                                progress=progress)
    videos = [p for p in paths if not is_image_file(p)]
    if videos:
        if len(paths) > 1:
            raise HandcapError(f"give one video, or image files, per camera; got {len(paths)} files with "
                               f"video(s) {', '.join(str(p) for p in videos)}")
        return detect_in_video(paths[0], board, every=every, mirrored=mirrored, progress=progress)
    return detect_in_images(paths, board, mirrored=mirrored, progress=progress)


__all__ = ["Board", "BoardDetections", "detect_board", "detect_in_files", "detect_in_images", "detect_in_video",
           "image_files", "is_image_file", "parse_board"]
