"""Calibration boards found in what one camera recorded: a video, a folder of images, or image files.

Detections are dense arrays ``(T, N, 2)`` of pixels (OpenCV's convention, the
centre of the top-left pixel at (0, 0)): T frames (images, or video frames),
N corners of the board, NaN where a corner was not found; a frame where the
board was not seen (see :mod:`~handcap.multiview.board_corners`) is all NaN.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from handcap.core.errors import HandcapError
from handcap.core.files import existing_file, natural_key
from handcap.multiview.board_corners import charuco_detector, find_corners, gray_image
from handcap.multiview.board_spec import Board, parse_board

IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff", ".webp", ".pgm", ".ppm")


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
    files = sorted((p for p in folder.iterdir() if p.is_file() and is_image_file(p)), key=natural_key)
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
    detector = charuco_detector(board) if board.kind == "charuco" else None
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
        pixels.append(find_corners(image, board, mirrored=mirrored, detector=detector))
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
        detector = charuco_detector(board) if board.kind == "charuco" else None
        pixels, frames, size = [], [], None
        bar = _progress(None, total=total, desc=f"board in {path.name}", progress=progress)
        index = 0
        while True:
            if index % every:
                ok = capture.grab()  # skip without converting the frame
            else:
                ok, image = capture.read()
                if ok:
                    gray = gray_image(image)
                    size = (gray.shape[1], gray.shape[0])
                    pixels.append(find_corners(gray, board, mirrored=mirrored, detector=detector))
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


__all__ = ["IMAGE_SUFFIXES", "BoardDetections", "detect_in_files", "detect_in_images", "detect_in_video", "image_files",
           "is_image_file"]
