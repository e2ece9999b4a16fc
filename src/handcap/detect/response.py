"""A camera's response to light: linear, or display-encoded (sRGB), and which one a camera's frames have.

The networks learned rendered images whose grey levels are linear in the light, raised to a power of 0.8-1.2
(:class:`handcap.synth.images.ImageStyle`), as a machine-vision camera gives them. A phone's photographs, a
webcam's and most video are display-encoded: sRGB (IEC 61966-2-1), or BT.709 for video, about the power 1/2.2
of the light. There the printed black is grey, and a blurred edge is no longer symmetric about its middle
grey, which moves the corners the refiner places. Measured with the shipped networks and checker
(2026-11-30), rendered images encoded as sRGB against as rendered, tags read right (corners' median error):

- 12 hand scenes (seed 100, full-size cameras): 72.5 % (0.262 px) against 84.4 % (0.150 px);
- 8 photographed sheets (seed 21, squares 14-30 px): 79.7 % (0.210 px) against 87.8 % (0.167 px).

Decoded back to linear light first (:func:`linear_light`) they read 84.1 % (0.150 px) and 87.7 % (0.166 px). The
hands encoded as video is (BT.709) read 76.5 % (0.263 px) as recorded and 84.7 % (0.157 px) decoded as sRGB.
Decoding images that were linear already costs as much the other way (hands 76.8 %, 0.357 px), so each camera's
response is chosen on its own frames (:class:`ResponseChoice`): its first :data:`LOOKS` frames that read a tag
are searched both ways, and the way that read more tags in them is kept for all its frames (as many tags: the
way whose blocks scored higher, as a camera whose squares are large and sharp reads as many either way; within its
first :data:`MOST_LOOKS` frames: linear, where none read a tag).
"""

from __future__ import annotations

import cv2
import numpy as np

from handcap.core.errors import HandcapError
from handcap.core.srgb import srgb_decoded

#: The responses a camera's frames may be read with: chosen on them, as recorded, or decoded from sRGB.
RESPONSES = ("auto", "linear", "srgb")
#: Frames that read a tag (either way) on which :class:`ResponseChoice` chooses a camera's response ...
LOOKS = 3
#: ... and the most frames it searches both ways: a camera that shows no tag for longer keeps what it has read
#: (linear, where it read nothing), so that a camera looking at nothing is not searched twice all take long.
MOST_LOOKS = 10


#: sRGB grey levels 0-255 to linear light (IEC 61966-2-1's decoding), as 0-255 (256,) uint8.
_SRGB_TO_LINEAR = np.clip(np.rint(255.0 * srgb_decoded(np.arange(256) / 255.0)), 0, 255).astype(np.uint8)


def linear_light(image: np.ndarray) -> np.ndarray:
    """A display-encoded (sRGB) grey image decoded to grey levels linear in the light.

    Parameters
    ----------
    image : ndarray (H, W) uint8
        sRGB grey levels.

    Returns
    -------
    ndarray (H, W) uint8
        Linear grey levels, 0-255 (white stays 255; the sRGB middle grey 128 becomes 55).
    """
    return cv2.LUT(np.ascontiguousarray(image, dtype=np.uint8), _SRGB_TO_LINEAR)


class ResponseChoice:
    """One camera's response, given or chosen on its frames (module docstring).

    Parameters
    ----------
    response : {"auto", "linear", "srgb"}
        ``auto`` chooses on the camera's first :data:`LOOKS` frames that read a tag; the others are kept.

    Attributes
    ----------
    response : str or None
        ``linear`` or ``srgb``; None while it is being chosen.
    tags : ndarray (2,) int
        Tags read in the frames looked at: as recorded, and decoded from sRGB.
    scores : ndarray (2,)
        The sums of their block scores, which decide where both ways read as many tags.
    looks : int
        Frames looked at both ways that read a tag.
    frames : int
        Frames looked at both ways.
    """

    def __init__(self, response: str = "auto"):
        if response not in RESPONSES:
            raise HandcapError(f"--response {response!r}: give one of {', '.join(RESPONSES)}")
        self.response = None if response == "auto" else response
        self.tags = np.zeros(2, np.int64)
        self.scores = np.zeros(2)
        self.looks = self.frames = 0

    def prepared(self, image: np.ndarray) -> np.ndarray:
        """``image`` (H, W) uint8 as the detector is to search it: decoded to linear light where the camera is sRGB
        (or, while it is being chosen, where its frames so far read more tags so)."""
        return linear_light(image) if self.leaning() == "srgb" else image

    def leaning(self) -> str:
        """The response chosen, or while choosing the one that read more tags so far (as many: the surer, by the
        sum of their block scores; ``linear`` where that ties too)."""
        if self.response is not None:
            return self.response
        decoded = self.tags[1] > self.tags[0] or (self.tags[1] == self.tags[0] and self.scores[1] > self.scores[0])
        return "srgb" if decoded else "linear"

    def look(self, detector, image: np.ndarray):
        """Search a frame both ways while the response is being chosen, and count the tags each read.

        Parameters
        ----------
        detector : Detector
        image : ndarray (H, W) uint8
            The frame as recorded; searched whole.

        Returns
        -------
        (ImageDetections, ImageDetections)
            The frame's detections as recorded and decoded; read them as :attr:`response` once it is chosen
            (:meth:`leaning` before).
        """
        found = detector.image(image), detector.image(linear_light(image))
        counts = np.array([len(f.block_text) for f in found])
        self.tags += counts
        self.scores += [float(f.block_score.sum()) for f in found]
        self.looks += int(counts.any())
        self.frames += 1
        if self.looks >= LOOKS or self.frames >= MOST_LOOKS:
            self.response = self.leaning()
        return found
