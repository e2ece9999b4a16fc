"""Sub-pixel refinement of corners: a small network on a full-resolution crop around each candidate.

The corner network (:mod:`~handcap.detect.corners`) sees the image at half
resolution and places a corner to about a third of a pixel. The refiner looks
again, at full resolution, at a 17 x 17 pixel crop centred on the pixel
nearest each candidate, and gives two things: the corner's offset from that
pixel, and the probability that a printed corner is there at all. It looks at
each crop in its eight turns and mirrors and averages what it says (it was
trained on all eight). It costs about 3.4 MFLOP per candidate and view (a few
hundred candidates per image), not per pixel, so the corner network can run at
a low threshold (more corners found) while the refiner turns away what is not a
corner (glyph strokes, skin creases, edges of occluders).

Classical refiners do worse here: OpenCV's ``cornerSubPix`` and a quadratic
saddle fit assume a clean X-corner, while most corners of a patch are L-shaped
(a white square against the black margin) and glyph strokes reach into the
window; on rendered hands both moved corners away from the truth (measured
while building this module: 0.33-0.35 px median against the corner network's
0.32).

Coordinates: pixel ``(x, y)`` at column x, row y, centres at integers (as in
:mod:`~handcap.detect.corners`).
"""

from __future__ import annotations

import numpy as np
import torch
from scipy.spatial import cKDTree
from scipy.special import expit
from torch import nn
from torch.nn import functional as F

from handcap.core.errors import HandcapError
from handcap.detect.corners import MIN_RANGE, THRESHOLD, CornerNet, detect_corners, grey_levels

#: Crop half-size: crops are ``2 * RADIUS + 1`` pixels square.
RADIUS = 8
#: Largest offset the refiner gives, pixels.
MAX_SHIFT = 2.0
#: Least corner-network probability of a candidate the refiner looks at.
CANDIDATES = 0.1
#: Least refiner probability of a corner kept, by default.
REFINED_THRESHOLD = 0.5
#: Corners closer than this to the image's edge are dropped, pixels: an edge that meets the border looks
#: like a corner there (the crop is mirrored beyond it), and the true corner may lie outside.
BORDER = 2.0
#: Candidates whose first view gives less than this share of the least probability kept get no other views.
PRESCREEN = 0.5
#: Candidates closer than this after refinement are one corner (the better scored is kept), pixels.
MERGE_PX = 1.0
#: A candidate farther than this from a hidden corner, and not at a visible one, is an occluder's edge for the
#: refiner's training (:func:`candidate_negatives`), pixels: the distance past which a named corner is wrong in
#: :func:`handcap.detect.evaluation.evaluate_detector`.
OCCLUDED_PX = 2.0


class CornerRefiner(nn.Module):
    """The refinement network (see the module docstring).

    Parameters
    ----------
    width : int
        Channels of the first layers (doubled after each stride-2 convolution).

    Attributes
    ----------
    ranges : ndarray (P, 2) or None
        Its activations' ranges for its 8-bit twin (:mod:`handcap.detect.int8`), saved with the weights.
    """

    def __init__(self, width: int = 16):
        super().__init__()
        self.width = width
        self.ranges = None
        w = width
        self.features = nn.Sequential(
            nn.Conv2d(1, w, 3, padding=1), nn.ReLU(),
            nn.Conv2d(w, 2 * w, 3, stride=2, padding=1), nn.ReLU(),  # 9 x 9
            nn.Conv2d(2 * w, 2 * w, 3, padding=1), nn.ReLU(),
            nn.Conv2d(2 * w, 4 * w, 3, stride=2, padding=1), nn.ReLU(),  # 5 x 5
        )
        self.head = nn.Sequential(nn.Flatten(), nn.Linear(4 * w * 25, 64), nn.ReLU(), nn.Linear(64, 3))

    def forward(self, crops: torch.Tensor) -> torch.Tensor:
        """Corner logit and offset of each crop.

        Parameters
        ----------
        crops : Tensor (N, 1, 17, 17)
            Normalised crops (:func:`crops_at`).

        Returns
        -------
        Tensor (N, 3)
            Column 0 the logit that a corner lies within about 1.5 pixels of the crop's centre, columns 1-2
            its offset (x, y) from the centre pixel, pixels, within +-:data:`MAX_SHIFT`.
        """
        out = self.head(self.features(crops))
        return torch.cat([out[:, :1], MAX_SHIFT * torch.tanh(out[:, 1:])], dim=1)

    def config(self) -> dict:
        """The constructor's arguments."""
        return {"width": self.width}


def crops_at(image: np.ndarray, centres: np.ndarray) -> np.ndarray:
    """Crops of ``image`` centred on integer pixels, each normalised to its own grey levels.

    Parameters
    ----------
    image : ndarray (H, W)
        uint8 or float grey image.
    centres : ndarray (N, 2) int
        Pixel (x, y) of each crop's centre; the image is mirrored beyond its border.

    Returns
    -------
    ndarray (N, 17, 17) float32
        See :func:`normalise_crops`.
    """
    return normalise_crops(raw_crops(np.asarray(image), centres))


def raw_crops(image: np.ndarray, centres: np.ndarray) -> np.ndarray:
    """The raw pixels around each centre, the image mirrored beyond its border (:func:`crops_at` unnormalised).

    Parameters
    ----------
    image : ndarray (H, W)
    centres : ndarray (N, 2) int
        Pixel (x, y) of each crop's centre.

    Returns
    -------
    ndarray (N, 17, 17)
        Of the image's dtype.
    """
    span = np.arange(-RADIUS, RADIUS + 1)
    c = np.asarray(centres, dtype=int).reshape(-1, 2)
    rows = _mirror(c[:, 1, None] + span[None], image.shape[0])
    cols = _mirror(c[:, 0, None] + span[None], image.shape[1])
    return image[rows[:, :, None], cols[:, None, :]]


def _mirror(index: np.ndarray, n: int) -> np.ndarray:
    """Indices reflected into ``0 .. n - 1`` (the edge pixel not repeated, as numpy's "reflect" pad)."""
    period = 2 * (n - 1) if n > 1 else 1
    folded = np.mod(index, period)
    return np.where(folded > n - 1, period - folded, folded).clip(0, n - 1)


def normalise_crops(crops: np.ndarray) -> np.ndarray:
    """Crops as the refiner's input: each one's median removed and divided by its spread.

    Parameters
    ----------
    crops : ndarray (N, 17, 17)
        Grey levels (uint8, or float 0..1).

    Returns
    -------
    ndarray (N, 17, 17) float32
        ``(crop - median) / spread`` with the spread the crop's 5-95 % range (at least 8 grey levels of
        255), so the local exposure and contrast do not move the input.
    """
    out = np.asarray(crops, dtype=np.float32)
    if crops.dtype == np.uint8:
        out = out / 255.0
    lo, mid, hi = np.percentile(out.reshape(len(out), -1), (5, 50, 95), axis=1)
    spread = np.maximum(hi - lo, 8 / 255)
    return ((out - mid[:, None, None]) / spread[:, None, None]).astype(np.float32)


def refine_corners(net: CornerRefiner, image: np.ndarray, xy: np.ndarray, *, min_score: float = REFINED_THRESHOLD,
                   views: int = 8, batch: int = 256, levels: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Refine candidate corners and keep those the refiner believes, one per corner.

    Parameters
    ----------
    net : CornerRefiner
    image : ndarray (H, W)
    xy : ndarray (K, 2)
        Candidates, pixels (from :func:`~handcap.detect.corners.detect_corners` at a low threshold).
    min_score : float
        Least probability of a corner to keep a candidate.
    views : int
        How many of the crop's eight turns and mirrors the refiner looks at (1 to 8); their offsets,
        turned back, and their logits are averaged. The refiner was trained on all eight, so averaging
        them cancels what it learned unevenly per direction: on held-out rendered hands the median error
        fell from 0.180 to 0.153 px with eight (measured while building this).
    batch : int
        Crops per network call.
    levels : ndarray (3,), optional
        :func:`~handcap.detect.corners.grey_levels` of the whole frame when ``image`` is a part of it.

    Returns
    -------
    xy : ndarray (K', 2)
        Refined corners, pixels; candidates that end within :data:`MERGE_PX` of a better one, or within
        :data:`BORDER` of the image's edge, are dropped.
    score : ndarray (K',)
        The refiner's probability of each.
    """
    xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
    if len(xy) == 0:
        return xy, np.zeros(0)
    if not 1 <= views <= 8:
        raise HandcapError(f"views must be 1 to 8, got {views}")
    centres = np.rint(xy).astype(int)
    keep = _contrasted(image, centres, levels)
    xy, centres = xy[keep], centres[keep]
    if len(xy) == 0:
        return xy, np.zeros(0)
    logit, offset = _views(net, image, centres, range(1), batch)
    seen = np.ones(len(xy))
    if views > 1:  # the other views only where one view leaves a chance (most candidates are far from it)
        near = np.flatnonzero(expit(logit) >= PRESCREEN * min_score)
        more = _views(net, image, centres[near], range(1, views), batch)
        logit[near], offset[near], seen[near] = logit[near] + more[0], offset[near] + more[1], views
    score, refined = expit(logit / seen), centres + offset / seen[:, None]
    # A corner that lies nearer another pixel than the crop's centre is looked at again from that pixel
    # (the refiner is surest near the centre); its probability stays the first look's. On held-out rendered
    # hands this took the RMS error from 0.343 to 0.327 px.
    again = np.flatnonzero((score >= min_score) & (np.rint(refined) != centres).any(axis=1))
    if len(again):
        moved = np.rint(refined[again]).astype(int)
        refined[again] = moved + _views(net, image, moved, range(views), batch)[1] / views
    h, w = np.asarray(image).shape[:2]
    inside = (refined >= BORDER).all(axis=1) & (refined[:, 0] <= w - 1 - BORDER) & (refined[:, 1] <= h - 1 - BORDER)
    keep = (score >= min_score) & inside
    refined, score = refined[keep], score[keep]
    return _merge(refined, score)


def _contrasted(image: np.ndarray, centres: np.ndarray, levels: np.ndarray | None = None) -> np.ndarray:
    """Which candidates have around them the contrast a printed corner needs (N,) bool.

    The test of the corner network's cells (:data:`~handcap.detect.corners.MIN_RANGE` of the image's 5-95 %
    spread, over 4 x 4 pixel means, where sensor noise averages out), made on the 16 x 16 pixels at each
    candidate. A noisy backdrop passes the cells' test in places and gives the network thousands of weak
    candidates (19,000 on one rendered 5 MP frame, where 300 corners are printed); on rendered hands every
    candidate within 2 px of a printed corner had at least 0.2.
    """
    img = np.asarray(image)
    lo, _, hi = grey_levels(img) if levels is None else levels
    spread = max(hi - lo, 8 / 255) * (255.0 if img.dtype == np.uint8 else 1.0)
    crops = raw_crops(img, centres)[:, 1:, 1:].astype(np.float32)
    means = crops.reshape(len(crops), 4, 4, 4, 4).mean(axis=(2, 4))
    return means.max(axis=(1, 2)) - means.min(axis=(1, 2)) >= MIN_RANGE * spread


def turned_crops(crops: np.ndarray, which) -> np.ndarray:
    """Crops seen in the turns and mirrors ``which`` (of 0-7: bit 0 mirrors x, bit 1 mirrors y, bit 2 swaps them).

    Parameters
    ----------
    crops : ndarray (N, S, S)
    which : iterable of int

    Returns
    -------
    ndarray (V * N, S, S)
        The views, one after another (contiguous).
    """
    seen = []
    for view in which:
        flip_x, flip_y, swap = view & 1, view & 2, view & 4
        turned = crops[:, :, ::-1] if flip_x else crops
        turned = turned[:, ::-1, :] if flip_y else turned
        seen.append(turned.transpose(0, 2, 1) if swap else turned)
    return np.ascontiguousarray(np.concatenate(seen))


def refiner_views(net: CornerRefiner, image: np.ndarray, centres: np.ndarray, views: int = 8,
                  batch: int = 256) -> tuple[np.ndarray, np.ndarray]:
    """What the refiner says of the crops at integer pixels, averaged over their turns and mirrors.

    Parameters
    ----------
    net : CornerRefiner
    image : ndarray (H, W)
    centres : ndarray (N, 2) int
        The crops' centres, pixels ``(x, y)``.
    views : int
        How many of the eight turns and mirrors (1 to 8).
    batch : int
        Crops per network call.

    Returns
    -------
    logit : ndarray (N,)
        The corner's logit (``expit`` of it: the probability of a printed corner).
    offset : ndarray (N, 2)
        The corner's offset from each centre, pixels.
    """
    logit, offset = _views(net, image, np.asarray(centres, dtype=np.int64).reshape(-1, 2), range(views), batch)
    return logit / views, offset / views


def _views(net: CornerRefiner, image: np.ndarray, centres: np.ndarray, which: range, batch: int):
    """The refiner on crops at integer ``centres`` (N, 2), seen in the turns and mirrors ``which`` (of 0-7).

    Returns the sums over those views of the corner logit (N,) and of the offset turned back into the
    image's frame (N, 2), pixels; divide by ``len(which)`` for the average.
    """
    logit, offset = np.zeros(len(centres)), np.zeros((len(centres), 2))
    if len(centres) == 0 or len(which) == 0:
        return logit, offset
    crops = crops_at(image, centres)
    seen = torch.from_numpy(turned_crops(crops, which))[:, None]
    # Channels-last and batches of a few hundred crops run fastest on the CPU (measured: ~1.5x NCHW).
    net.eval().to(memory_format=torch.channels_last)
    with torch.inference_mode():
        out = np.concatenate([net(seen[k:k + batch].contiguous(memory_format=torch.channels_last)).numpy()
                              for k in range(0, len(seen), batch)]).astype(np.float64)
    out = out.reshape(len(which), len(crops), 3)
    for k, view in enumerate(which):
        flip_x, flip_y, swap = view & 1, view & 2, view & 4
        back = out[k, :, 1:][:, ::-1] if swap else out[k, :, 1:]
        offset += back * [-1 if flip_x else 1, -1 if flip_y else 1]
    return out[..., 0].sum(axis=0), offset


def locate_corners(corner_net: CornerNet, refiner: CornerRefiner | None, image: np.ndarray,
                   threshold: float | None = None, levels: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """The detector's corners in one image: the corner network's, refined when a refiner is given.

    Parameters
    ----------
    corner_net : CornerNet
    refiner : CornerRefiner or None
        With it, the corner network's candidates down to :data:`CANDIDATES` are refined and kept where the
        refiner's probability reaches ``threshold``; without it, the corner network's corners down to
        ``threshold``.
    image : ndarray (H, W)
    threshold : float, optional
        Least corner probability (default: :data:`REFINED_THRESHOLD` with a refiner, else
        :data:`~handcap.detect.corners.THRESHOLD`).
    levels : ndarray (3,), optional
        :func:`~handcap.detect.corners.grey_levels` of the whole frame when ``image`` is a part of it.

    Returns
    -------
    xy : ndarray (K, 2)
        Pixels.
    score : ndarray (K,)
    """
    if refiner is None:
        return detect_corners(corner_net, image, threshold=THRESHOLD if threshold is None else threshold,
                              levels=levels)
    xy, _ = detect_corners(corner_net, image, threshold=CANDIDATES, levels=levels)
    return refine_corners(refiner, image, xy, min_score=REFINED_THRESHOLD if threshold is None else threshold,
                          levels=levels)


def _merge(xy: np.ndarray, score: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Drop every corner within :data:`MERGE_PX` of a better scored one."""
    if len(xy) < 2:
        return xy, score
    pairs = cKDTree(xy).query_pairs(MERGE_PX, output_type="ndarray")
    if len(pairs) == 0:
        return xy, score
    order = np.argsort(-score, kind="stable")
    rank = np.empty(len(xy), int)
    rank[order] = np.arange(len(xy))
    beaten = {}  # corner -> its worse-scored neighbours
    for a, b in pairs:
        best, worst = (a, b) if rank[a] < rank[b] else (b, a)
        beaten.setdefault(best, []).append(worst)
    keep = np.ones(len(xy), bool)
    for q in order:  # greedy in score order: a corner suppresses others only while it is itself kept
        if keep[q] and q in beaten:
            keep[beaten[q]] = False
    return xy[keep], score[keep]


def false_candidates(corner_net: CornerNet, scene, threshold: float = 0.05, far: float = 3.0) -> np.ndarray:
    """The corner network's candidates in a scene that are no printed corner: (N, 2) pixels.

    Those over ``far`` pixels from every printed corner, hidden ones included (a corner the truth calls
    hidden may still show at a grazing angle): the first of :func:`candidate_negatives`. The threshold is
    below the detector's (:data:`CANDIDATES`): more, and harder, negatives.

    Parameters
    ----------
    corner_net : CornerNet
    scene : Scene
    threshold : float
        Least corner probability of a candidate.
    far : float
        As :func:`candidate_negatives`.
    """
    return candidate_negatives(detect_corners(corner_net, scene.image, threshold=threshold)[0], scene, far)[0]


def candidate_negatives(candidates: np.ndarray, scene, far: float = 3.0,
                        near: float = OCCLUDED_PX) -> tuple[np.ndarray, np.ndarray]:
    """The candidate corners in a scene that the refiner must turn away, in two kinds.

    * false: over ``far`` pixels from every printed corner, hidden ones included;
    * occluded: within ``far`` of a printed corner that the truth calls hidden, but over ``near`` from it and
      over ``far`` from every visible corner. An occluder's edge (a finger, the hand's own outline) crossing
      a white square's side a few pixels from its hidden corner makes a junction that looks like the corner;
      a block read through it names a corner two to five pixels from where that corner is.

    A scene without the projections of its hidden corners (``scene.projected``) has no occluded candidates.

    Parameters
    ----------
    candidates : ndarray (K, 2)
        The corner network's candidates, pixels.
    scene : Scene
    far : float
        Least distance of a false candidate from every printed corner, and of an occluded one from every
        visible corner, pixels.
    near : float
        Least distance of an occluded candidate from its hidden corner, pixels.

    Returns
    -------
    false, occluded : ndarrays (N, 2), (M, 2)
        Pixels.
    """
    xy = np.asarray(candidates, dtype=np.float64).reshape(-1, 2)
    printed = np.array(list(scene.projected.values())) if scene.projected else scene.corners
    none = np.zeros((0, 2))
    if len(xy) == 0 or len(printed) == 0:
        return xy, none
    distance, nearest = cKDTree(printed).query(xy)
    if not scene.projected or len(scene.corners) == 0:
        return xy[distance > far], none
    seen = set(scene.corner_names)
    hidden = np.array([name not in seen for name in scene.projected])
    occluded = hidden[nearest] & (distance > near) & (distance <= far) & (cKDTree(scene.corners).query(xy)[0] > far)
    return xy[distance > far], xy[occluded]


def refiner_loss(output: torch.Tensor, is_corner: torch.Tensor, offset: torch.Tensor) -> torch.Tensor:
    """Binary cross-entropy on the corner logit plus L1 on the offsets of true corners.

    Parameters
    ----------
    output : Tensor (N, 3)
    is_corner : Tensor (N,)
    offset : Tensor (N, 2)

    Returns
    -------
    Tensor ()
    """
    bce = F.binary_cross_entropy_with_logits(output[:, 0], is_corner)
    pos = is_corner > 0.5
    l1 = (output[pos, 1:] - offset[pos]).abs().sum(dim=1).mean() if pos.any() else output.sum() * 0
    return bce + l1

