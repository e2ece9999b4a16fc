"""Where the detector's frames come from: image files, folders of images, videos, one camera each.

Each input path is one camera, named after it: a folder of images (its frames
in file-name order, the numbers in the names compared as numbers, so ``img2``
comes before ``img10``; e.g. ``images/cam_0/000000.png`` as ``handcap synth
--images`` writes), a video (its frames in order, read one at a time), or a
single image (one frame). A take's folder that holds no images itself gives a
camera to each video and each folder of images in it (anipose's
``videos/cam1.mp4``, Pose2Sim's ``intrinsics/int_cam01_img/``). Frames are
grey ``(H, W)`` uint8; colour images are converted. A file that cannot be
decoded is one clear error naming it.

Frames are matched across cameras by their index. Where every file of the folders is named with a frame
number (rising, and skipping no more frames than the folder holds: not a clock time) and the folders share
most of their numbers (one frame counter, as a synchronised rig writes), the index is that number less the
smallest: a frame a camera dropped is missing from it, and its later frames still meet the other cameras'
frames of the same instant. Otherwise (cameras numbering their files apart, names without numbers) the
index is the order in the folder. :func:`frame_notes` says where either may pair frames of different
instants.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, replace
from pathlib import Path

import cv2
import numpy as np

from handcap.core.errors import HandcapError
from handcap.core.files import natural_key

IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff", ".pgm", ".ppm", ".webp")
VIDEO_SUFFIXES = (".mp4", ".avi", ".mov", ".mkv", ".m4v", ".webm", ".mpg", ".mpeg")
#: Frames a video may fall short of its header's count without a warning (the count is an estimate in some
#: containers); the slack is 1 % of the count where that is more.
COUNT_SLACK = 2
#: Photographs OpenCV cannot decode, and what to do with them.
UNREADABLE = {**dict.fromkeys((".heic", ".heif"), "a HEIC/HEIF photograph (a phone's default), which OpenCV cannot "
                                                  "decode: convert it to JPEG or PNG first (heif-convert, or the "
                                                  "phone's 'Most Compatible' format)"),
              **dict.fromkeys((".dng", ".cr2", ".cr3", ".nef", ".arw", ".raf", ".orf", ".rw2"),
                              "a camera raw file, which OpenCV cannot decode: develop it to a 16-bit TIFF or PNG "
                              "first (dcraw -T, darktable-cli)")}


@dataclass(frozen=True)
class FrameSelection:
    """The frames of a take to read, as a take of their own: its frame ``k`` is the input's frame
    ``start + k * every`` (below ``stop``), at ``1 / every`` of the input's rate.

    Attributes
    ----------
    start : int
        First input frame read (0-based, as the frames are indexed: :class:`FrameSource`).
    stop : int or None
        Input frame the selection stops before (None: the end).
    every : int
        Read every ``every``-th frame from ``start``.
    """

    start: int = 0
    stop: int | None = None
    every: int = 1

    def __post_init__(self):
        if self.start < 0 or (self.stop is not None and self.stop <= self.start):
            raise HandcapError(f"--frames {self.start}:{'' if self.stop is None else self.stop}: give A:B with "
                               "0 <= A < B (input frame numbers, 0-based)")
        if self.every < 1:
            raise HandcapError(f"--every {self.every}: give 1 (every frame) or more")

    def keeps(self, index: int) -> bool:
        """Whether input frame ``index`` is read."""
        return (index >= self.start and (self.stop is None or index < self.stop)
                and (index - self.start) % self.every == 0)

    def renumbered(self, index: int) -> int:
        """The selection's frame number of a kept input frame."""
        return (index - self.start) // self.every


@dataclass(frozen=True)
class FrameSource:
    """The frames of one camera.

    Attributes
    ----------
    camera : str
        Its name: the folder's or file's name without suffix.
    path : Path
    kind : str
        ``folder``, ``video`` or ``image``.
    files : tuple of Path
        The images of a folder (or the single image).
    numbers : tuple of int
        Each file's frame index where the folder's file names give it (see the module docstring); empty
        where the frames are indexed by their order.
    pick : FrameSelection or None
        Read only these frames, numbered as the selection numbers them (:func:`select_frames`).
    """

    camera: str
    path: Path
    kind: str
    files: tuple = ()
    numbers: tuple = ()
    pick: FrameSelection | None = None

    def frames(self, colour: bool = False):
        """Yield ``(frame_index, image)`` in order; images are grey uint8 ``(H, W)``.

        With ``colour``, BGR uint8 ``(H, W, 3)`` instead (grey inputs repeated in the three channels).

        Raises
        ------
        HandcapError
            A file that cannot be decoded, or a video with no readable frame.
        """
        pick = self.pick or FrameSelection()
        if self.kind == "video":
            capture = cv2.VideoCapture(str(self.path))
            if not capture.isOpened():
                raise HandcapError(f"{self.path}: cannot be opened as a video (unknown format or damaged file)")
            try:
                index = 0
                while pick.stop is None or index < pick.stop:
                    if not capture.grab():  # a frame not read is only grabbed: its picture is not made
                        break
                    if pick.keeps(index):
                        ok, frame = capture.retrieve()
                        if not ok:
                            break
                        yield pick.renumbered(index), _bgr(frame) if colour else _grey(frame)
                    index += 1
            finally:
                capture.release()
            if index == 0:
                raise HandcapError(f"{self.path}: no frame could be read from this video (empty or damaged)")
            return
        for index, file in enumerate(self.files):
            number = self.numbers[index] if self.numbers else index
            if pick.keeps(number):
                yield pick.renumbered(number), read_image(file, colour=colour)

    def fps(self) -> float | None:
        """A video's frame rate as its header says (None for images, or when it does not say)."""
        if self.kind != "video":
            return None
        capture = cv2.VideoCapture(str(self.path))
        try:
            fps = float(capture.get(cv2.CAP_PROP_FPS))
        finally:
            capture.release()
        return fps if 0 < fps < 10000 else None

    def count(self) -> int:
        """Number of frames read (a video's as its header says; 0 when it does not say)."""
        pick = self.pick or FrameSelection()
        if self.kind != "video":
            return sum(pick.keeps(n) for n in (self.numbers or range(len(self.files))))
        capture = cv2.VideoCapture(str(self.path))
        try:
            total = max(int(capture.get(cv2.CAP_PROP_FRAME_COUNT)), 0)
        finally:
            capture.release()
        return len(range(pick.start, total if pick.stop is None else min(total, pick.stop), pick.every))

    def span(self) -> int:
        """One more than the last frame index (:meth:`count`, unless the files' numbers skip frames)."""
        pick = self.pick or FrameSelection()
        kept = [pick.renumbered(n) for n in self.numbers if pick.keeps(n)]
        return (kept[-1] + 1 if kept else 0) if self.numbers else self.count()


def select_frames(sources, pick: FrameSelection) -> list:
    """The same cameras, each reading only the frames ``pick`` selects (numbered as it numbers them).

    Parameters
    ----------
    sources : sequence of FrameSource
    pick : FrameSelection

    Returns
    -------
    list of FrameSource

    Raises
    ------
    HandcapError
        Where no camera holds a selected frame (its first frame past the take's end).
    """
    picked = [replace(s, pick=pick) for s in sources]
    whole = [replace(s, pick=None).span() for s in sources]  # 0 for a video whose header gives no count
    if not any(s.count() for s in picked) and all(whole):
        raise HandcapError(f"--frames {pick.start}:{'' if pick.stop is None else pick.stop}: the inputs hold frames "
                           f"0 to {max(whole) - 1} only")
    return picked


class ArrayFrames:
    """One camera's frames held in memory, read as a :class:`FrameSource` is (by
    :func:`handcap.detect.capture.detect_capture`): frame ``t`` is ``images[t]``.

    Parameters
    ----------
    camera : str
        The camera's name.
    images : sequence of ndarray (H, W) uint8
        Its grey frames in order.
    """

    def __init__(self, camera: str, images):
        self.camera, self.images = str(camera), list(images)

    def frames(self):
        """Yield (index, image) for every frame, in order."""
        yield from enumerate(self.images)

    def count(self) -> int:
        """Number of frames."""
        return len(self.images)

    def span(self) -> int:
        """One more than the last frame index."""
        return len(self.images)


def read_image(path, colour: bool = False) -> np.ndarray:
    """One image file as grey uint8 ``(H, W)``.

    Parameters
    ----------
    path : str or Path
    colour : bool
        Return BGR uint8 ``(H, W, 3)`` instead (a grey file repeated in the three channels).

    Returns
    -------
    ndarray (H, W) uint8
        Deeper images are scaled to 8 bits (:func:`eight_bit`); colour is converted to grey. The image is turned
        upright as its EXIF orientation says (phone photographs are stored sideways with such a tag), as image viewers,
        ``cv2.imread`` (which reads the calibration board's images) and OpenCV's video reader show it: every
        pixel position handcap reports is in the picture as the user sees it.

    Raises
    ------
    HandcapError
        A missing file or one that does not decode as an image.
    """
    path = Path(path)
    if not path.is_file():
        raise HandcapError(f"{path}: no such image file")
    data = np.fromfile(path, dtype=np.uint8)
    # Any depth and colour, but not IMREAD_UNCHANGED: that also ignores the EXIF orientation.
    image = cv2.imdecode(data, cv2.IMREAD_ANYDEPTH | cv2.IMREAD_ANYCOLOR) if data.size else None
    if image is None:
        raise HandcapError(f"{path}: not an image that can be decoded (damaged, truncated or not an image)")
    return _bgr(image) if colour else _grey(image)


def eight_bit(image: np.ndarray) -> np.ndarray:
    """An image of any depth as uint8, its grey levels kept apart.

    Parameters
    ----------
    image : ndarray (H, W) or (H, W, C)
        uint8; uint16 (16-bit, or a machine-vision camera's 10- or 12-bit pixels in a 16-bit file); or float
        (0..1, as OpenCV and most tools write float images, or 0..255).

    Returns
    -------
    ndarray, same shape, uint8
        16-bit pixels scaled from the least bit depth that holds the image's largest value (at least 8 bits): a
        12-bit camera's 0..4095 fills 0..255 instead of 0..16, where its glyphs would fall apart. Floats whose
        largest finite value is at most 1 are scaled by 255, larger ones from that value; NaN and infinity
        are 0.
    """
    image = np.asarray(image)
    if image.dtype == np.uint8:
        return image
    if image.dtype.kind in "ui":
        bits = max(8, int(image.max(initial=0)).bit_length())
        return np.clip(np.rint(image * (255.0 / (2 ** bits - 1))), 0, 255).astype(np.uint8)
    image = np.where(np.isfinite(image), image, 0.0)
    top = float(image.max(initial=0.0))
    scale = 255.0 if top <= 1.0 else 1.0 if top <= 255.0 else 255.0 / top
    return np.clip(np.rint(image * scale), 0, 255).astype(np.uint8)


def _grey(image: np.ndarray) -> np.ndarray:
    image = eight_bit(image)
    if image.ndim == 3 and image.shape[2] == 4:
        image = cv2.cvtColor(image, cv2.COLOR_BGRA2GRAY)
    elif image.ndim == 3 and image.shape[2] == 3:
        image = cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)
    elif image.ndim == 3:
        image = image[..., 0]
    return np.ascontiguousarray(image)


def _bgr(image: np.ndarray) -> np.ndarray:
    image = eight_bit(image)
    if image.ndim == 2:
        image = cv2.cvtColor(image, cv2.COLOR_GRAY2BGR)
    elif image.shape[2] == 4:
        image = cv2.cvtColor(image, cv2.COLOR_BGRA2BGR)
    elif image.shape[2] != 3:
        image = cv2.cvtColor(np.ascontiguousarray(image[..., 0]), cv2.COLOR_GRAY2BGR)
    return np.ascontiguousarray(image)


def frame_sources(paths) -> list[FrameSource]:
    """The cameras of the input paths: one per folder of images, video or image file.

    A folder that holds no images but videos or folders of images (a take's folder) gives one camera to
    each of them, in natural order.

    Parameters
    ----------
    paths : sequence of str or Path
        Folders of images, videos, image files, or folders of videos and folders of images.

    Returns
    -------
    list of FrameSource

    Raises
    ------
    HandcapError
        A missing path, a folder without images, videos or folders of images, a file of another kind, or two
        inputs with one camera name.
    """
    sources = []
    for raw in paths:
        path = Path(raw)
        if path.is_dir():
            sources += _folder(path)
        elif path.is_file():
            suffix = path.suffix.lower()
            if suffix in VIDEO_SUFFIXES:
                sources.append(FrameSource(path.stem, path, "video"))
            elif suffix in IMAGE_SUFFIXES:
                sources.append(FrameSource(path.stem, path, "image", (path,)))
            elif suffix in UNREADABLE:
                raise HandcapError(f"{path}: {UNREADABLE[suffix]}")
            else:
                raise HandcapError(f"{path}: not an image ({', '.join(IMAGE_SUFFIXES)}) or a video "
                                   f"({', '.join(VIDEO_SUFFIXES)})")
        else:
            raise HandcapError(f"{path}: no such file or folder")
    names = [s.camera for s in sources]
    twice = sorted({n for n in names if names.count(n) > 1})
    if twice:
        raise HandcapError(f"two inputs are both camera {twice[0]!r}; give each camera's images a folder (or video) "
                           "of its own name")
    return _numbered(sources)


def _images(folder: Path) -> tuple:
    """The image files of a folder, in natural order."""
    return tuple(sorted((p for p in folder.iterdir() if p.suffix.lower() in IMAGE_SUFFIXES and p.is_file()),
                        key=natural_key))


def _folder(path: Path) -> list[FrameSource]:
    """A folder's cameras: itself where it holds images; else each video in it and each folder of images
    in it (a take's folder, one camera to a video or folder: anipose's and Pose2Sim's layouts)."""
    files = _images(path)
    if files:
        return [FrameSource(path.name, path, "folder", files)]
    inside = sorted(path.iterdir(), key=natural_key)
    videos = [FrameSource(p.stem, p, "video") for p in inside if p.is_file() and p.suffix.lower() in VIDEO_SUFFIXES]
    folders = [FrameSource(p.name, p, "folder", files) for p in inside if p.is_dir() for files in [_images(p)]
               if files]
    if videos or folders:
        return videos + folders
    other = sorted(p.suffix.lower() for p in inside if p.suffix.lower() in UNREADABLE)
    raise HandcapError(f"{path}: folder holds no images ({', '.join(IMAGE_SUFFIXES)}), no videos and no folders "
                       "of images" + (f"; it holds {other[0]} files, each {UNREADABLE[other[0]]}" if other else ""))


def _file_numbers(files) -> tuple | None:
    """The last number in each file's stem, where every file has one and they rise as a frame counter does
    (skipping no more frames than the files hold: clock times such as ``IMG_20261128_101533`` jump further);
    else None."""
    found = [re.findall(r"\d+", f.stem) for f in files]
    if not all(found):
        return None
    numbers = tuple(int(n[-1]) for n in found)
    rising = all(a < b for a, b in zip(numbers, numbers[1:]))
    return numbers if rising and numbers[-1] - numbers[0] + 1 <= 2 * len(numbers) else None


def _numbered(sources: list[FrameSource]) -> list[FrameSource]:
    """The folders indexed by their files' frame numbers where they share one counter (module docstring)."""
    numbers = {s.camera: _file_numbers(s.files) for s in sources if s.kind == "folder"}
    usable = [set(n) for n in numbers.values() if n is not None]
    if not usable or len(set.intersection(*usable)) < len(set.union(*usable)) / 2:
        return sources
    first = min(min(n) for n in usable)
    return [replace(s, numbers=tuple(k - first for k in numbers[s.camera])) if numbers.get(s.camera) else s
            for s in sources]


def short_videos(sources, frames) -> list[str]:
    """Warnings for the videos that ended before the frame count their header gives (a truncated or damaged file).

    Parameters
    ----------
    sources : sequence of FrameSource
    frames : sequence of int
        Frames read from each source.

    Returns
    -------
    list of str
        One line per video that gave fewer frames than its header says, less a slack of :data:`COUNT_SLACK`
        frames (a header's count is an estimate in some containers).
    """
    notes = []
    for source, read in zip(sources, frames):
        said = source.count() if source.kind == "video" else 0
        if read < said - max(COUNT_SLACK, said // 100):
            notes.append(f"{source.camera}: its video ended after {read} of the {said} frames its header gives "
                         f"(truncated or damaged?); {source.path.name}'s later frames are missing")
    return notes


def frame_notes(sources) -> list[str]:
    """Warnings where frames of different instants may be paired across cameras, or frames are missing.

    Parameters
    ----------
    sources : sequence of FrameSource
        From :func:`frame_sources`.

    Returns
    -------
    list of str
        One line per camera whose files' numbers skip frames, and one where cameras indexed by their order
        hold different numbers of frames.
    """
    notes = []
    for s in sources:
        gaps = [(a, b) for a, b in zip(s.numbers, s.numbers[1:]) if b > a + 1]
        if gaps:
            missing = sum(b - a - 1 for a, b in gaps)
            notes.append(f"{s.camera}: {missing} frame(s) missing by its files' numbers (first after frame "
                         f"{gaps[0][0]}); its other frames keep their numbers")
    ordered = {s.camera: s.count() for s in sources if not s.numbers and s.kind != "image"}
    if len(ordered) > 1 and len(set(ordered.values())) > 1:
        notes.append("cameras hold different numbers of frames (" + ", ".join(f"{c}: {n}" for c, n in ordered.items())
                     + ") and are matched by their order: check that they start together and drop no frame "
                       "(cameras started one by one: triangulate --sync auto finds each one's offset)")
    return notes
