"""Block reader: the two glyphs of a white square and which of its corners is the tag's top-left.

A block's four corners (in the image order of :mod:`handcap.detect.blocks`)
map the square onto a 32 x 32 view (the square fills pixels 4..28, with a
little of its black surround), the same whatever the perspective. A small
convolutional network reads the view with three heads, as DexterCap's BlockNet
(a ResNet-34) does: the first glyph, the second glyph (each one of
:data:`GLYPHS` or "none"), and the rotation, the index of the tag's top-left
among the four corners, or "not a block". It reads any alphabet drawn from
:data:`GLYPHS`; :func:`read_blocks` keeps the glyphs of the alphabet in use, so a
glyph that the alphabet lacks is never read.
"""

from __future__ import annotations

import cv2
import numpy as np
import torch
from torch import nn
from torch.nn import functional as F

from handcap.core.errors import HandcapError
from handcap.patterns.alphabet import READABLE

#: Every glyph the reader knows: digits, capitals and a few symbols of bold monospace fonts (its heads' classes).
GLYPHS = READABLE
NONE = len(GLYPHS)  # class of "no glyph" (a black square, or not a block)
VIEW = 32
_INSET = 4.0  # pixels of the view outside the square on every side
#: Evenly spaced turns of each block's view that :func:`read_blocks` reads and averages by default. On 60 rendered
#: hand scenes the reader's first choice is right for 84.8 % of the true blocks with 1, 87.3 % with 2 (as printed
#: and upside down) and 87.8 % with 4, but each turn costs one more pass of the network (about 0.1 s on a hand
#: frame on 2 cores) and the detector's tags rise less than a point after the vote, so one view is the default
#: (and the shipped gate was set for one view).
TURNS = 1


class BlockReader(nn.Module):
    """The reader network (see the module docstring).

    Parameters
    ----------
    width : int
        Channels of the first convolution; doubled after each pooling.
    min_score : float
        The least confidence of a reading to rely on by itself; training sets it from validation
        scenes (:func:`handcap.detect.evaluation.reader_gate`) and saves it with the weights.
    """

    def __init__(self, width: int = 32, min_score: float = 0.5):
        super().__init__()
        self.width = width
        self.min_score = float(min_score)
        c1, c2, c3 = width, 2 * width, 3 * width
        self.features = nn.Sequential(
            nn.Conv2d(1, c1, 3, padding=1), nn.BatchNorm2d(c1), nn.ReLU(),
            nn.Conv2d(c1, c1, 3, padding=1), nn.BatchNorm2d(c1), nn.ReLU(), nn.MaxPool2d(2),
            nn.Conv2d(c1, c2, 3, padding=1), nn.BatchNorm2d(c2), nn.ReLU(),
            nn.Conv2d(c2, c2, 3, padding=1), nn.BatchNorm2d(c2), nn.ReLU(), nn.MaxPool2d(2),
            nn.Conv2d(c2, c3, 3, padding=1), nn.BatchNorm2d(c3), nn.ReLU(), nn.MaxPool2d(2),
        )
        self.hidden = nn.Linear(c3 * 16, 256)
        self.first = nn.Linear(256, len(GLYPHS) + 1)
        self.second = nn.Linear(256, len(GLYPHS) + 1)
        self.turn = nn.Linear(256, 5)

    def forward(self, views: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """Logits of the first glyph, the second glyph and the rotation.

        Parameters
        ----------
        views : Tensor (B, 1, 32, 32)
            Normalised block views (:func:`block_views`).

        Returns
        -------
        (Tensor (B, G + 1), Tensor (B, G + 1), Tensor (B, 5))
            G = len(GLYPHS); the last glyph class is "none"; rotations 0-3, then "not a block".
        """
        x = self.features(views).flatten(1)
        x = F.elu(self.hidden(x))
        return self.first(x), self.second(x), self.turn(x)

    def config(self) -> dict:
        """The constructor's arguments."""
        return {"width": self.width, "min_score": self.min_score}


def block_views(image: np.ndarray, quads: np.ndarray) -> np.ndarray:
    """Each block's square, mapped from its four corners onto a 32 x 32 view and normalised.

    Parameters
    ----------
    image : ndarray (H, W)
        uint8 or float grey image.
    quads : ndarray (B, 4, 2)
        Corners in the order the rotation refers to, pixels.

    Returns
    -------
    ndarray (B, 32, 32) float32
        Zero median, unit 5-95 % spread per view.
    """
    img = np.asarray(image, dtype=np.float32)
    square = np.array([[_INSET, _INSET], [VIEW - _INSET, _INSET], [VIEW - _INSET, VIEW - _INSET],
                       [_INSET, VIEW - _INSET]], np.float32) - 0.5
    views = np.zeros((len(quads), VIEW, VIEW), np.float32)
    for k, quad in enumerate(np.asarray(quads, dtype=np.float32)):
        h = cv2.getPerspectiveTransform(quad, square)
        views[k] = cv2.warpPerspective(img, h, (VIEW, VIEW), flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
    if len(views) == 0:
        return views
    lo, mid, hi = np.percentile(views.reshape(len(views), -1), (5, 50, 95), axis=1)
    spread = np.maximum(hi - lo, 1e-3 * np.maximum(np.abs(hi), 1.0))
    return ((views - mid[:, None, None]) / spread[:, None, None]).astype(np.float32)


def reader_heads(net: BlockReader, image: np.ndarray, quads: np.ndarray, alphabet: str, *, batch: int = 512,
                 turns: int = TURNS) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The reader's three heads for each block, which :func:`read_blocks` and :func:`tag_probability` read.

    Parameters
    ----------
    net, image, quads, alphabet, batch, turns
        As :func:`read_blocks` takes them.

    Returns
    -------
    (ndarray (B, G + 1), ndarray (B, G + 1), ndarray (B, 5))
        The first and second glyph's probabilities, each over ``alphabet`` and "no tag" only (G = len(GLYPHS);
        the last class is "no tag"), and the rotation's (0-3, then "not a block"), averaged over the turns.
    """
    allowed = _allowed(alphabet)
    if turns not in (1, 2, 4):
        raise HandcapError(f"a block is read in 1, 2 or 4 turns, not {turns!r}")
    return _heads(net, image, np.asarray(quads, dtype=np.float64).reshape(-1, 4, 2), allowed, turns, batch)


def read_blocks(net: BlockReader, image: np.ndarray, quads: np.ndarray, alphabet: str, *, batch: int = 512,
                turns: int = TURNS, heads=None):
    """Read blocks: their tags in reading order and a confidence.

    Each block is read in ``turns`` evenly spaced turns (its corners rolled, so the view turns by quarter
    turns; the reader learned every turn) and the heads' probabilities are averaged, the rotation head's
    turned back first: a reading that holds in every turn is surer than one view's.

    Parameters
    ----------
    net : BlockReader
    image : ndarray (H, W)
    quads : ndarray (B, 4, 2)
        Corners in image order, pixels.
    alphabet : str
        Glyphs that may be read (each must be in :data:`GLYPHS`).
    batch : int
        Views per network pass.
    turns : int
        Turns of each view read and averaged: 1, 2 (as printed and upside down) or 4 (every quarter turn).
    heads : tuple of ndarrays, optional
        :func:`reader_heads` of these blocks (with these ``turns``), already computed: the network is not run.

    Returns
    -------
    text : ndarray (B,) str
        Two glyphs, or "" where the reader sees no tag.
    corners : ndarray (B, 4, 2)
        The same corners in reading order (top-left, top-right, bottom-right, bottom-left).
    rotation : ndarray (B,) int
        Index of the tag's top-left among the given corners (-1 for no tag).
    score : ndarray (B,)
        Product of the three heads' probabilities, each glyph head's over ``alphabet`` and "no tag" only.
    """
    allowed = _allowed(alphabet)
    quads = np.asarray(quads, dtype=np.float64).reshape(-1, 4, 2)
    first, second, turn = reader_heads(net, image, quads, alphabet, batch=batch, turns=turns) if heads is None \
        else heads
    p1, p2 = first[:, allowed], second[:, allowed]
    i1, i2 = p1.argmax(axis=1), p2.argmax(axis=1)
    rot = turn.argmax(axis=1)
    score = p1.max(axis=1) * p2.max(axis=1) * turn.max(axis=1)
    none = (rot == 4) | (first[:, NONE] > p1.max(axis=1)) | (second[:, NONE] > p2.max(axis=1))
    texts = ["" if n else alphabet[a] + alphabet[b] for a, b, n in zip(i1, i2, none)]
    rotations = np.where(none, -1, rot).astype(int)
    order = (np.arange(4)[None] + np.maximum(rotations, 0)[:, None]) % 4
    corners = np.take_along_axis(quads, order[..., None], axis=1)
    return np.array(texts, dtype="<U2"), corners, rotations, np.where(none, 0.0, score).astype(np.float64)


def tag_probability(net: BlockReader, image: np.ndarray, quads: np.ndarray, alphabet: str, tags, rotation,
                    *, batch: int = 512, heads=None) -> np.ndarray:
    """The reader's probability that each block shows a given tag in a given turn (one view, as
    :func:`read_blocks` reads by default).

    Parameters
    ----------
    net : BlockReader
    image : ndarray (H, W)
    quads : ndarray (B, 4, 2)
        Corners in image order, pixels.
    alphabet : str
        Glyphs that may be read.
    tags : sequence of str
        A two-glyph tag of ``alphabet`` for each block.
    rotation : ndarray (B,) int
        Index of the tag's top-left among each block's given corners (0-3).
    heads : tuple of ndarrays, optional
        :func:`reader_heads` of these blocks in one turn, already computed: the network is not run.

    Returns
    -------
    ndarray (B,)
        Product of the three heads' probabilities of that tag and turn, each glyph head's over ``alphabet``
        and "no tag" only (as :func:`read_blocks` scores its own reading).
    """
    allowed = _allowed(alphabet)
    quads = np.asarray(quads, dtype=np.float64).reshape(-1, 4, 2)
    tags = [str(t) for t in tags]
    bad = [t for t in tags if len(t) != 2 or t[0] not in alphabet or t[1] not in alphabet]
    if bad:
        raise HandcapError(f"tag {bad[0]!r} is not two glyphs of the alphabet {alphabet!r}")
    rotation = np.asarray(rotation, dtype=int).reshape(-1)
    if len(tags) != len(quads) or len(rotation) != len(quads) or ((rotation < 0) | (rotation > 3)).any():
        raise HandcapError("tag_probability needs one tag and one rotation (0-3) per block")
    first_glyph = np.array([GLYPHS.index(t[0]) for t in tags], dtype=int)
    second_glyph = np.array([GLYPHS.index(t[1]) for t in tags], dtype=int)
    first, second, turn = _heads(net, image, quads, allowed, 1, batch) if heads is None else heads
    rows = np.arange(len(quads))
    return (first[rows, first_glyph] * second[rows, second_glyph] * turn[rows, rotation]).astype(np.float64)


def glyph_probabilities(net: BlockReader, image: np.ndarray, quads: np.ndarray, alphabet: str, *,
                        batch: int = 512) -> tuple[np.ndarray, np.ndarray]:
    """The two glyph heads' probabilities over the printed alphabet (one view, as :func:`read_blocks` reads).

    Parameters
    ----------
    net : BlockReader
    image : ndarray (H, W)
    quads : ndarray (B, 4, 2)
        Corners in image order, pixels.
    alphabet : str
        Glyphs that may be read.

    Returns
    -------
    (ndarray (B, L), ndarray (B, L))
        The first and the second glyph's probabilities over the L glyphs of ``alphabet``, each head's over the
        alphabet and "no tag" (so a row sums to 1 less its "no tag").
    """
    allowed = _allowed(alphabet)
    first, second, _ = _heads(net, image, np.asarray(quads, dtype=np.float64).reshape(-1, 4, 2), allowed, 1, batch)
    return first[:, allowed].astype(np.float64), second[:, allowed].astype(np.float64)


def _allowed(alphabet: str) -> np.ndarray:
    """Indices in :data:`GLYPHS` of the glyphs of ``alphabet``; a glyph the reader does not know is an error."""
    unknown = [ch for ch in alphabet if ch not in GLYPHS]
    if unknown:
        raise HandcapError(f"the block reader knows no glyph {''.join(unknown)!r}; it reads {GLYPHS}")
    return np.array([GLYPHS.index(ch) for ch in alphabet], dtype=int)


def _heads(net: BlockReader, image: np.ndarray, quads: np.ndarray, allowed: np.ndarray, turns: int, batch: int):
    """The reader's three heads for ``quads`` (B, 4, 2), ``batch`` views a pass: the glyph heads (B, G + 1) over the
    allowed glyphs and "no tag" (:func:`_renormalised`), the rotation head (B, 5), each averaged over ``turns``."""
    heads = [np.zeros((len(quads), n), np.float32) for n in (len(GLYPHS) + 1, len(GLYPHS) + 1, 5)]
    net.eval().to(memory_format=torch.channels_last)  # channels-last convolutions: ~1.5x faster on the CPU
    with torch.inference_mode():
        for start in range(0, len(quads), batch):
            first, second, turn = _averaged(net, image, quads[start:start + batch], turns)
            part = slice(start, start + batch)
            heads[0][part], heads[1][part] = _renormalised(first, allowed), _renormalised(second, allowed)
            heads[2][part] = turn
    return tuple(heads)


def _renormalised(head: np.ndarray, allowed: np.ndarray) -> np.ndarray:
    """A glyph head's probabilities (B, G + 1) over the printed alphabet and "no tag" only: mass on a look-alike
    glyph of another alphabet does not count as doubt about this one."""
    return head / (head[:, allowed].sum(axis=1) + head[:, NONE])[:, None]


def _averaged(net: BlockReader, image: np.ndarray, quads: np.ndarray, turns: int):
    """The reader's three heads' probabilities for ``quads`` (B, 4, 2), averaged over ``turns`` evenly spaced
    turns of their views."""
    rolls = range(0, 4, 4 // turns)
    rolled = np.concatenate([np.roll(quads, -k, axis=1) for k in rolls])
    views = torch.from_numpy(block_views(image, rolled))[:, None].contiguous(memory_format=torch.channels_last)
    first, second, turn = (F.softmax(out, dim=1).numpy().reshape(turns, len(quads), -1) for out in net(views))
    # Read from corners rolled by k, rotation index i is index (i + k) % 4 of the given corners.
    for j, k in enumerate(rolls):
        turn[j, :, :4] = np.roll(turn[j, :, :4], k, axis=1)
    return first.mean(axis=0), second.mean(axis=0), turn.mean(axis=0)


def reader_loss(outputs, first: torch.Tensor, second: torch.Tensor, turn: torch.Tensor) -> torch.Tensor:
    """Sum of the three cross-entropies.

    Parameters
    ----------
    outputs : tuple of Tensor
        :meth:`BlockReader.forward`'s logits.
    first, second, turn : Tensor (B,) int
        Class of each head.

    Returns
    -------
    Tensor ()
    """
    return F.cross_entropy(outputs[0], first) + F.cross_entropy(outputs[1], second) + F.cross_entropy(outputs[2], turn)
