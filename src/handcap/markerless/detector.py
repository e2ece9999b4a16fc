"""2D hand keypoints in images and videos: MediaPipe's hand landmarker, and retries where it finds no hand.

The landmarker comes from the optional extra (``pip install 'handcap[markerless]'``, then
``pip install --no-deps mediapipe==0.10.14``: that release bundles its hand models in the package, so
nothing is downloaded at run time, and it runs with numpy 2; its declared dependencies would replace
OpenCV's headless build and bring JAX, which the legacy hand solution does not use).

Off the shelf the landmarker misses hands in tight crops (its palm detector needs some context), small
hands, and hands turned far from upright. When it finds no hand, :class:`KeypointDetector` tries again
(first success wins), each time mapping the keypoints back to the original image:

1. around the hand of the frame before, in a video (a crop twice the hand's size, enlarged to at least
   :data:`CROP_PX`);
2. the image padded by half its size on every side (a hand that fills the frame);
3. overlapping crops of half, then a quarter, of the image, enlarged 2 and 4 times (a small hand);
4. the image turned by 90, 180 and 270 degrees;
5. the image mirrored (its labels swapped back).

Handedness: MediaPipe labels hands as seen in a mirrored (selfie) image; for an ordinary camera the label
is the other one, which the detector gives unless ``mirrored`` is set.

Pixels: OpenCV's convention, pixel centres at integers (MediaPipe's normalised 0..1 spans the image's
edges, so ``x = u * W - 0.5``).
"""

from __future__ import annotations

import contextlib
import os
import sys
import warnings
from dataclasses import dataclass

import cv2
import numpy as np
from tqdm import tqdm

from handcap.core.errors import HandcapError
from handcap.markerless.keypoints import hand_names
from handcap.multiview.detections import Detections

#: The smallest side a crop around a previous hand is enlarged to, pixels.
CROP_PX = 256
#: Enlargements of the zoom retry: crops of 1/2 then 1/4 of the image (9 then 49 overlapping crops).
ZOOMS = (2, 4)
#: The retries, in the order tried.
RETRIES = ("previous", "pad", "zoom", "rotate", "mirror")
INSTALL = ("the hand keypoint detector needs the markerless extra: pip install 'handcap[markerless]' && "
           "pip install --no-deps mediapipe==0.10.14")


@dataclass(frozen=True)
class Hand:
    """One hand found in an image.

    Attributes
    ----------
    label : str
        ``left`` or ``right`` (for a camera that is not mirrored, unless told otherwise).
    pixels : ndarray (21, 2)
        Keypoints in the image, keypoint order.
    score : float
        The landmarker's handedness score, 0..1.
    how : str
        ``plain`` or the retry that found it (:data:`RETRIES`).
    """

    label: str
    pixels: np.ndarray
    score: float
    how: str = "plain"


def _landmarker(max_hands: int, min_score: float, complexity: int):
    os.environ.setdefault("GLOG_minloglevel", "2")  # MediaPipe's C++ log lines on stderr: errors only
    try:
        with warnings.catch_warnings():  # its protobuf use is deprecated there; nothing for a user to do
            warnings.simplefilter("ignore", UserWarning)
            from mediapipe.python.solutions import hands as mp_hands  # noqa: PLC0415 (optional extra)
    except ImportError:
        raise HandcapError(INSTALL) from None
    return mp_hands.Hands(static_image_mode=True, max_num_hands=max_hands, model_complexity=complexity,
                          min_detection_confidence=min_score)


@contextlib.contextmanager
def _quiet_stderr(quiet: bool):
    """Send the process's standard error to nowhere meanwhile: TensorFlow Lite and absl print notes there
    from C++ (delegates created, feedback tensors), which no Python setting silences; MediaPipe's failures
    still come as Python exceptions."""
    if not quiet:
        yield
        return
    sys.stderr.flush()
    saved = os.dup(2)
    try:
        with open(os.devnull, "wb") as null:
            os.dup2(null.fileno(), 2)
        yield
    finally:
        os.dup2(saved, 2)
        os.close(saved)


class KeypointDetector:
    """MediaPipe's hand landmarker with retries (see the module docstring).

    Parameters
    ----------
    max_hands : int
        Most hands per image.
    min_score : float
        The landmarker's least detection confidence.
    mirrored : bool
        The images are mirrored (a selfie camera): keep MediaPipe's labels as they are.
    retry : bool or sequence of str
        Retries to make when the landmarker finds nothing (True: all of :data:`RETRIES`; False: none).
    complexity : {0, 1}
        MediaPipe's model: 0 lite, 1 full.

    Raises
    ------
    HandcapError
        The extra is not installed, or an unknown retry.
    """

    def __init__(self, max_hands: int = 2, min_score: float = 0.5, mirrored: bool = False, retry=True,
                 complexity: int = 1):
        self.retries = tuple(RETRIES if retry is True else () if retry is False else retry)
        unknown = sorted(set(self.retries) - set(RETRIES))
        if unknown:
            raise HandcapError(f"unknown retry {', '.join(unknown)}; choose from {', '.join(RETRIES)}")
        self.mirrored = bool(mirrored)
        with _quiet_stderr(True):
            self._hands = _landmarker(int(max_hands), float(min_score), int(complexity))

    def close(self) -> None:
        """Free the landmarker."""
        self._hands.close()

    def _plain(self, image_bgr: np.ndarray, how: str = "plain") -> list[Hand]:
        """The landmarker once on a BGR image."""
        h, w = image_bgr.shape[:2]
        with warnings.catch_warnings(), _quiet_stderr(True):
            warnings.simplefilter("ignore", UserWarning)
            result = self._hands.process(cv2.cvtColor(image_bgr, cv2.COLOR_BGR2RGB))
        found = []
        for marks, handed in zip(result.multi_hand_landmarks or [], result.multi_handedness or []):
            xy = np.array([[p.x * w - 0.5, p.y * h - 0.5] for p in marks.landmark])
            best = handed.classification[0]
            label = best.label.lower()
            if not self.mirrored:
                label = {"left": "right", "right": "left"}.get(label, label)
            found.append(Hand(label, xy, float(best.score), how))
        return found

    def detect(self, image, previous: np.ndarray | None = None) -> list[Hand]:
        """Hands in one image, retrying where the landmarker alone finds none.

        Parameters
        ----------
        image : ndarray (H, W, 3) BGR or (H, W) grey, uint8
        previous : ndarray (21, 2), optional
            Keypoints of a hand in the frame before (a video), pixels.

        Returns
        -------
        list of Hand
        """
        image = np.asarray(image)
        if image.ndim == 2:
            image = cv2.cvtColor(image, cv2.COLOR_GRAY2BGR)
        if image.ndim != 3 or image.shape[2] != 3 or image.dtype != np.uint8 or min(image.shape[:2]) < 8:
            raise HandcapError(f"an image must be uint8 (H, W, 3) BGR or (H, W) grey, got {image.dtype} "
                               f"{image.shape}")
        found = self._plain(image)
        for retry in self.retries:
            if found:
                break
            found = getattr(self, f"_{retry}")(image, previous)
        return found

    def _previous(self, image, previous):
        if previous is None or not np.isfinite(previous).all():
            return []
        lo, hi = previous.min(axis=0), previous.max(axis=0)
        centre, half = (lo + hi) / 2, max((hi - lo).max(), 16.0)
        x0, y0 = np.floor(centre - half).astype(int)
        x1, y1 = np.ceil(centre + half).astype(int)
        h, w = image.shape[:2]
        x0, y0, x1, y1 = max(x0, 0), max(y0, 0), min(x1, w), min(y1, h)
        if x1 - x0 < 8 or y1 - y0 < 8:
            return []
        crop = image[y0:y1, x0:x1]
        zoom = max(1.0, CROP_PX / min(crop.shape[:2]))
        crop = cv2.resize(crop, None, fx=zoom, fy=zoom, interpolation=cv2.INTER_LINEAR)
        return [_scaled(hand, zoom, (x0, y0), "previous") for hand in self._plain(crop)]

    def _pad(self, image, previous):
        h, w = image.shape[:2]
        p = max(h, w) // 2
        padded = cv2.copyMakeBorder(image, p, p, p, p, cv2.BORDER_CONSTANT, value=(0, 0, 0))
        return [_scaled(hand, 1.0, (-p, -p), "pad") for hand in self._plain(padded)]

    def _zoom(self, image, previous):
        h, w = image.shape[:2]
        for zoom in ZOOMS:  # crops of 1/zoom of the image, overlapping by half, each enlarged zoom times
            ch, cw = h // zoom, w // zoom
            if min(ch, cw) < 16:
                break
            for y0 in range(0, h - ch + 1, max(ch // 2, 1)):
                for x0 in range(0, w - cw + 1, max(cw // 2, 1)):
                    big = cv2.resize(image[y0:y0 + ch, x0:x0 + cw], None, fx=zoom, fy=zoom,
                                     interpolation=cv2.INTER_LINEAR)
                    found = self._plain(big, "zoom")
                    if found:
                        return [_scaled(hand, zoom, (x0, y0), "zoom") for hand in found]
        return []

    def _rotate(self, image, previous):
        h, w = image.shape[:2]
        for turns, code in ((1, cv2.ROTATE_90_CLOCKWISE), (2, cv2.ROTATE_180), (3, cv2.ROTATE_90_COUNTERCLOCKWISE)):
            found = self._plain(cv2.rotate(image, code), "rotate")
            if found:
                return [Hand(hand.label, _unturn(hand.pixels, turns, w, h), hand.score, "rotate") for hand in found]
        return []

    def _mirror(self, image, previous):
        w = image.shape[1]
        swap = {"left": "right", "right": "left"}
        return [Hand(swap.get(hand.label, hand.label), np.c_[w - 1 - hand.pixels[:, 0], hand.pixels[:, 1]],
                     hand.score, "mirror") for hand in self._plain(image[:, ::-1].copy())]


def _scaled(hand: Hand, zoom: float, offset, how: str) -> Hand:
    """A hand found in a crop (at ``offset`` (x, y) of the image) enlarged ``zoom`` times, in the image's pixels."""
    return Hand(hand.label, (hand.pixels + 0.5) / zoom - 0.5 + np.asarray(offset, dtype=np.float64), hand.score, how)


def _unturn(xy, turns: int, w: int, h: int) -> np.ndarray:
    """Pixels of an image turned clockwise by ``turns`` quarter turns, back in the original (W x H) image."""
    x, y = xy[:, 0], xy[:, 1]
    if turns == 1:  # clockwise: (x, y) -> (h - 1 - y, x)
        return np.c_[y, h - 1 - x]
    if turns == 2:
        return np.c_[w - 1 - x, h - 1 - y]
    return np.c_[w - 1 - y, x]  # counter-clockwise: (x, y) -> (y, w - 1 - x)


def detect_keypoints(sources, detector: KeypointDetector, rate: float, *, progress: bool | None = None):
    """2D keypoints of every frame of every camera, as 2D detections.

    Parameters
    ----------
    sources : sequence of FrameSource
        One per camera (:func:`handcap.detect.sources.frame_sources`); videos are read frame by frame.
    detector : KeypointDetector
    rate : float
        Frames per second.
    progress : bool, optional
        Progress bar over frames (default: on a terminal).

    Returns
    -------
    detections : Detections
        Marker names ``left:wrist`` ... ``right:pinky_tip``; a second hand with a label already taken in
        that frame gets the other label, a third ``hand2``. Each keypoint's score is its hand's.
    counts : dict
        ``frames``, frames ``with_hand``, and hands found by each way (``plain`` and the retries).
    """
    labels = ["left", "right"]
    rows = {"frame": [], "camera": [], "marker": [], "xy": [], "score": []}
    counts = {"frames": 0, "with_hand": 0, **{k: 0 for k in ("plain",) + RETRIES}}
    n_frames = 0
    total = sum(s.count() for s in sources) or None
    with tqdm(total=total, desc="keypoints", unit="frame", disable=None if progress is None else not progress,
              leave=False) as bar:
        for c, source in enumerate(sources):
            previous = None
            for t, image in source.frames(colour=True):
                hands = sorted(detector.detect(image, previous), key=lambda h: -h.score)
                taken = set()
                for hand in hands:
                    label = hand.label if hand.label not in taken else next(
                        (x for x in ("left", "right") if x not in taken), f"hand{len(taken)}")
                    taken.add(label)
                    if label not in labels:
                        labels.append(label)
                    rows["frame"].append(np.full(21, t))
                    rows["camera"].append(np.full(21, c))
                    rows["marker"].append(21 * labels.index(label) + np.arange(21))
                    rows["xy"].append(hand.pixels)
                    rows["score"].append(np.full(21, hand.score))
                    counts[hand.how] += 1
                previous = hands[0].pixels if hands else previous
                counts["frames"] += 1
                counts["with_hand"] += bool(hands)
                n_frames = max(n_frames, t + 1)
                bar.update(1)
    empty = [np.zeros(0, int)]
    detections = Detections(tuple(s.camera for s in sources), tuple(n for lab in labels for n in hand_names(lab)),
                            np.concatenate(rows["frame"] or empty), np.concatenate(rows["camera"] or empty),
                            np.concatenate(rows["marker"] or empty),
                            np.concatenate(rows["xy"] or [np.zeros((0, 2))]),
                            np.concatenate(rows["score"] or [np.zeros(0)]), rate, n_frames, source="keypoints")
    return detections, counts
