"""Calibration boards: what a board is, and its spec string.

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

Finding a board in images and videos is in :mod:`~handcap.multiview.board_corners` (one image) and
:mod:`~handcap.multiview.board_recordings` (what one camera recorded).
"""

from __future__ import annotations

import re
from dataclasses import dataclass

import cv2
import numpy as np

from handcap.core.errors import HandcapError

KINDS = ("checkerboard", "charuco")
DEFAULT_DICTIONARY = "DICT_4X4_1000"
DEFAULT_MARKER_SCALE = 0.75
# ChArUco views with fewer corners are dropped (a homography has 8 unknowns;
# six corners not on one line pin a pose well enough to start from).
MIN_CHARUCO_CORNERS = 6


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


__all__ = ["DEFAULT_DICTIONARY", "DEFAULT_MARKER_SCALE", "KINDS", "MIN_CHARUCO_CORNERS", "Board", "parse_board"]
