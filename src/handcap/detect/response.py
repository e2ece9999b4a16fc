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
are searched both ways, and the way that read more tags in them is kept for all its frames (within its first
:data:`MOST_LOOKS` frames: linear, where none read a tag).

A camera whose squares are large and sharp reads about as many tags either way, and there the counts do not
tell (a rendered linear camera read 58 tags both ways, and decoded its corners' median error was 0.276 px
against 0.158 px). Where the counts are within :data:`NEAR` of each other, the ink decides: printed black
reflects a few per cent of the paper's light, and the networks learned renders whose ink lies at 0.02-0.2 of
the paper (:class:`handcap.synth.pages.PageLook`), so the way whose read blocks show the ink nearer (in ratio)
to the middle of that range, :data:`INK_LEARNED`, is kept (:func:`block_contrast`). Measured on 40 cameras of
three rendered hand scenes each (2026-11-30), the ink in the way that reads right lay at 0.037-0.113 of the
paper, decoding a linear camera put it at 0.005-0.017 and reading an sRGB one as recorded at 0.20-0.37; all 40
were chosen right, 4 of them by the ink.
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
#: Tag counts of the two ways within this share of the larger are as many: the ink in the blocks decides.
NEAR = 0.05
#: The ink's grey level relative to the paper's that the networks learned, the middle (in ratio) of the rendered
#: sheets' 0.02-0.2 (:class:`handcap.synth.pages.PageLook`): a way whose ink lies nearer it is the camera's.
INK_LEARNED = float(np.sqrt(0.02 * 0.2))
#: Unit-square points a block's paper (its white square, the glyphs' ink among it) is sampled at ...
_PAPER = np.stack(np.meshgrid(np.linspace(0.15, 0.85, 7), np.linspace(0.15, 0.85, 7)), -1).reshape(-1, 2)
#: ... and the points of the four black squares (or margins) across its sides, a quarter of a side beyond each:
#: top, right, bottom, left (5 each).
_ALONG = np.linspace(0.3, 0.7, 5)
_INK = np.concatenate([np.c_[_ALONG, np.full(5, -0.25)], np.c_[np.full(5, 1.25), _ALONG],
                       np.c_[_ALONG, np.full(5, 1.25)], np.c_[np.full(5, -0.25), _ALONG]])


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


def block_contrast(image: np.ndarray, blocks: np.ndarray) -> np.ndarray:
    """The ink's grey level relative to the paper's at each read block: the median of the black squares across
    its four sides over the bright end (90th percentile) of its own white square.

    Parameters
    ----------
    image : ndarray (H, W) uint8
        The image the blocks were read in.
    blocks : ndarray (B, 4, 2)
        Their corners in reading order (top-left, top-right, bottom-right, bottom-left), pixels.

    Returns
    -------
    ndarray (B,)
        Ink over paper, NaN where a block is smaller than 2 px a side, its paper is darker than 20 grey levels,
        or fewer than half its samples lie in the image.
    """
    blocks = np.asarray(blocks, dtype=np.float64).reshape(-1, 4, 2)
    out = np.full(len(blocks), np.nan)
    unit = np.float32([[0, 0], [1, 0], [1, 1], [0, 1]])
    points = np.concatenate([_PAPER, _INK])
    lifted = np.c_[points, np.ones(len(points))]
    h, w = image.shape
    for b, quad in enumerate(blocks):
        if not np.isfinite(quad).all() or min(np.linalg.norm(quad - np.roll(quad, 1, axis=0), axis=1)) < 2.0:
            continue
        mapped = lifted @ cv2.getPerspectiveTransform(unit, quad.astype(np.float32)).T
        with np.errstate(divide="ignore", invalid="ignore"):
            xy = np.rint(mapped[:, :2] / mapped[:, 2:]).astype(np.int64, copy=False)
        inside = (xy[:, 0] >= 0) & (xy[:, 1] >= 0) & (xy[:, 0] < w) & (xy[:, 1] < h) & (mapped[:, 2] > 0)
        if inside.sum() < len(points) / 2:
            continue
        grey = np.full(len(points), np.nan)
        grey[inside] = image[xy[inside, 1], xy[inside, 0]]
        paper = np.nanpercentile(grey[:len(_PAPER)], 90)
        sides = [np.nanmedian(side) for side in grey[len(_PAPER):].reshape(4, -1) if np.isfinite(side).sum() >= 3]
        if paper >= 20 and sides:
            out[b] = float(np.median(sides)) / paper
    return out


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
        The sums of their block scores, which decide where both ways read as many tags and no block shows its ink.
    ink : tuple of 2 lists
        The ink relative to the paper at every block read each way (:func:`block_contrast`), which decides where
        both ways read about as many tags (within :data:`NEAR`).
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
        self.ink = ([], [])
        self.looks = self.frames = 0

    def prepared(self, image: np.ndarray) -> np.ndarray:
        """``image`` (H, W) uint8 as the detector is to search it: decoded to linear light where the camera is sRGB
        (or, while it is being chosen, where its frames so far read more tags so)."""
        return linear_light(image) if self.leaning() == "srgb" else image

    def leaning(self) -> str:
        """The response chosen, or while choosing the one that read more tags so far; where both read about as
        many (within :data:`NEAR`), the one whose blocks show the ink nearer :data:`INK_LEARNED`; where no block
        shows it, the surer by the sum of their block scores (``linear`` where that ties too)."""
        if self.response is not None:
            return self.response
        if abs(int(self.tags[1]) - int(self.tags[0])) > NEAR * max(self.tags):
            return "srgb" if self.tags[1] > self.tags[0] else "linear"
        ink = [np.nanmedian(v) if np.isfinite(v).any() else np.nan for v in map(np.asarray, self.ink)]
        if np.isfinite(ink).all() and min(ink) > 0:
            far = np.abs(np.log(np.asarray(ink) / INK_LEARNED))
            return "srgb" if far[1] < far[0] else "linear"
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
        decoded = linear_light(image)
        found = detector.image(image), detector.image(decoded)
        counts = np.array([len(f.block_text) for f in found])
        self.tags += counts
        self.scores += [float(f.block_score.sum()) for f in found]
        for ink, searched, f in zip(self.ink, (image, decoded), found):
            ink.extend(block_contrast(searched, f.block_xy).tolist())
        self.looks += int(counts.any())
        self.frames += 1
        if self.looks >= LOOKS or self.frames >= MOST_LOOKS:
            self.response = self.leaning()
        return found
