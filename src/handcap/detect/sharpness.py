"""How blurred the printed edges of an image are, so that a camera out of focus is named, not silent.

The networks learned a defocus of 0.3-1.2 px (:class:`handcap.synth.images.ImageStyle`) on top of the renderer's
own softness. A camera out of focus, a phone's soft pixels or motion blur go beyond that, and fewer corners and
tags are read: on rendered hands (16 scenes, full-size cameras) 75.1 % of the tags were read right sharp, 37.5 % with
a blur of 1.5 px added and 30.4 % with 2 px (2026-11-30). A large square is then read at half the image's size
(:data:`handcap.detect.pipeline.HALVABLE`); a small one cannot be, and ``handcap detect`` says which cameras are
blurred.

:func:`edge_blur` measures a step edge's blur where the detector read its blocks: across each side of a white square
the steepest slope of the grey levels is ``contrast / (sigma sqrt(2 pi))`` for a step blurred by a Gaussian of
``sigma``, with the contrast from the square's paper and its black neighbours. Measured on the true blocks of
rendered images (2026-11-30; 20 hand scenes of seed 100 and 10 photographed sheets of seed 41), per image:
0.53-1.37 px as rendered, 1.11-1.62 px with a blur of 1 px added, 1.48-1.90 px with 1.5 px and 1.75-2.22 px with 2 px.
"""

from __future__ import annotations

import cv2
import numpy as np
from scipy.spatial import cKDTree

#: Edge blur above which an image is blurred beyond what the networks learned, pixels (sigma): above every rendered
#: image measured as the networks learned them (at most 1.37 px; module docstring).
BLUR_LEARNED = 1.5
#: An unread white square is measured only if its mean side is within this factor of the spacing of the image's
#: corners (the median distance from each to its nearest): a bright object's outline can pass the white-square test
#: as one large "square" whose soft edges would name a sharp camera blurred.
SCALE_SPREAD = 3.0
#: Where across a side the slope is looked for, pixels from the side (the steepest of these).
_ACROSS = np.arange(-2.0, 2.01, 0.25)
#: Where along a side, as shares of it (away from the corners, where the neighbours meet).
_ALONG = np.array([0.3, 0.5, 0.7])


def edge_blur(image: np.ndarray, block_xy: np.ndarray) -> float:
    """The blur of an image's printed edges: the median over its blocks' sides of a step edge's Gaussian sigma.

    Parameters
    ----------
    image : ndarray (H, W)
        Grey image.
    block_xy : ndarray (B, 4, 2)
        Read blocks (white squares), their corners in order round the square, pixels.

    Returns
    -------
    float
        Sigma, pixels; NaN without a block whose paper is at least 20 grey levels lighter than its neighbours.
    """
    block_xy = np.asarray(block_xy, dtype=np.float64).reshape(-1, 4, 2)
    if len(block_xy) == 0:
        return float("nan")
    img = np.asarray(image, dtype=np.float32)
    start, end = block_xy, np.roll(block_xy, -1, axis=1)
    length = np.maximum(np.linalg.norm(end - start, axis=2), 1e-9)
    along = (end - start) / length[..., None]
    normal = np.stack([along[..., 1], -along[..., 0]], axis=-1)
    middle = (start + end) / 2
    outward = np.sum((middle - block_xy.mean(axis=1, keepdims=True)) * normal, axis=-1) >= 0
    normal = np.where(outward[..., None], normal, -normal)
    # The paper: the lightest tenth of a grid inside the square (its glyphs are ink); the black: the middle of the
    # neighbouring squares' near halves.
    share = np.linspace(0.1, 0.9, 7)
    u, v = np.meshgrid(share, share)
    first, second, last = block_xy[:, 0], block_xy[:, 1], block_xy[:, 3]
    grid = (first[:, None, None] + u[None, ..., None] * (second - first)[:, None, None]
            + v[None, ..., None] * (last - first)[:, None, None])
    paper = np.percentile(_sample(img, grid).reshape(len(block_xy), -1), 90, axis=1)
    black = np.median(_sample(img, middle + 0.3 * length[..., None] * normal), axis=1)
    contrast = paper - black
    base = start[:, :, None, :] + _ALONG[None, None, :, None] * (end - start)[:, :, None, :]
    offsets = normal[:, :, None, None, :] * _ACROSS[None, None, None, :, None]
    half = 0.5 * normal[:, :, None, None, :]
    slope = np.abs(_sample(img, base[..., None, :] + offsets + half)
                   - _sample(img, base[..., None, :] + offsets - half)).max(axis=-1)
    steepest = np.median(slope.reshape(len(block_xy), -1), axis=1)
    usable = (contrast >= 20.0) & (steepest > 1.0)
    if not usable.any():
        return float("nan")
    return float(np.median(contrast[usable] / (np.sqrt(2.0 * np.pi) * steepest[usable])))


def image_blur(image: np.ndarray, read: np.ndarray, unread: np.ndarray, corners: np.ndarray) -> float:
    """An image's :func:`edge_blur` over its read blocks and those unread white squares that are of its corners' scale.

    A blurred image reads few of its squares, so the unread ones are measured too. But not every unread "square" is
    printed: a bright object's outline against a dark background can pass the white-square test as one quad many
    times the patches' size (a held cylinder in a rendered take: 148 px where the printed squares are 6-10 px, and
    10.9 px of blur measured in an image that is sharp). The corners of printed squares lie a side apart, so an
    unread square counts only where its mean side is within :data:`SCALE_SPREAD` of the median distance from each of
    the image's corners to its nearest.

    Parameters
    ----------
    image : ndarray (H, W)
        Grey image.
    read : ndarray (B, 4, 2)
        Read blocks' corners in order round the square, pixels.
    unread : ndarray (U, 4, 2)
        Unread white squares' corners, likewise.
    corners : ndarray (K, 2)
        Every corner found in the image, pixels (the unread squares' among them).

    Returns
    -------
    float
        Sigma, pixels; NaN where nothing is measured.
    """
    read = np.asarray(read, dtype=np.float64).reshape(-1, 4, 2)
    unread = np.asarray(unread, dtype=np.float64).reshape(-1, 4, 2)
    corners = np.asarray(corners, dtype=np.float64).reshape(-1, 2)
    if len(unread) and len(corners) >= 2:
        spacing = np.median(cKDTree(corners).query(corners, 2)[0][:, 1])
        side = _mean_side(unread)
        unread = unread[(side <= SCALE_SPREAD * spacing) & (side >= spacing / SCALE_SPREAD)]
    return edge_blur(image, np.concatenate([read, unread]))


def _mean_side(quads: np.ndarray) -> np.ndarray:
    """Each quad's mean side, pixels: (B,) of (B, 4, 2)."""
    return np.linalg.norm(quads - np.roll(quads, -1, axis=1), axis=2).mean(axis=1)


def _sample(image: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Bilinear grey levels of ``image`` at ``points`` (..., 2) (x, y), mirrored beyond its border."""
    flat = np.asarray(points, dtype=np.float32).reshape(-1, 2)
    rows = -(-len(flat) // 1024)  # OpenCV maps stay under 32,767 on a side
    grid = np.zeros((rows * 1024, 2), np.float32)
    grid[:len(flat)] = flat
    grid = grid.reshape(rows, 1024, 2)
    values = cv2.remap(image, grid[..., 0], grid[..., 1], cv2.INTER_LINEAR, borderMode=cv2.BORDER_REFLECT)
    return values.reshape(-1)[:len(flat)].reshape(points.shape[:-1])
