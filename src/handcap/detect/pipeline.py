"""The coded-patch detector on one image: corners, blocks, tags, votes, named corners.

:class:`Detector` chains the stages: the corner network
(:mod:`~handcap.detect.corners`), the sub-pixel refiner that also turns away
false candidates (:mod:`~handcap.detect.refine`), block assembly (:mod:`~handcap.detect.blocks`),
the block reader (:mod:`~handcap.detect.reader`) and, given a template,
the vote over its patches and the corner names (:mod:`~handcap.detect.voting`).
Without a template it reports blocks and their corners only (a single photo of
patches from an unknown sheet), and only the readings sure enough to stand alone in a font the reader
never saw (:data:`UNSEEN_FONT_GATE`).

The networks learned squares of 9-40 pixels. A photograph taken close to the patches shows them larger
(a phone 15-30 cm from a 5 mm checker: 60-130 px), where the glyphs' strokes have corners of their own and
the blocks fall apart: on rendered photographs of a printed sheet (seed 11, four per size), 1.4 % of the
visible tags were read with 60 px squares, 22 % with 90 px and 6.6 % with 130 px. So where an image gives no
block, or blocks whose sides have a median over :data:`LARGE_SQUARE`, it is
searched again halved (area averaging), and halved again while that holds and the image keeps
:data:`COARSEST` pixels; the level that reads the most tags is kept, its positions mapped back to the
image's pixels. The same photographs then gave 99.8, 95.5 and 97.9 % (one tag of 487 wrong: read right,
one corner of its foreshortened block 2.1 px off); frames whose squares are small (the rig's cameras) are
searched once, as before (the benchmark's hand scenes give the same figures). A halved level places its
corners to a fraction of its own pixels, which are two, four or eight of the image's: so on the way back each
corner is placed again by the refiner in every finer level whose squares are at most :data:`FINER_SIDE`
(:func:`look_again`), and the corners of 150-250 px squares are named within 0.08-0.12 px (median) of the truth
instead of 0.25-0.32 px. An image whose blocks are :data:`HALVABLE` px or more is searched halved as well, where
a blur beyond what the networks learned is halved too; there a level of squares they learned gives way only to
one reading :data:`CLEARLY_MORE` times its tags (sheets of 20-30 px squares blurred by 2 px: 67 -> 93 % read).
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass, field, replace

import cv2
import numpy as np
from scipy.spatial import cKDTree
from scipy.special import expit

from handcap.core.errors import HandcapError
from handcap.patterns.alphabet import ALPHABET, check_alphabet, lookalikes
from handcap.detect.blocks import candidate_quads, white_blocks
from handcap.detect.corners import CornerNet, grey_levels
from handcap.patterns.pattern import Pattern
from handcap.detect.reader import GLYPHS, BlockReader, read_blocks, reader_heads, tag_probability
from handcap.detect.adapt import GATE as ADAPTED_GATE
from handcap.detect.refine import MAX_SHIFT, REFINED_THRESHOLD, CornerRefiner, locate_corners, refiner_views
from handcap.detect.checker import BlockChecker, block_features
from handcap.detect.checks import unconfirmed, uncrossed
from handcap.detect.voting import name_corners, vote
from handcap.detect.noise import NOISE_LEARNED, denoised, noise_sigma
from handcap.detect.sharpness import image_blur

#: Least side of a region searched, pixels: the corner network's tiles need 8, the refiner's crops 17.
MIN_REGION = 32
#: Median side of the read blocks above which an image is searched again halved, pixels (halved, such squares
#: are 14 px or more, well inside the 9-40 px the networks learned).
LARGE_SQUARE = 28.0
#: Shorter side of the smallest image level searched, pixels.
COARSEST = 128
#: Median side of the read blocks from which an image is searched halved as well, pixels: halved, such squares are
#: 9 px or more, the least the networks learned. A blurred image reads more there (its blur is halved too).
HALVABLE = 18.0
#: How many times the tags of a level whose squares the networks learned a halved level must read to replace it.
CLEARLY_MORE = 1.2
#: A halved level's corners are placed again by the refiner in each finer level whose squares are at most this wide,
#: pixels: twice the largest the networks learned (40 px; no bound, or 40 px, placed them worse: README, "Photographs
#: taken close").
FINER_SIDE = 80.0
#: Least confidence of a reading trusted alone when a glyph of it has a look-alike in the printed alphabet
#: (:data:`~handcap.patterns.alphabet.LOOKALIKES`; the reader's own gate otherwise). On 200 rendered scenes in a font
#: the reader never saw (2026-11-28), 0.00 % of its readings at or above 0.999 were wrong. Measured (2026-11-29) on
#: sheets of DexterCap's 22-glyph alphabet (S and 5, Z and 2 and 7) in that font, read without a template: 7 of
#: 923 tags read wrong at the reader's gate, all of them such swaps, and none at 0.999 (25 % fewer tags read).
LOOKALIKE_GATE = 0.999
#: Least confidence of a reading reported without a template, where no vote can correct it: the confidence at which
#: the shipped reader read at most 0.1 % of the true squares wrong in four fonts it never saw (Hack, Fira Code,
#: JetBrains Mono and Anonymous Pro, bold; 90 rendered scenes in handcap's and DexterCap's alphabets, 2026-11-29:
#: 0.9916, where its own gate, set in its training fonts, read 9 of 1,776 wrong). Another lab's patches are printed
#: in a font it never saw.
UNSEEN_FONT_GATE = 0.9916


def region_box(region, shape) -> tuple[int, int, int, int]:
    """A search box clipped to the image, its top-left rounded down to even pixels.

    Parameters
    ----------
    region : (x0, y0, x1, y1)
        Pixels; x1 and y1 excluded.
    shape : (int, int)
        Image height and width.

    Returns
    -------
    (int, int, int, int)
        The box, at least :data:`MIN_REGION` pixels on each side (or the image's side).

    Raises
    ------
    HandcapError
        A box that is not four finite numbers.
    """
    try:
        box = np.asarray(region, dtype=np.float64).reshape(-1)
    except (TypeError, ValueError):
        box = np.zeros(0)
    if box.shape != (4,) or not np.isfinite(box).all():
        raise HandcapError(f"a region is (x0, y0, x1, y1) in pixels, got {region!r}")
    h, w = shape[:2]
    x0 = int(np.clip(np.floor(box[0]), 0, max(w - MIN_REGION, 0))) // 2 * 2
    y0 = int(np.clip(np.floor(box[1]), 0, max(h - MIN_REGION, 0))) // 2 * 2
    x1 = int(np.clip(np.ceil(box[2]), x0 + MIN_REGION, w))
    y1 = int(np.clip(np.ceil(box[3]), y0 + MIN_REGION, h))
    return x0, y0, x1, y1


@dataclass(frozen=True)
class ImageDetections:
    """What the detector found in one image.

    Attributes
    ----------
    corners : ndarray (K, 2)
        Every corner found, pixels.
    corner_score : ndarray (K,)
    names : ndarray (K,) object
        Template name of each corner (``OWNER:PATCH_rRcC``), None where it has none.
    block_text : ndarray (B,) str
        Tags of the blocks kept (voted, with a template).
    block_xy : ndarray (B, 4, 2)
        Their corners in reading order (top-left, top-right, bottom-right, bottom-left), pixels.
    block_score : ndarray (B,)
    corrected : int
        Readings the vote changed.
    sure, disowned : int
        Readings the reader trusts alone (their confidence at its gate), and those of them the vote over the
        template dropped or changed: nearly all of them where the template is not the printed patches'.
    read : int
        White squares in which the reader saw a tag, at any confidence.
    noise : float
        The sensor noise of the image searched (:func:`~handcap.detect.noise.noise_sigma`), grey levels; over
        :data:`~handcap.detect.noise.NOISE_LEARNED` it was denoised first (unless the detector was told not to).
    twice : int
        Sure readings (as ``sure``) whose tag the reader was sure of at another white square of the image too: a
        tag printed twice, or two sessions' patches that share tags. With a template the vote drops them all.
    unread : ndarray (U, 4) int
        White squares given no tag (indices into ``corners``, in the order the corners go round): the other
        cameras of a rig may name them (:mod:`~handcap.detect.views`).
    blur : float
        The white squares' edge blur (:func:`~handcap.detect.sharpness.image_blur`), pixels; NaN without one.
    """

    corners: np.ndarray
    corner_score: np.ndarray
    names: np.ndarray
    block_text: np.ndarray
    block_xy: np.ndarray
    block_score: np.ndarray
    corrected: int
    sure: int = 0
    disowned: int = 0
    read: int = 0
    noise: float = 0.0
    twice: int = 0
    unread: np.ndarray = field(default_factory=lambda: np.zeros((0, 4), dtype=np.int64))
    blur: float = float("nan")


class Detector:
    """Coded-patch detector (see the module docstring).

    Parameters
    ----------
    corner_net : CornerNet
    reader : BlockReader
    pattern : Pattern, optional
        The session's template; without it no corner gets a name, and a tag is reported only at
        :data:`UNSEEN_FONT_GATE` (or :data:`LOOKALIKE_GATE`) or above.
    alphabet : str, optional
        Glyphs of the printed tags (default: the template's, else handcap's).
    threshold : float, optional
        Least corner probability: the refiner's when there is one (default 0.5), else the corner
        network's (default 0.3).
    refiner : CornerRefiner, optional
        Sub-pixel refinement of the corners (without it, the corner network's positions).
    pyramid : bool
        Search again at halved levels where the squares are large or no block is read (module docstring);
        False searches each image at its own size only.
    checker : BlockChecker, optional
        The learned check of the voted blocks (:mod:`~handcap.detect.checker`); without it, the hand-set
        rules of :mod:`~handcap.detect.checks`.
    denoise : bool
        Take an image's sensor noise down first where it holds more than the networks learned
        (:mod:`~handcap.detect.noise`).

    Attributes
    ----------
    adapted : BlockReader or None
        Without a template: a copy of the reader fine-tuned on the take (:mod:`~handcap.detect.adapt`), which
        vouches for readings the reader alone is not sure enough of; None (the default) reads with the reader only.
    confused : str
        Glyphs the reader confuses with another printed one in the take (:func:`~handcap.detect.adapt.
        confused_glyphs`): the adapted reader vouches for no reading with one of them.
    """

    def __init__(self, corner_net: CornerNet, reader: BlockReader, pattern: Pattern | None = None,
                 alphabet: str | None = None, threshold: float | None = None, refiner: CornerRefiner | None = None,
                 pyramid: bool = True, checker: BlockChecker | None = None, denoise: bool = True):
        self.corner_net, self.reader, self.pattern, self.refiner = corner_net, reader, pattern, refiner
        self.checker, self.denoise = checker, denoise
        if alphabet is None:
            alphabet = pattern.alphabet if pattern is not None else ALPHABET
        self.alphabet = check_alphabet(alphabet)
        unknown = [ch for ch in self.alphabet if ch not in GLYPHS]
        if unknown:
            raise HandcapError(f"--alphabet: the reader knows no glyph {''.join(unknown)!r}; it reads {GLYPHS}")
        if pattern is not None and set(pattern.alphabet) - set(self.alphabet):
            raise HandcapError(f"--alphabet {self.alphabet!r} lacks glyphs of the template's alphabet "
                               f"{pattern.alphabet!r}; leave --alphabet out to use the template's")
        self.threshold, self.pyramid = threshold, pyramid
        self.risky = "".join(sorted(set("".join(lookalikes(self.alphabet)))))  # glyphs with a look-alike printed
        self.adapted: BlockReader | None = None
        self.confused = ""

    def image(self, image: np.ndarray, region=None) -> ImageDetections:
        """Detect the patches of one grey image, or of a region of it.

        Parameters
        ----------
        image : ndarray (H, W) uint8
        region : (x0, y0, x1, y1), optional
            Search only this box of the image, pixels (x1, y1 excluded; x0 and y0 are rounded down to
            even pixels, so the corner network's half-resolution cells are the whole frame's). The grey
            levels are still the whole frame's, so what is found well inside the box is what the whole
            frame gives; a corner within a few pixels of the box's edge may be missed.

        Returns
        -------
        ImageDetections
            Positions in the whole image's pixels.
        """
        levels = grey_levels(image)
        origin = np.zeros(2)
        if region is not None:
            x0, y0, x1, y1 = region_box(region, image.shape)
            image, origin = np.ascontiguousarray(image[y0:y1, x0:x1]), np.array([x0, y0], float)
        image, noise = self.searched(image)
        found = self._detect(image, levels)
        if self.pyramid:
            found = self._coarser(image, levels, found)
        return replace(found, corners=found.corners + origin, block_xy=found.block_xy + origin, noise=noise,
                       blur=image_blur(image, found.block_xy, found.corners[found.unread], found.corners))

    def searched(self, image: np.ndarray) -> tuple[np.ndarray, float]:
        """``image`` as the detector searches it, and its sensor noise.

        Parameters
        ----------
        image : ndarray (H, W) uint8

        Returns
        -------
        image : ndarray (H, W) uint8
            Denoised where its noise is over :data:`~handcap.detect.noise.NOISE_LEARNED` (unless the detector was
            told not to), else ``image`` itself.
        noise : float
            :func:`~handcap.detect.noise.noise_sigma`, grey levels.
        """
        noise = noise_sigma(image)
        if self.denoise and noise > NOISE_LEARNED:
            image = denoised(image, noise)
        return image, noise

    def _coarser(self, image: np.ndarray, levels: np.ndarray, found: ImageDetections) -> ImageDetections:
        """``found`` in ``image``, or what a halved level of it reads where that holds more tags (module
        docstring), in ``image``'s pixels."""
        best, current, pyramid, chosen = found, found, [image], 0
        while (_too_large(current) or _halvable(current)) and min(pyramid[-1].shape[:2]) >= 2 * COARSEST:
            h, w = pyramid[-1].shape[:2]
            pyramid.append(cv2.resize(pyramid[-1], (w // 2, h // 2), interpolation=cv2.INTER_AREA))
            current = self._detect(pyramid[-1], levels)
            # A level of squares the networks learned gives way only to one that reads clearly more.
            if len(current.block_text) > len(best.block_text) * (1.0 if _too_large(best) else CLEARLY_MORE):
                best, chosen = current, len(pyramid) - 1
        return self._finer(best, pyramid[:chosen + 1]) if chosen else found

    def _finer(self, found: ImageDetections, pyramid: list) -> ImageDetections:
        """``found`` in the last (coarsest) image of ``pyramid`` brought to the first one's pixels, level by level,
        its corners placed again by the refiner in each finer level (:func:`look_again`):
        a halved level places them to a fraction of its own, larger, pixels."""
        xy = found.corners
        # The blocks' corners are the corners' own positions: each is found again by where it lies.
        index = cKDTree(xy).query(found.block_xy.reshape(-1, 2))[1] if len(found.block_xy) else np.zeros(0, int)
        side = _block_side(found)
        for finer, coarser in zip(pyramid[-2::-1], pyramid[:0:-1]):
            scale = np.array([finer.shape[1] / coarser.shape[1], finer.shape[0] / coarser.shape[0]])
            xy, side = (xy + 0.5) * scale - 0.5, side * scale.mean()
            if self.refiner is not None and side <= FINER_SIDE:
                xy, _ = look_again(self.refiner, finer, xy)
        return replace(found, corners=xy, block_xy=xy[index].reshape(found.block_xy.shape))

    def _detect(self, image: np.ndarray, levels: np.ndarray) -> ImageDetections:
        """:meth:`image` on an image (or a region of a frame) with the frame's grey levels (3,)."""
        xy, cscore = locate_corners(self.corner_net, self.refiner, image, self.threshold, levels)
        quads, _ = white_blocks(image, xy, candidate_quads(xy, score=cscore), levels)
        heads = reader_heads(self.reader, image, xy[quads], self.alphabet) if len(quads) else None
        text, reading, rotation, bscore = read_blocks(self.reader, image, xy[quads], self.alphabet, heads=heads) \
            if len(quads) else (np.zeros(0, "<U2"), np.zeros((0, 4, 2)), np.zeros(0, int), np.zeros(0))
        names = np.full(len(xy), None, dtype=object)
        corrected = disowned = 0
        sure, read = (text != "") & (bscore >= self.gates(text)), int((text != "").sum())
        seen = Counter(text[sure].tolist())
        twice = sum(n for n in seen.values() if n > 1)
        if self.pattern is not None and len(quads):
            tags, turns, corrected = self.vote(image, xy, cscore, quads, text, rotation, bscore, heads)
            disowned = int((sure & ((tags != text) | (turns != rotation))).sum())
            names = name_corners(self.pattern, quads, tags, turns, len(xy))
            keep = tags != ""
            order = (np.arange(4)[None] + np.maximum(turns, 0)[:, None]) % 4
            reading = np.take_along_axis(xy[quads], order[..., None], axis=1)
            text = tags
        else:  # nothing to vote with: a reading stands alone, in a font the reader may never have seen
            keep = sure & (bscore >= UNSEEN_FONT_GATE)
            if self.adapted is not None and len(quads):
                keep |= self._vouched(image, xy[quads], text, rotation, bscore)
        return ImageDetections(xy, cscore, names, text[keep], reading[keep], bscore[keep], corrected, int(sure.sum()),
                               disowned, read, twice=twice, unread=np.asarray(quads, dtype=np.int64)[~keep])

    def _vouched(self, image: np.ndarray, quads: np.ndarray, text, rotation, score) -> np.ndarray:
        """The readings (B,) the reader adapted to the take vouches for: it reads the same tag and turn at
        :data:`~handcap.detect.adapt.GATE` or more, the reader gave that reading its own gate or more, and no glyph
        of it has a look-alike in the alphabet or is one the reader confuses in this take."""
        again, _, turn, sure = read_blocks(self.adapted, image, quads, self.alphabet)
        doubtful = set(self.risky + self.confused)
        plain = np.array([not doubtful.intersection(str(t)) for t in text], dtype=bool)
        return ((text != "") & (again == text) & (turn == rotation) & plain & (score >= self.reader.min_score)
                & (sure >= ADAPTED_GATE))

    def gates(self, text) -> np.ndarray:
        """The confidence at which each reading is trusted alone: the reader's gate, or :data:`LOOKALIKE_GATE` for a
        reading with a glyph that has a look-alike in the alphabet.

        Parameters
        ----------
        text : ndarray (B,) str
            Readings.

        Returns
        -------
        ndarray (B,)
        """
        risky = np.array([any(ch in self.risky for ch in str(t)) for t in np.asarray(text).reshape(-1)], bool)
        return np.where(risky, max(self.reader.min_score, LOOKALIKE_GATE), self.reader.min_score)

    def vote(self, image: np.ndarray, xy: np.ndarray, corner_score: np.ndarray, quads: np.ndarray, text, rotation,
             score, heads=None) -> tuple[np.ndarray, np.ndarray, int]:
        """The template's vote over one image's read blocks, and the checks of the blocks it keeps.

        Parameters
        ----------
        image : ndarray (H, W)
        xy : ndarray (K, 2)
            Corners, pixels.
        corner_score : ndarray (K,)
        quads : ndarray (B, 4) int
            The white squares' corner indices in image order.
        text, rotation, score : ndarrays (B,)
            :func:`~handcap.detect.reader.read_blocks`'s readings of them.
        heads : tuple of ndarrays, optional
            :func:`~handcap.detect.reader.reader_heads` of the blocks in one turn, as they were read (the reader
            then need not look again at the blocks whose voted tag it did not read).

        Returns
        -------
        tags : ndarray (B,) str
            Each block's voted tag, "" where it is dropped.
        turns : ndarray (B,) int
            Index of the tag's top-left among the block's corners (-1 where dropped).
        corrected : int
            Readings the vote changed.
        """
        if self.checker is not None:
            return self._checked(image, xy, corner_score, quads, text, rotation, score, heads)
        tags, turns, corrected = vote(self.pattern, quads, text, rotation, score, self.reader.min_score, xy)
        agreed = (text == tags) & (rotation == turns)
        other = np.flatnonzero((tags != "") & ~agreed)
        voted_probability = np.ones(len(quads))
        if len(other):
            voted_probability[other] = tag_probability(
                self.reader, image, xy[quads[other]], self.alphabet, tags[other], turns[other],
                heads=None if heads is None else tuple(h[other] for h in heads))
        drop = unconfirmed(quads, tags, xy, agreed & (score >= self.reader.min_score), corner_score, agreed,
                           voted_probability)
        tags[drop], turns[drop] = "", -1
        drop = uncrossed(self.pattern, image, quads, tags, turns, xy)
        tags[drop], turns[drop] = "", -1
        return tags, turns, corrected

    def _checked(self, image, xy, corner_score, quads, text, rotation, score,
                 heads=None) -> tuple[np.ndarray, np.ndarray, int]:
        """:meth:`vote` with the learned checker: each block the vote gives a tag is kept where the checker's
        probability of it reaches the checker's gate."""
        tags, turns, features = block_features(self.pattern, self.reader, self.alphabet, image, xy, corner_score,
                                               quads, text, rotation, score, heads)
        drop = (tags != "") & ~self.checker.keeps(features, self.reader.min_score)
        tags[drop], turns[drop] = "", -1
        return tags, turns, int(((tags != "") & (text != "") & (tags != text)).sum())


def look_again(net: CornerRefiner, image: np.ndarray, xy: np.ndarray, *,
               min_score: float = REFINED_THRESHOLD) -> tuple[np.ndarray, np.ndarray]:
    """Points placed again by the refiner, each where it believes a corner near it; no point dropped or merged.

    A point is looked at from its nearest pixel, in the eight views, and again from the pixel nearest where that
    look places the corner (as :func:`~handcap.detect.refine.refine_corners`). It moves where the refiner gives
    ``min_score`` or more there and places the corner within :data:`~handcap.detect.refine.MAX_SHIFT` of the point;
    else it stays. For corners found in a halved image (:class:`Detector`'s levels), placed again in each finer
    level.

    Parameters
    ----------
    net : CornerRefiner
    image : ndarray (H, W)
    xy : ndarray (N, 2)
        Where the corners are thought to be, pixels.
    min_score : float
        Least probability of a corner to move a point.

    Returns
    -------
    xy : ndarray (N, 2)
        The points, moved or as given, pixels.
    moved : ndarray (N,) bool
    """
    xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
    h, w = np.asarray(image).shape[:2]
    placed, score = xy.copy(), np.zeros(len(xy))
    for _ in range(2):
        centres = np.rint(placed).astype(int)
        inside = np.flatnonzero((centres >= 0).all(axis=1) & (centres[:, 0] < w) & (centres[:, 1] < h))
        logit, offset = refiner_views(net, image, centres[inside])
        placed[inside], score[:] = centres[inside] + offset, 0.0
        score[inside] = expit(logit)
    moved = (score >= min_score) & (np.linalg.norm(placed - xy, axis=1) <= MAX_SHIFT)
    return np.where(moved[:, None], placed, xy), moved


def _block_side(found: ImageDetections) -> float:
    """The median side of an image level's blocks (each block's four sides averaged), pixels; NaN without one."""
    if len(found.block_xy) == 0:
        return float("nan")
    return float(np.median(np.linalg.norm(found.block_xy - np.roll(found.block_xy, -1, axis=1), axis=2).mean(axis=1)))


def _halvable(found: ImageDetections) -> bool:
    """Whether an image level's blocks are large enough to be read halved too: their sides' median is
    :data:`HALVABLE` or more. A blurred image reads more at half its size, where the blur is half as wide."""
    return _block_side(found) >= HALVABLE


def _too_large(found: ImageDetections) -> bool:
    """Whether an image level read no block, or blocks whose sides' median is over :data:`LARGE_SQUARE`.

    Even where it found no corner: a photograph taken very close shows corners too soft for the networks at its
    own size (rendered sheets with squares of 320-480 px: none at the image's size, and 41 -> 74 % of the tags
    read with the halved levels searched, none wrong). An image of nothing costs about the same (its flat tiles are
    skipped at every level: 0.06-0.07 s for a grey 5 MP frame either way)."""
    side = _block_side(found)
    return bool(np.isnan(side) or side > LARGE_SQUARE)
