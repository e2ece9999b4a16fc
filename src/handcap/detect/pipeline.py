"""The coded-patch detector on one image: corners, blocks, tags, votes, named corners.

:class:`Detector` chains the stages: the corner network
(:mod:`~handcap.detect.corners`), the sub-pixel refiner that also turns away
false candidates (:mod:`~handcap.detect.refine`), block assembly (:mod:`~handcap.detect.blocks`),
the block reader (:mod:`~handcap.detect.reader`) and, given a template,
the vote over its patches and the corner names (:mod:`~handcap.detect.voting`).
Without a template it reports blocks and their corners only (a single photo of
patches from an unknown sheet).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from handcap.core.errors import HandcapError
from handcap.patterns.alphabet import ALPHABET, check_alphabet
from handcap.detect.blocks import candidate_quads, white_blocks
from handcap.detect.corners import CornerNet
from handcap.patterns.pattern import Pattern
from handcap.detect.reader import GLYPHS, BlockReader, read_blocks, tag_probability
from handcap.detect.refine import CornerRefiner, locate_corners
from handcap.detect.voting import name_corners, unconfirmed, uncrossed, vote

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
    """

    corners: np.ndarray
    corner_score: np.ndarray
    names: np.ndarray
    block_text: np.ndarray
    block_xy: np.ndarray
    block_score: np.ndarray
    corrected: int


class Detector:
    """Coded-patch detector (see the module docstring).

    Parameters
    ----------
    corner_net : CornerNet
    reader : BlockReader
    pattern : Pattern, optional
        The session's template; without it no corner gets a name.
    alphabet : str, optional
        Glyphs of the printed tags (default: the template's, else handcap's).
    threshold : float, optional
        Least corner probability: the refiner's when there is one (default 0.5), else the corner
        network's (default 0.3).
    refiner : CornerRefiner, optional
        Sub-pixel refinement of the corners (without it, the corner network's positions).
    """

    def __init__(self, corner_net: CornerNet, reader: BlockReader, pattern: Pattern | None = None,
                 alphabet: str | None = None, threshold: float | None = None, refiner: CornerRefiner | None = None):
        self.corner_net, self.reader, self.pattern, self.refiner = corner_net, reader, pattern, refiner
        if alphabet is None:
            alphabet = pattern.alphabet if pattern is not None else ALPHABET
        self.alphabet = check_alphabet(alphabet)
        unknown = [ch for ch in self.alphabet if ch not in GLYPHS]
        if unknown:
            raise HandcapError(f"--alphabet: the reader knows no glyph {''.join(unknown)!r}; it reads {GLYPHS}")
        if pattern is not None and set(pattern.alphabet) - set(self.alphabet):
            raise HandcapError(f"--alphabet {self.alphabet!r} lacks glyphs of the template's alphabet "
                               f"{pattern.alphabet!r}; leave --alphabet out to use the template's")
        self.threshold = threshold

    def image(self, image: np.ndarray) -> ImageDetections:
        """Detect the patches of one grey image.

        Parameters
        ----------
        image : ndarray (H, W) uint8

        Returns
        -------
        ImageDetections
        """
        xy, cscore = locate_corners(self.corner_net, self.refiner, image, self.threshold)
        quads, _ = white_blocks(image, xy, candidate_quads(xy, score=cscore))
        text, reading, rotation, bscore = read_blocks(self.reader, image, xy[quads], self.alphabet) if len(quads) \
            else (np.zeros(0, "<U2"), np.zeros((0, 4, 2)), np.zeros(0, int), np.zeros(0))
        names = np.full(len(xy), None, dtype=object)
        corrected = 0
        if self.pattern is not None and len(quads):
            tags, turns, corrected = self.vote(image, xy, cscore, quads, text, rotation, bscore)
            names = name_corners(self.pattern, quads, tags, turns, len(xy))
            keep = tags != ""
            order = (np.arange(4)[None] + np.maximum(turns, 0)[:, None]) % 4
            reading = np.take_along_axis(xy[quads], order[..., None], axis=1)
            text = tags
        else:
            keep = (text != "") & (bscore >= self.reader.min_score)
        return ImageDetections(xy, cscore, names, text[keep], reading[keep], bscore[keep], corrected)

    def vote(self, image: np.ndarray, xy: np.ndarray, corner_score: np.ndarray, quads: np.ndarray, text, rotation,
             score) -> tuple[np.ndarray, np.ndarray, int]:
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

        Returns
        -------
        tags : ndarray (B,) str
            Each block's voted tag, "" where it is dropped.
        turns : ndarray (B,) int
            Index of the tag's top-left among the block's corners (-1 where dropped).
        corrected : int
            Readings the vote changed.
        """
        tags, turns, corrected = vote(self.pattern, quads, text, rotation, score, self.reader.min_score, xy)
        agreed = (text == tags) & (rotation == turns)
        other = np.flatnonzero((tags != "") & ~agreed)
        voted_probability = np.ones(len(quads))
        if len(other):
            voted_probability[other] = tag_probability(self.reader, image, xy[quads[other]], self.alphabet,
                                                       tags[other], turns[other])
        drop = unconfirmed(quads, tags, xy, agreed & (score >= self.reader.min_score), corner_score, agreed,
                           voted_probability)
        tags[drop], turns[drop] = "", -1
        drop = uncrossed(self.pattern, image, quads, tags, turns, xy)
        tags[drop], turns[drop] = "", -1
        return tags, turns, corrected
