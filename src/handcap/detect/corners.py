"""Corner heatmap network: where the checkerboard corners of coded patches are, to a fraction of a pixel.

DexterCap's CornerNet is a U-Net costing about 6 GFLOP per 64 x 64 window
(roughly 1.5 MFLOP per pixel, anchor notes Sec. 5). Ours is a small fully
convolutional network of about 10 kFLOP per pixel: a full-resolution stem,
one stride-2 convolution, dilated convolutions at half resolution (a
receptive field of about 35 pixels, three to four squares of a patch seen at
the usual sizes), and a head that gives, for every half-resolution cell, the
logit that a corner lies in it and the corner's offset from the cell centre.
It runs on a whole image at once (no overlapping windows to stitch), and
corners are the local maxima of the heatmap above a threshold, placed by
their offsets.

Coordinates: pixel ``(x, y)`` at column x, row y, centres at integers. Cell
``(i, j)`` of the half-resolution output covers input pixels ``2i .. 2i + 1``
(rows) and ``2j .. 2j + 1`` (columns); its centre is at ``(2j + 0.5, 2i + 0.5)``.
"""

from __future__ import annotations

import cv2
import numpy as np
from scipy.special import expit
import torch
from torch import nn
from torch.nn import functional as F

from handcap.core.errors import HandcapError

#: Least corner probability kept, by default.
THRESHOLD = 0.3
#: Longest side of an image the detector takes, pixels: OpenCV warps images under 32,767 pixels on a side.
MAX_SIDE = 32766
#: Largest offset from a cell centre the head can give, pixels of the input.
MAX_OFFSET = 1.5


class CornerNet(nn.Module):
    """The corner network (see the module docstring).

    Parameters
    ----------
    width : int
        Channels at half resolution.
    stem : int
        Channels at full resolution.
    dilations : tuple of int
        One 3 x 3 convolution at half resolution per entry, with that dilation.

    Attributes
    ----------
    ranges : ndarray (P, 2) or None
        Its activations' ranges for its 8-bit twin (:mod:`handcap.detect.int8`), saved with the weights.
    """

    def __init__(self, width: int = 24, stem: int = 16, dilations=(1, 2, 4)):
        super().__init__()
        self.width, self.stem_width, self.dilations = width, stem, tuple(dilations)
        self.ranges = None
        self.stem = nn.Conv2d(1, stem, 3, padding=1)
        self.down = nn.Conv2d(stem, width, 3, stride=2, padding=1)
        self.body = nn.ModuleList([nn.Conv2d(width, width, 3, padding=d, dilation=d) for d in self.dilations])
        self.head = nn.Conv2d(width, 3, 1)
        with torch.no_grad():  # start at a corner probability of 1 % everywhere (CenterNet's prior)
            self.head.bias[0] = -4.6

    def forward(self, image: torch.Tensor) -> torch.Tensor:
        """Heatmap logits and offsets.

        Parameters
        ----------
        image : Tensor (B, 1, H, W)
            Grey levels scaled to about zero mean, unit spread (:func:`normalise`); H and W even.

        Returns
        -------
        Tensor (B, 3, H / 2, W / 2)
            Channel 0 the logit of a corner in the cell, channels 1-2 its offset (x, y) from the cell
            centre in input pixels, within +-:data:`MAX_OFFSET`.
        """
        x = F.relu(self.stem(image))
        x = F.relu(self.down(x))
        for conv in self.body:
            x = F.relu(conv(x)) + x
        out = self.head(x)
        return torch.cat([out[:, :1], MAX_OFFSET * torch.tanh(out[:, 1:])], dim=1)

    def flops_per_pixel(self) -> float:
        """Multiply-adds times two per input pixel."""
        mac = 9 * self.stem_width + 9 * self.stem_width * self.width / 4
        mac += len(self.dilations) * 9 * self.width * self.width / 4 + 3 * self.width / 4
        return 2.0 * mac

    def reach(self) -> int:
        """How far an output cell sees into the input around it, pixels (half the receptive field)."""
        return 1 + 2 + 2 * sum(self.dilations)

    def config(self) -> dict:
        """The constructor's arguments."""
        return {"width": self.width, "stem": self.stem_width, "dilations": list(self.dilations)}


def grey_levels(image: np.ndarray) -> np.ndarray:
    """An image's 5, 50 and 95 % grey levels (of every fourth pixel each way), on the 0..1 scale.

    Every stage scales contrast by these: computed once on a whole frame and passed on, they make a search
    in a part of the frame (the hand's region) see the grey levels the whole frame gives.

    Parameters
    ----------
    image : ndarray (H, W)
        uint8 (0..255) or float (0..1) grey image.

    Returns
    -------
    ndarray (3,) float64
    """
    img = np.asarray(image)
    sample = img[::4, ::4].astype(np.float32)
    if img.dtype == np.uint8:
        sample = sample / 255.0
    return np.percentile(sample, (5, 50, 95))


def normalise(image: np.ndarray, levels: np.ndarray | None = None) -> np.ndarray:
    """An 8-bit (or float 0..1) grey image as the network's input: float32, mean and spread of the image fixed.

    Parameters
    ----------
    image : ndarray (H, W)
    levels : ndarray (3,), optional
        :func:`grey_levels` to scale by (default: the image's own).

    Returns
    -------
    ndarray (H, W) float32
        ``(image - median) / (spread)``, with the spread the 5-95 % range (at least 8 grey levels of 255),
        so exposure and contrast changes do not move the input.
    """
    img = np.asarray(image, dtype=np.float32)
    if image.dtype == np.uint8:
        img = img / 255.0
    lo, mid, hi = grey_levels(image) if levels is None else levels
    return ((img - mid) / max(hi - lo, 8 / 255)).astype(np.float32)


def targets(shape, corners, sigma: float = 0.8):
    """Training targets for an image of ``shape`` with corners at ``corners`` (pixels).

    Parameters
    ----------
    shape : (int, int)
        Image height and width (even).
    corners : ndarray (K, 2)
        Visible corners, pixels.
    sigma : float
        Spread of each corner's peak, in half-resolution cells.

    Returns
    -------
    heat : ndarray (H / 2, W / 2) float32
        Gaussian skirts around each corner, exactly 1 at the cell that holds it.
    offset : ndarray (2, H / 2, W / 2) float32
        The nearest corner's offset from each cell centre, pixels.
    near : ndarray (H / 2, W / 2) bool
        Cells within one cell of a corner (where the offset is learned).
    """
    h, w = shape[0] // 2, shape[1] // 2
    heat = np.zeros((h, w), np.float32)
    offset = np.zeros((2, h, w), np.float32)
    near = np.zeros((h, w), bool)
    xy = np.asarray(corners, dtype=np.float64).reshape(-1, 2)
    if len(xy) == 0:
        return heat, offset, near
    cx, cy = (xy[:, 0] - 0.5) / 2, (xy[:, 1] - 0.5) / 2  # in cell units, cell centres at integers
    # Every corner's 6 x 6 cells around it (K, 6, 6), those inside the map kept.
    ii = (np.floor(cy).astype(int) - 2)[:, None, None] + np.arange(6)[None, :, None]
    jj = (np.floor(cx).astype(int) - 2)[:, None, None] + np.arange(6)[None, None, :]
    ii, jj = np.broadcast_arrays(ii, jj)
    dx, dy = cx[:, None, None] - jj, cy[:, None, None] - ii
    d2 = dx ** 2 + dy ** 2
    inside = (ii >= 0) & (ii < h) & (jj >= 0) & (jj < w)
    cell = (ii * w + jj)[inside]
    np.maximum.at(heat.reshape(-1), cell, np.exp(-d2 / (2 * sigma ** 2))[inside].astype(np.float32))
    pi, pj = np.rint(cy).astype(int), np.rint(cx).astype(int)
    own = (pi >= 0) & (pi < h) & (pj >= 0) & (pj < w)
    heat[pi[own], pj[own]] = 1.0  # the corner's own cell is the peak (the focal loss's positive)
    # The offset of the nearest corner within one cell (the first corner on a tie).
    close = inside & (d2 <= 1.0 + 1e-9)
    which = np.broadcast_to(np.arange(len(xy))[:, None, None], d2.shape)[close]
    cell, dist = (ii * w + jj)[close], d2[close]
    order = np.lexsort((which, dist, cell))
    first = order[np.diff(cell[order], prepend=-1) != 0]
    offset[0].reshape(-1)[cell[first]] = 2 * dx[close][first]
    offset[1].reshape(-1)[cell[first]] = 2 * dy[close][first]
    near.reshape(-1)[cell[first]] = True
    return heat, offset, near


def corner_loss(output: torch.Tensor, heat: torch.Tensor, offset: torch.Tensor, near: torch.Tensor) -> torch.Tensor:
    """Focal loss on the heatmap (CenterNet's, peaks of 1 and their Gaussian skirts) plus L1 on the offsets.

    Parameters
    ----------
    output : Tensor (B, 3, h, w)
    heat : Tensor (B, h, w)
    offset : Tensor (B, 2, h, w)
    near : Tensor (B, h, w) bool

    Returns
    -------
    Tensor ()
    """
    logit = output[:, 0]
    p = torch.sigmoid(logit).clamp(1e-4, 1 - 1e-4)
    peak = heat > 0.99
    pos = -((1 - p) ** 2) * torch.log(p) * peak
    neg = -((1 - heat) ** 4) * (p ** 2) * torch.log(1 - p) * (~peak)
    n = peak.sum().clamp(min=1)
    focal = (pos.sum() + neg.sum()) / n
    if near.any():
        l1 = (output[:, 1:] - offset).abs().sum(dim=1)[near].mean()
    else:
        l1 = output.sum() * 0
    return focal + l1


def find_corners(heatmap: np.ndarray, offsets: np.ndarray, threshold: float = 0.3) -> tuple[np.ndarray, np.ndarray]:
    """Corners as the local maxima of a heatmap, placed by their offsets.

    Parameters
    ----------
    heatmap : ndarray (h, w)
        Probabilities (after the sigmoid).
    offsets : ndarray (2, h, w)
        Pixels from each cell centre.
    threshold : float
        Least probability of a corner.

    Returns
    -------
    xy : ndarray (K, 2)
        Pixels of the input image.
    score : ndarray (K,)
    """
    heat = torch.as_tensor(heatmap)[None, None]
    peak = (F.max_pool2d(heat, 3, stride=1, padding=1) == heat)[0, 0].numpy() & (heatmap >= threshold)
    i, j = np.nonzero(peak)
    xy = np.c_[2 * j + 0.5 + offsets[0, i, j], 2 * i + 0.5 + offsets[1, i, j]]
    return xy, heatmap[i, j]


def detect_corners(net: CornerNet, image: np.ndarray, *, threshold: float = 0.3, tile: int = 512,
                   halo: int | None = None, levels: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Run the corner network over a whole image, in tiles with a halo, and return its corners.

    Parameters
    ----------
    net : CornerNet
    image : ndarray (H, W)
        uint8 or float grey image.
    threshold : float
    tile : int
        Tile side, pixels (even); memory grows with its square (512 is the fastest on a laptop CPU: the
        tile stays in cache).
    halo : int, optional
        Context kept around each tile and dropped from its output, pixels: more than the network's
        :meth:`~CornerNet.reach` (default: 32, or the reach rounded up to 16 where it is more).
    levels : ndarray (3,), optional
        :func:`grey_levels` of the whole frame when ``image`` is a part of it (default: the image's own).

    Returns
    -------
    xy : ndarray (K, 2)
        Pixels.
    score : ndarray (K,)
    """
    if image.ndim != 2 or min(image.shape) < 8:
        raise HandcapError(f"a grey image of at least 8 x 8 pixels is needed, got shape {image.shape}")
    if max(image.shape) > MAX_SIDE:
        raise HandcapError(f"an image of {image.shape[1]} x {image.shape[0]} pixels: the detector takes at most "
                           f"{MAX_SIDE} pixels on a side (OpenCV's warps); scale it down or cut it into parts first")
    if halo is None:
        halo = max(32, -(-net.reach() // 16) * 16)
    img = normalise(image, levels)
    h, w = img.shape
    ph, pw = (-h) % 2, (-w) % 2
    img = np.pad(img, ((0, ph), (0, pw)), mode="edge")
    busy = _contrast_cells(img)
    heat = np.zeros((img.shape[0] // 2, img.shape[1] // 2), np.float32)
    offs = np.zeros((2,) + heat.shape, np.float32)
    # Channels-last convolutions run about a third faster on the CPU (measured in benchmarks/detect.py).
    net.eval().to(memory_format=torch.channels_last)
    with torch.inference_mode():
        for y0 in range(0, img.shape[0], tile):
            for x0 in range(0, img.shape[1], tile):
                ya, xa = max(0, y0 - halo), max(0, x0 - halo)
                yb, xb = min(img.shape[0], y0 + tile + halo), min(img.shape[1], x0 + tile + halo)
                if not busy[ya // CELL:-(-yb // CELL), xa // CELL:-(-xb // CELL)].any():
                    continue  # no contrast a printed corner needs: its heatmap stays 0
                part = torch.from_numpy(np.ascontiguousarray(img[ya:yb, xa:xb]))[None, None]
                out = net(part.contiguous(memory_format=torch.channels_last))[0].contiguous().numpy()
                cy0, cx0 = (y0 - ya) // 2, (x0 - xa) // 2
                ch = min(tile, img.shape[0] - y0) // 2
                cw = min(tile, img.shape[1] - x0) // 2
                heat[y0 // 2:y0 // 2 + ch, x0 // 2:x0 // 2 + cw] = expit(out[0, cy0:cy0 + ch, cx0:cx0 + cw])
                offs[:, y0 // 2:y0 // 2 + ch, x0 // 2:x0 // 2 + cw] = out[1:, cy0:cy0 + ch, cx0:cx0 + cw]
    xy, score = find_corners(heat, offs, threshold)
    keep = (xy[:, 0] <= w - 0.5) & (xy[:, 1] <= h - 0.5)
    return xy[keep], score[keep]


#: Side of the cells whose grey range decides where the network runs, pixels.
CELL = 32
#: Least grey range of a cell (max - min of its 4 x 4 means, in the normalised image: a share of the image's 5-95 %
#: spread) where a printed corner can be: the least contrast the block stage accepts between a white square and
#: its black neighbours (:data:`handcap.detect.blocks.MIN_CONTRAST`). On rendered hands every corner's cell had
#: twice that; a plain backdrop has a fraction of it.
MIN_RANGE = 0.15


def _contrast_cells(img: np.ndarray) -> np.ndarray:
    """Which :data:`CELL`-pixel cells of a normalised image have a grey range of at least :data:`MIN_RANGE`.

    The range is taken over 4 x 4 pixel means (sensor noise averages out; a printed square of 8 pixels or more
    keeps its grey). Returns a bool array of ceil(H / CELL) x ceil(W / CELL) cells.
    """
    h, w = img.shape
    ch, cw = -(-h // CELL), -(-w // CELL)
    padded = np.pad(img, ((0, ch * CELL - h), (0, cw * CELL - w)), mode="edge")
    small = cv2.resize(padded, (cw * CELL // 4, ch * CELL // 4), interpolation=cv2.INTER_AREA)
    cells = small.reshape(ch, CELL // 4, cw, CELL // 4)
    return cells.max(axis=(1, 3)) - cells.min(axis=(1, 3)) >= MIN_RANGE
