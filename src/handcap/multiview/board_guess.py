"""What board a recording shows, when it never shows the board it was asked for.

"0 boards detected" is the most common calibration support question of anipose, Pose2Sim and FreeMoCap
(``../shared/anchors/peer-features.md``): the board spec differs from the printed board in a way that is easy
to get wrong and hard to see. :func:`board_hint` looks at a few frames of the recording and names the mistake:

* a ChArUco board: which ArUco dictionary family its markers are from, whether they are white on black
  (``inverted``), and which of the spec's near relatives (columns and rows swapped, the other polarity, the
  other family, OpenCV's pattern before 4.6) finds the board;
* a checkerboard: its squares counted instead of its inner corners, columns and rows swapped, or a ChArUco
  board given as a checkerboard.

The spec it finds is only ever suggested, never used: the user decides.
"""

from __future__ import annotations

import os
import re
from dataclasses import replace
from pathlib import Path

import cv2
import numpy as np

from handcap.core.errors import HandcapError
from handcap.multiview.board_corners import find_corners, gray_image
from handcap.multiview.board_recordings import image_files, is_image_file
from handcap.multiview.board_spec import Board

#: Frames looked at, spread evenly over the recording.
SAMPLES = 8
#: One dictionary of each ArUco family, the largest: the smaller ones of a family are its first markers, so a
#: board of ``DICT_4X4_50`` is found as ``DICT_4X4_1000`` too. The commonest first: the search stops at a family
#: that shows :data:`MIN_MARKERS` markers per frame.
FAMILIES = ("DICT_4X4_1000", "DICT_5X5_1000", "DICT_6X6_1000", "DICT_ARUCO_ORIGINAL", "DICT_7X7_1000",
            "DICT_APRILTAG_36h11")
#: Markers a family must show (over the frames looked at) to be taken for the board's.
MIN_MARKERS = 4
#: Squares along a side of the ChArUco boards tried for the number of markers seen.
SIDES = range(3, 21)


def sample_frames(paths, count: int = SAMPLES) -> list[np.ndarray]:
    """Up to ``count`` grey frames spread evenly over what one camera recorded.

    Parameters
    ----------
    paths : str, Path or sequence of them
        One video, one folder of images, or image files (as :func:`handcap.multiview.boards.detect_in_files`).
    count : int

    Returns
    -------
    list of ndarray of uint8, shape (H, W)
        Frames that could be read (unreadable ones are skipped).
    """
    if isinstance(paths, (str, os.PathLike)):
        paths = [paths]
    paths = [Path(p) for p in paths]
    if len(paths) == 1 and paths[0].is_dir():
        paths = image_files(paths[0])
    if len(paths) == 1 and not is_image_file(paths[0]):
        return _video_frames(paths[0], count)
    chosen = [paths[int(k)] for k in np.unique(np.linspace(0, len(paths) - 1, count).round())] if paths else []
    frames = [cv2.imread(str(p), cv2.IMREAD_UNCHANGED) for p in chosen]
    return [gray_image(f) for f in frames if f is not None]


def _video_frames(path: Path, count: int) -> list[np.ndarray]:
    capture = cv2.VideoCapture(str(path))
    try:
        total = int(capture.get(cv2.CAP_PROP_FRAME_COUNT))
        wanted = set(np.unique(np.linspace(0, max(total - 1, 0), count).round().astype(int)).tolist())
        frames, index = [], 0
        while len(frames) < len(wanted):
            ok, image = capture.read()
            if not ok:
                break
            if index in wanted:
                frames.append(gray_image(image))
            index += 1
        return frames
    finally:
        capture.release()


def aruco_markers(frames, dictionary: str) -> tuple[np.ndarray, np.ndarray]:
    """Markers of ``dictionary`` seen in the frames, as printed and inverted.

    Parameters
    ----------
    frames : list of ndarray of uint8
    dictionary : str
        An OpenCV predefined dictionary's name.

    Returns
    -------
    (ndarray of int, ndarray of int)
        The ids of every marker found in black on white, and in white on black (one per sighting).
    """
    detector = cv2.aruco.ArucoDetector(cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, dictionary)))
    found = ([], [])
    for gray in frames:
        for k, image in enumerate((gray, cv2.bitwise_not(gray))):
            _, ids, _ = detector.detectMarkers(image)
            if ids is not None:
                found[k].extend(int(i) for i in ids.reshape(-1))
    return np.array(found[0], dtype=int), np.array(found[1], dtype=int)


def _seen(frames, board: Board) -> tuple[int, int]:
    """Frames that show ``board``, of those looked at. A checkerboard is looked for by OpenCV's quick test only
    (:func:`handcap.multiview.boards.detect_board` tries harder, seconds per frame where there is none)."""
    if board.kind == "checkerboard":
        flags = cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE | cv2.CALIB_CB_FAST_CHECK
        return sum(bool(cv2.findChessboardCorners(_small(gray), board.grid, flags=flags)[0]) for gray in frames), len(
            frames)
    return sum(bool(np.isfinite(find_corners(gray, board)[:, 0]).any()) for gray in frames), len(frames)


def _small(gray: np.ndarray, side: int = 1000) -> np.ndarray:
    """The frame at most ``side`` pixels long."""
    scale = min(1.0, side / max(gray.shape))
    return gray if scale == 1.0 else cv2.resize(gray, None, fx=scale, fy=scale, interpolation=cv2.INTER_AREA)


def _charuco_family(frames, first: str | None = None) -> tuple[str, bool, int] | None:
    """The ArUco family whose markers the frames show most of (``first``'s family looked at first), whether white
    on black, and the markers the board has by their ids (the highest id seen twice, plus one)."""
    best, most = None, 0
    order = dict.fromkeys([f for f in FAMILIES if first is not None and _family(f) == _family(first)] + list(FAMILIES))
    for family in order:
        for inverted, ids in zip((False, True), aruco_markers(frames, family)):
            if len(ids) >= MIN_MARKERS and len(ids) > most:
                values, counts = np.unique(ids, return_counts=True)
                twice = values[counts >= 2]
                best, most = (family, inverted, int((twice if len(twice) else values).max()) + 1), len(ids)
        if most >= MIN_MARKERS * len(frames):  # plainly this family's: the rarer ones need not be looked at
            break
    return best


def _family(dictionary: str) -> str:
    """``DICT_4X4`` of ``DICT_4X4_250``; other names are their own family."""
    return re.sub(r"^(DICT_\dX\d)_\d+$", r"\1", dictionary)


def _sizes_with(markers: int) -> list[tuple[int, int]]:
    """ChArUco boards (columns, rows of squares) with as many markers as the ids seen say."""
    return [(a, b) for a in SIDES for b in SIDES if a * b // 2 == markers]


def _checkerboards(columns: int, rows: int, square: float) -> list[Board]:
    """Checkerboards of about ``columns`` x ``rows`` inner corners: the larger first (OpenCV finds a smaller grid
    inside a larger board), then the swapped, then the smaller (squares counted instead of inner corners)."""
    sizes = [(columns + 1, rows + 1), (rows + 1, columns + 1), (columns, rows), (rows, columns),
             (columns - 1, rows - 1), (rows - 1, columns - 1)]
    return [Board("checkerboard", a, b, square) for a, b in sizes if min(a, b) >= 3]


def _candidates(board: Board, family: tuple[str, bool, int] | None) -> list[Board]:
    """The spec's near relatives with the markers seen (``family``), most likely first: for a checkerboard the
    ChArUco boards it may be (its checkerboards are looked for before the markers)."""
    out = []
    if board.kind == "checkerboard":
        c, r = board.columns, board.rows
        if family is not None:  # markers on it: a ChArUco board of (corners + 1) squares, looked for first
            sizes = [*_sizes_with(family[2]), (c + 1, r + 1), (r + 1, c + 1), (c + 2, r + 2), (r + 2, c + 2)]
            for a, b in dict.fromkeys(sizes):
                for legacy in (False, True)[:1 + (b % 2 == 0)]:  # OpenCV's old pattern differs with even rows
                    try:
                        out.append(Board("charuco", a, b, board.square, dictionary=family[0], inverted=family[1],
                                         legacy=legacy))
                    except HandcapError:  # too many markers for the dictionary
                        continue
        return out
    if family is None:  # no markers: a checkerboard of its inner corners?
        return _checkerboards(board.columns - 1, board.rows - 1, board.square)
    dictionary = board.dictionary if _family(family[0]) == _family(board.dictionary) else family[0]
    for columns, rows in ((board.columns, board.rows), (board.rows, board.columns), *_sizes_with(family[2])):
        for legacy in (board.legacy, not board.legacy)[:1 + (rows % 2 == 0)]:  # the same with odd rows
            try:
                out.append(replace(board, columns=columns, rows=rows, dictionary=dictionary, inverted=family[1],
                                   legacy=legacy))
            except HandcapError:  # too many markers for the dictionary
                continue
    return [b for b in dict.fromkeys(out) if b != board]


def board_hint(paths, board: Board) -> str:
    """Why ``board`` is not seen in a recording, and the spec that finds it there, as one clause for a message.

    Parameters
    ----------
    paths : str, Path or sequence of them
        What one camera recorded (a video, a folder of images, image files).
    board : Board
        The board asked for, never found.

    Returns
    -------
    str
        E.g. ``"looking at 8 of its frames, its markers are 4X4 white on black and
        charuco:4x5:0.054:0.0405:DICT_4X4_1000:inverted finds the board in 8 of 8; is that your board (--board
        charuco:4x5:0.054:0.0405:DICT_4X4_1000:inverted)?"``.
    """
    frames = sample_frames(paths)
    if not frames:
        return "no frame of it could be read"

    best = (0, 0, None, "")  # frames seen, looked at, the board, the markers seen
    family, markers = None, ""

    def look(candidates, markers=""):
        """The best candidate so far; stops at one that shows the board in half the frames or more."""
        nonlocal best
        for candidate in candidates:
            seen, looked = _seen(frames, candidate)
            if seen < min(looked, 2):  # one frame of many may be a part of the board, or a false find
                continue
            if seen > best[0]:
                best = (seen, looked, candidate, markers)
            if 2 * seen >= looked:
                return True
        return False

    # the quick look first (the search for markers costs seconds), then the boards the markers seen may be
    if not (board.kind == "checkerboard" and look(c for c in _checkerboards(board.columns, board.rows, board.square)
                                                  if c != board)):
        family = _charuco_family(frames, board.dictionary)
        markers = "" if family is None else (f"its markers are {_family(family[0])[5:]} "
                                             f"{'white on black' if family[1] else 'black on white'}")
        look(_candidates(board, family), markers)
    seen, looked, candidate, said = best
    if candidate is not None:
        return (f"looking at {len(frames)} of its frames, {said + ' and ' if said else ''}{candidate.spec} "
                f"finds the board in {seen} of {looked}; is that your board (--board {candidate.spec})?")
    if markers and board.kind == "checkerboard":
        return (f"looking at {len(frames)} of its frames, {markers}, ids up to {family[2] - 1}: a ChArUco board, "
                f"counted in squares (charuco:COLSxROWS:SQUARE_M:MARKER_M:{family[0]}"
                f"{':inverted' if family[1] else ''})?")
    if markers:
        return (f"looking at {len(frames)} of its frames, {markers}, ids up to {family[2] - 1}, but no board near "
                f"{board.spec} is found: check its size (in squares) and its marker size")
    if board.kind == "charuco":
        return (f"looking at {len(frames)} of its frames, no ArUco markers of any dictionary are found, nor a "
                f"checkerboard of about {board.columns - 1}x{board.rows - 1} inner corners: is the board in view "
                f"and in focus (a checkerboard of other size: checkerboard:COLSxROWS:SQUARE_M, inner corners)?")
    return (f"looking at {len(frames)} of its frames, no checkerboard of about {board.columns}x{board.rows} inner "
            f"corners is found, nor ArUco markers: is the board in view and in focus?")


__all__ = ["FAMILIES", "SAMPLES", "aruco_markers", "board_hint", "sample_frames"]
