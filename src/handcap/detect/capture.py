"""The detector over a whole capture: every frame of every camera, into the 2D detections arrays.

The arrays are the 2D detections File contract (``camera_names``,
``marker_names``, ``frame``, ``camera``, ``marker``, ``xy``, ``score``,
``rate``) plus one row per read block (``block_text``, ``block_frame``,
``block_camera``, ``block_xy``, ``block_score``); ``handcap detect`` writes
them, ``handcap demo --images`` uses them directly.

Tracking: in a camera's run of frames, a frame is searched only around where
the patches the previous frame found are expected (their box, widened by
:data:`MARGIN` of its longer side and at least :data:`MARGIN_PX` on every side,
and moved on as far as they moved between the two frames before: a hand
moving steadily stays inside it), once that prediction held to half the
widening for the last frame, with the whole frame's grey levels, so what lies
well inside the box is found exactly as a whole-frame search finds it. The frame is searched whole again when that
search may have missed something: a block within two of its squares (and
half the widening) of the box's edge (the hand may reach beyond it), fewer
blocks than
:data:`KEEP_SHARE` of the previous frame's, or :data:`FULL_EVERY` frames since
the last whole search (a patch coming into view away from the hand). A
camera whose region search missed, where the whole frame then read a tag the
region did not, searches whole for the next 2, then 4, ... frames before it
tries a region again. The motion is the median shift of the
tags both frames read (else of the box's centre), so a take filmed at a few
frames a second, where the hand's motion changes much between frames, is
searched whole and pays nothing for tracking. (The box first followed the
patches without moving on: on a rendered grasp take of 20 frames a second,
the hand moved more than half the widening between frames in a quarter of
them, but its motion changed that much in 2 %.) On a 5 MP frame
of a hand the region costs about a third of the whole frame
(``benchmarks/detect.py``).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import cv2
import numpy as np
import torch
from tqdm import tqdm

from handcap.core.errors import HandcapError
from handcap.detect.noise import NOISE_LEARNED
from handcap.detect.pipeline import Detector, ImageDetections, region_box
from handcap.detect.response import ResponseChoice
from handcap.detect.naming import UnreadSquares
from handcap.detect.sharpness import BLUR_LEARNED
from handcap.parallel import map_chunks

#: A camera's frame is searched whole at least once in this many frames.
FULL_EVERY = 10
#: The search region around the previous frame's blocks is widened by this share of its longer side ...
MARGIN = 0.25
#: ... and at least by this many pixels, on every side.
MARGIN_PX = 48
#: A region search that finds fewer blocks than this share of the previous frame's is redone on the whole frame:
#: a hand that left the box in one frame while another stayed. Blur and occlusion alone cost a frame up to a
#: third of its blocks (seen in rendered videos), and those the whole frame would not find either.
KEEP_SHARE = 0.6


@dataclass(frozen=True)
class CaptureDetections:
    """The detections of a capture and what was counted on the way.

    Attributes
    ----------
    arrays : dict of str to ndarray
        The detections file's arrays (see the module docstring), no warnings entry.
    images : int
        Images read.
    empty : int
        Images with no corner found.
    corrected : int
        Readings the vote over the template changed.
    regions : int
        Images searched only around the previous frame's patches (see the module docstring).
    sure, disowned : int
        Readings the reader trusted alone, and those of them the vote over the template dropped or changed
        (:class:`~handcap.detect.pipeline.ImageDetections`).
    read : int
        White squares in which the reader saw a tag, at any confidence.
    frames : tuple of int
        Images read from each camera, in the order of the sources.
    noisy : int
        Images with more sensor noise than the networks learned (:data:`~handcap.detect.noise.NOISE_LEARNED`).
    noise : float
        The most sensor noise of an image, grey levels (:func:`~handcap.detect.noise.noise_sigma`).
    responses : tuple of str
        Each camera's response to light as its frames were read, ``linear`` or ``srgb``
        (:mod:`~handcap.detect.response`), in the order of the sources.
    looked : tuple of (int, int)
        Each camera's tags read in the frames its response was chosen on: as recorded and decoded ((0, 0) where
        the response was given).
    twice : int
        Sure readings whose tag the reader was sure of at another white square of the same image too.
    twice_images : int
        Images that hold such readings.
    unread : list of UnreadSquares
        Each image's white squares without a tag, for :func:`~handcap.detect.views.name_from_views` and
        :func:`~handcap.detect.motion.name_from_frames` (kept only where the detector has a template).
    blurred : tuple of int
        Each camera's images whose printed edges are blurred beyond what the networks learned
        (:data:`~handcap.detect.sharpness.BLUR_LEARNED`), in the order of the sources.
    blur : float
        The most edge blur of those images (:func:`~handcap.detect.sharpness.edge_blur`), pixels; 0 without one.
    """

    arrays: dict
    images: int
    empty: int
    corrected: int
    regions: int = 0
    sure: int = 0
    disowned: int = 0
    read: int = 0
    frames: tuple = ()
    noisy: int = 0
    noise: float = 0.0
    responses: tuple = ()
    looked: tuple = ()
    twice: int = 0
    twice_images: int = 0
    unread: list = field(default_factory=list)
    blurred: tuple = ()
    blur: float = 0.0


class Tracker:
    """Where to search one camera's next frame (see the module docstring).

    Parameters
    ----------
    shape : (int, int)
        The camera's image height and width, pixels.
    """

    def __init__(self, shape):
        self.shape = tuple(shape[:2])
        self.box = None
        self.blocks = 0
        self.since_full = 0
        self.wait = 0  # whole frames to search before the next region search
        self.backoff = 1
        self.steady = False  # the last motion was within half the widening of the one before (its prediction)
        self.centres = {}  # the last frame's block centres by tag
        self.motion = np.zeros(2)  # how far the patches moved between the last two frames, pixels

    def region(self):
        """The box (x0, y0, x1, y1) to search next, pixels, or None for the whole frame."""
        if self.box is None or not self.steady or self.wait > 0 or self.since_full + 1 >= FULL_EVERY:
            return None
        x0, y0, x1, y1 = self.box
        dx, dy = self.motion
        return x0 + dx, y0 + dy, x1 + dx, y1 + dy

    def missed(self, found: ImageDetections, region) -> bool:
        """Whether a search of ``region`` may have missed patches the whole frame shows.

        Parameters
        ----------
        found : ImageDetections
            What the search found, whole-frame pixels.
        region : (x0, y0, x1, y1)
            The box searched.

        Returns
        -------
        bool
        """
        if len(found.block_text) < KEEP_SHARE * self.blocks or len(found.block_text) == 0:
            return True
        x0, y0, x1, y1 = region_box(region, self.shape)
        h, w = self.shape
        pts = found.block_xy.reshape(-1, 2)
        # Within two squares of the edge the hand may go on beyond it (the patch next to the outermost block
        # found lies outside); a block read now that the last frame did not read, further in, is no sign.
        sides = np.linalg.norm(np.roll(found.block_xy, -1, axis=1) - found.block_xy, axis=2)
        slack = min(2 * float(np.median(sides)), self._pad(pts) / 2)
        near = np.zeros(len(pts), bool)
        if x0 > 0:
            near |= pts[:, 0] < x0 + slack
        if y0 > 0:
            near |= pts[:, 1] < y0 + slack
        if x1 < w:
            near |= pts[:, 0] > x1 - slack
        if y1 < h:
            near |= pts[:, 1] > y1 - slack
        return bool(near.any())

    def update(self, found: ImageDetections, whole: bool, missed: bool = False) -> None:
        """Take in a frame's detections.

        Parameters
        ----------
        found : ImageDetections
        whole : bool
            They come from the whole frame.
        missed : bool
            A region search of this frame came first and missed (:meth:`missed`).
        """
        self.since_full = 0 if whole else self.since_full + 1
        if missed:
            self.backoff = min(2 * self.backoff, FULL_EVERY)
            self.wait = self.backoff
        elif not whole:
            self.backoff = 1
        elif self.wait > 0:
            self.wait -= 1
        self.blocks = len(found.block_text)
        if self.blocks == 0:
            self.box, self.steady, self.centres, self.motion = None, False, {}, np.zeros(2)
            return
        pts = found.block_xy.reshape(-1, 2)
        pad = self._pad(pts)
        box = (*(pts.min(axis=0) - pad), *(pts.max(axis=0) + pad))
        centres = dict(zip(found.block_text, found.block_xy.mean(axis=1)))
        shift = self._shift(centres, box)
        # Steady: this frame's motion was what the last one predicted, to half the widening (a first motion is
        # predicted as none).
        self.steady = shift is not None and float(np.abs(shift - self.motion).max()) <= pad / 2
        self.box, self.centres = box, centres
        self.motion = np.zeros(2) if shift is None else np.asarray(shift, dtype=np.float64)

    def _shift(self, centres: dict, box) -> np.ndarray | None:
        """How far the patches moved since the last frame (2,), pixels: the median over the tags both read, else the
        shift of the box's centre; None without a last frame."""
        common = [t for t in centres if t in self.centres]
        if common:
            return np.median([centres[t] - self.centres[t] for t in common], axis=0)
        if self.box is None:
            return None
        return (np.add(box[:2], box[2:]) - np.add(self.box[:2], self.box[2:])) / 2

    @staticmethod
    def _pad(pts: np.ndarray) -> float:
        """The widening of the box around ``pts`` (N, 2), pixels."""
        return max(MARGIN * float((pts.max(axis=0) - pts.min(axis=0)).max()), MARGIN_PX)


def detect_capture(detector: Detector, sources, marker_names, rate: float, *,
                   progress: bool | None = None, track: bool = True, sizes=None,
                   response="auto", workers: int = 1, scheduler=None) -> CaptureDetections:
    """Run ``detector`` on every frame of ``sources`` (one per camera, in the rig's order).

    Parameters
    ----------
    detector : Detector
    sources : sequence of FrameSource
        Camera ``c`` of the output is ``sources[c]``.
    marker_names : sequence of str
        The markers a corner id may name (the template's corner names, or a subset of them); a corner
        named otherwise is left out.
    rate : float
        Frames per second.
    progress : bool, optional
        Progress bar over the images (over the cameras when they run in parallel; default: on a terminal).
    track : bool
        Search a frame around the previous frame's patches where that is safe (see the module docstring);
        without, every frame is searched whole.
    sizes : sequence of (int, int), optional
        Image (width, height) of each source's camera in the rig, pixels: a frame of another size is an error
        (its pixels would not be those the rig was calibrated for), raised at that frame.
    response : {"auto", "linear", "srgb"} or sequence of them
        The cameras' response to light (or each source's): chosen for each camera on its first frames
        (``auto``), linear as recorded, or display-encoded, decoded to linear light first
        (:mod:`~handcap.detect.response`).
    workers : int
        Cameras detected at once, each in a local process of its own with this process's torch threads shared
        out among them (:func:`handcap.parallel.map_chunks`; the detector and the sources travel to them, so both
        must pickle); 1 (the default): one camera after another in this process. The cameras are independent, so
        the arrays are the same either way.
    scheduler : None, str or distributed.Client
        A Dask scheduler to run the cameras on instead (its workers need handcap and the input files at the same
        paths); ``workers`` is then ignored.

    Returns
    -------
    CaptureDetections

    Raises
    ------
    HandcapError
        A frame whose size is not its camera's.
    """
    keep = getattr(detector, "pattern", None) is not None  # a template names the unread squares
    given = [response] * len(sources) if isinstance(response, str) else list(response)
    jobs = [(source, c, None if sizes is None else sizes[c], given[c]) for c, source in enumerate(sources)]
    workers = min(int(workers), len(sources))
    out, cameras = _Rows(marker_names, keep_unread=keep), []
    if scheduler is None and workers <= 1:
        with tqdm(total=sum(s.count() for s in sources), desc="detect", unit="image",
                  disable=None if progress is None else not progress, leave=False) as bar:
            for source, c, size, chosen in jobs:
                cameras.append(_detect_camera(detector, source, c, out, size, chosen, track, bar))
    else:
        threads = max(1, torch.get_num_threads() // max(workers, 1))
        chunks = [(detector, list(marker_names), keep, track, threads, *job) for job in jobs]
        done = map_chunks(_camera_chunk, chunks, scheduler=scheduler, workers=workers, progress=progress,
                          desc="detect (cameras)")
        for rows, camera in done:  # in the cameras' order, so the rows are those of one camera after another
            out.extend(rows)
            cameras.append(camera)
    regions = sum(camera[0] for camera in cameras)
    return CaptureDetections(out.arrays(sources, rate), out.images, out.empty, out.corrected, regions, out.sure,
                             out.disowned, out.read, tuple(out.frames.get(c, 0) for c in range(len(sources))),
                             out.noisy, out.noise, tuple(camera[1] for camera in cameras),
                             tuple(camera[2] for camera in cameras), out.twice, out.twice_images, out.unread,
                             tuple(out.blurred.get(c, 0) for c in range(len(sources))), out.blur)


def _camera_chunk(chunk) -> tuple:
    """One camera in a worker process: its rows (a :class:`_Rows` of its own) and :func:`_detect_camera`'s tuple."""
    detector, marker_names, keep, track, threads, source, c, size, response = chunk
    before = torch.get_num_threads(), cv2.getNumThreads()
    torch.set_num_threads(threads)
    cv2.setNumThreads(threads)
    try:
        rows = _Rows(marker_names, keep_unread=keep)
        return rows, _detect_camera(detector, source, c, rows, size, response, track, None)
    finally:
        torch.set_num_threads(before[0])
        cv2.setNumThreads(before[1])


def _detect_camera(detector: Detector, source, c: int, out: "_Rows", size, response: str, track: bool,
                   bar) -> tuple:
    """Every frame of camera ``c`` into ``out``; (images searched in a region, its response, its tags read in the
    frames the response was chosen on (as recorded, decoded))."""
    tracker, choice, pending, regions = None, ResponseChoice(response), [], 0
    for t, image in source.frames():
        if size is not None:
            check_size(source, t, image.shape, size)
        if tracker is None or tracker.shape != image.shape[:2]:
            tracker = Tracker(image.shape)
        if choice.response is None:  # still choosing the camera's response: the whole frame, both ways
            both = choice.look(detector, image)
            tracker.update(both[choice.leaning() == "srgb"], whole=True)
            pending.append((t, both))
            if choice.response is not None:  # chosen: the frames looked at, read the way chosen
                out.add_all(pending, c, choice.response)
                pending = []
            if bar is not None:
                bar.update()
            continue
        image = choice.prepared(image)
        region = tracker.region() if track else None
        found = detector.image(image, region) if region is not None else None
        missed = found is not None and tracker.missed(found, region)
        if found is None or missed:
            partial, found, region = found, detector.image(image), None
            # Only a miss the whole frame confirms, a tag it reads that the region did not, makes the
            # camera wait before it tries a region again; on a rendered grasp take 14 of 15 were not.
            missed = missed and bool(set(found.block_text.tolist()) - set(partial.block_text.tolist()))
        regions += region is not None
        tracker.update(found, whole=region is None, missed=missed)
        out.add(found, t, c)
        if bar is not None:
            bar.update()
    out.add_all(pending, c, choice.leaning())  # a camera with fewer frames than the choice looks at
    return regions, choice.leaning(), tuple(int(n) for n in choice.tags)


class _Rows:
    """The detections of a capture as they are added, frame by frame, and what is counted on the way."""

    def __init__(self, marker_names, keep_unread: bool = True):
        self.marker_names = marker_names
        self.index = {n: k for k, n in enumerate(marker_names)}
        self.rows = {"frame": [], "camera": [], "marker": [], "xy": [], "score": []}
        self.blocks = {"block_text": [], "block_frame": [], "block_camera": [], "block_xy": [], "block_score": []}
        self.images = self.empty = self.corrected = self.sure = self.disowned = self.read = self.noisy = 0
        self.twice = self.twice_images = 0
        self.noise, self.frames, self.unread, self.keep_unread = 0.0, {}, [], keep_unread
        self.blurred, self.blur = {}, 0.0

    def add_all(self, pending, camera: int, response: str) -> None:
        """Frames searched both ways, ``pending`` [(frame, (as recorded, decoded))], read as ``response``."""
        for t, both in pending:
            self.add(both[response == "srgb"], t, camera)

    def add(self, found: ImageDetections, t: int, camera: int) -> None:
        """Frame ``t`` of ``camera``: its named corners' rows, its blocks, and the counts."""
        self.images += 1
        self.frames[camera] = self.frames.get(camera, 0) + 1
        self.noisy, self.noise = self.noisy + (found.noise > NOISE_LEARNED), max(self.noise, found.noise)
        if found.blur > BLUR_LEARNED:  # NaN (no block read) is not
            self.blurred[camera], self.blur = self.blurred.get(camera, 0) + 1, max(self.blur, found.blur)
        self.empty += len(found.corners) == 0
        self.corrected, self.sure = self.corrected + found.corrected, self.sure + found.sure
        self.disowned, self.read = self.disowned + found.disowned, self.read + found.read
        self.twice, self.twice_images = self.twice + found.twice, self.twice_images + (found.twice > 0)
        named = [k for k, n in enumerate(found.names) if n is not None and n in self.index]
        self.rows["frame"] += [t] * len(named)
        self.rows["camera"] += [camera] * len(named)
        self.rows["marker"] += [self.index[found.names[k]] for k in named]
        self.rows["xy"] += [found.corners[k] for k in named]
        self.rows["score"] += [found.corner_score[k] for k in named]
        self.blocks["block_text"] += list(found.block_text)
        self.blocks["block_frame"] += [t] * len(found.block_text)
        self.blocks["block_camera"] += [camera] * len(found.block_text)
        self.blocks["block_xy"] += list(found.block_xy)
        self.blocks["block_score"] += list(found.block_score)
        if self.keep_unread and len(found.unread):
            self.unread.append(UnreadSquares(camera, t, found.corners[found.unread].astype(np.float32),
                                             found.corner_score[found.unread].astype(np.float32)))

    def extend(self, other: "_Rows") -> None:
        """Take in ``other``'s frames after this one's (another camera's, detected apart)."""
        for mine, theirs in ((self.rows, other.rows), (self.blocks, other.blocks)):
            for key in mine:
                mine[key] += theirs[key]
        for key in ("images", "empty", "corrected", "sure", "disowned", "read", "noisy", "twice", "twice_images"):
            setattr(self, key, getattr(self, key) + getattr(other, key))
        self.noise, self.blur = max(self.noise, other.noise), max(self.blur, other.blur)
        for mine, theirs in ((self.frames, other.frames), (self.blurred, other.blurred)):
            for camera, count in theirs.items():
                mine[camera] = mine.get(camera, 0) + count
        self.unread += other.unread

    def arrays(self, sources, rate: float) -> dict:
        """The detections file's arrays (the module docstring), in the order the frames were added."""
        rows, blocks = self.rows, self.blocks
        return {
            "camera_names": np.array([s.camera for s in sources]),
            "marker_names": np.array(self.marker_names, dtype=str),
            "frame": np.array(rows["frame"], dtype=np.int64), "camera": np.array(rows["camera"], dtype=np.int64),
            "marker": np.array(rows["marker"], dtype=np.int64),
            "xy": np.array(rows["xy"], dtype=np.float64).reshape(-1, 2),
            "score": np.array(rows["score"], dtype=np.float64), "rate": np.array(float(rate)),
            "n_frames": np.array(max((s.span() for s in sources), default=0), dtype=np.int64),
            "block_text": np.array(blocks["block_text"], dtype="<U2"),
            "block_frame": np.array(blocks["block_frame"], dtype=np.int64),
            "block_camera": np.array(blocks["block_camera"], dtype=np.int64),
            "block_xy": np.array(blocks["block_xy"], dtype=np.float64).reshape(-1, 4, 2),
            "block_score": np.array(blocks["block_score"], dtype=np.float64),
        }


def check_size(source, frame: int, shape, size) -> None:
    """Refuse a frame whose size is not the rig's for its camera.

    Parameters
    ----------
    source : FrameSource
    frame : int
        The frame's index.
    shape : tuple of int
        The frame's array shape, (H, W) or (H, W, 3).
    size : (int, int)
        The camera's image (width, height) in the rig, pixels.

    Raises
    ------
    HandcapError
        One line naming the camera, the frame and both sizes, and the likely cause.
    """
    w, h = int(shape[1]), int(shape[0])
    rw, rh = (int(v) for v in size)
    if (w, h) == (rw, rh):
        return
    where = f"{source.camera} frame {frame}: the image is {w}x{h} px but the rig calibrated camera {source.camera} at "
    if (w, h) == (rh, rw):
        raise HandcapError(where + f"{rw}x{rh}: turned a quarter (a phone's EXIF orientation, or a rotated "
                                   "export?); give the images as the camera recorded them for this calibration")
    raise HandcapError(where + f"{rw}x{rh}: scaled or cropped images would not match the calibration; give the "
                               "camera's full-size images, or calibrate the rig on images of this size")
