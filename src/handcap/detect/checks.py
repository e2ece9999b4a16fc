"""Checks of the blocks the template's vote keeps: their shape, their lone corners, the squares across them.

The vote (:mod:`handcap.detect.voting`) puts a tag on every block that a reading's walk reaches. A block
with a false corner (an occluder's edge or a finger's outline crossing a square's side near its hidden
corner) can be reached too; these tests find most of them from the block's shape, its corners'
probabilities and what the image shows across them. The hand-set rules (:func:`unconfirmed`,
:func:`uncrossed`) are the detector's checks without a learned checker (:mod:`handcap.detect.checker`);
the measures they test are the learned checker's features.
"""

from __future__ import annotations

import numpy as np
from scipy.ndimage import map_coordinates

from handcap.patterns.pattern import Pattern


def corner_uses(quads, tags, n_corners: int):
    """Blocks as corner indices, which of them are voted, and how many voted blocks use each corner.

    Parameters
    ----------
    quads : ndarray (B, 4) int
        Corner indices of each block.
    tags : sequence of str
        Voted tags ("" for none).
    n_corners : int
        Corners in the image.

    Returns
    -------
    quads : ndarray (B, 4) int
    voted : ndarray (B,) bool
    uses : ndarray (n_corners,) int
    """
    quads = np.asarray(quads, dtype=int).reshape(-1, 4)
    voted = np.array([bool(t) for t in tags], bool).reshape(-1)
    return quads, voted, np.bincount(quads[voted].ravel(), minlength=n_corners)


#: Largest distance of a block's fourth corner from where the other three put it (the corner that closes their
#: parallelogram), in sides of the block, for a block not confirmed by its neighbours. A printed square seen over a
#: few millimetres of skin is nearly a parallelogram in the image; a false corner beside a missed one bends it.
MAX_DEFECT = 0.12
#: Least probability of a corner that only one voted block uses: a weaker one is most often a silhouette or an
#: occluder's edge crossing the block's side a few pixels from its hidden corner.
MIN_LONE_SCORE = 0.7
#: Least probability of each lone corner of a block whose shape a trusted reading vouches for.
TRUSTED_CORNER_SCORE = 0.9
#: Least probability of each lone corner of a block whose shape its own reading vouches for, whatever that reading's
#: confidence, when it is the voted tag and turn. Chosen on 80 rendered hand scenes (seeds 777 and 778; 0.99, 0.98
#: and 0.95 tried, with one view and with two: 0.95 let a wrong block through that 0.98 did not) and checked on the
#: 90 of ``benchmarks/detect.py``'s seeds 99, 7 and 123.
AGREED_CORNER_SCORE = 0.98
#: Largest parallelogram defect (as :data:`MAX_DEFECT`) of a block that its agreeing reading vouches for: nine in ten
#: true squares on rendered hands bend less (0.24 measured on seed 7 of ``benchmarks/detect.py``); past it, a lone
#: corner is more often one found where the finger's outline cuts the square's side.
AGREED_MAX_DEFECT = 0.25
#: Least probability the reader gives a voted block's tag and turn when it reads another tag there and two or more
#: of its corners are lone: below it the quad is not that square (most often one shifted a square over, which the
#: vote placed through its two shared corners).
MIN_VOTED_PROBABILITY = 1e-4


def unconfirmed(quads: np.ndarray, tags, xy: np.ndarray, trusted=None, score=None, agreed=None,
                voted_probability=None) -> np.ndarray:
    """Voted blocks with a corner no other voted block confirms, no parallelogram shape, no trusted reading.

    A corner shared by two voted blocks (diagonal neighbours on a patch) was found where two squares,
    read apart, both put it. A block with a corner nobody else uses (at a patch's edge, beside an
    unread neighbour, or a false detection beside a missed corner) is kept only when its four corners
    close a parallelogram to within :data:`MAX_DEFECT` of its side: a false corner a few pixels off
    breaks the shape, while perspective and the skin's curve over one square hardly do. (On rendered
    hands this keeps about 80 % of the right blocks and drops nearly all with a corner over 2 px off;
    comparing each block's homography with its patch-mates' corners, as tried first, dropped a third of
    the right blocks because the skin bends over two squares.) A block whose own reading is ``trusted``
    is kept whatever its shape: the reader saw the square through exactly these four corners, and a
    corner a few pixels off shows it part of a black square or of the background (on rendered hands, a
    reading trusted by itself keeps about 40 % of the right blocks this test would drop, and no more wrong ones;
    in the demo's 13-camera take, where blur leaves corners less sure, it also let 2 % wrong ones through, so its
    lone corners must score :data:`TRUSTED_CORNER_SCORE`).
    A block the reader read as its voted tag and turn (``agreed``), at any confidence, is also kept whatever
    its shape when each of its lone corners scores :data:`AGREED_CORNER_SCORE` and it is no more bent than
    :data:`AGREED_MAX_DEFECT`: a quad with a false corner seldom shows the reader the very tag its neighbours
    put there, and a false corner is seldom that sure (on rendered hands the true squares themselves are no
    parallelogram to 0.12 of their side in a quarter of the views: the skin bends under them).
    Given ``voted_probability``, a block the reader reads as another tag, with two or more lone corners, is
    dropped when the reader gives its voted tag and turn less than :data:`MIN_VOTED_PROBABILITY`.
    With corner ``score`` given, a block is also dropped, whatever its shape and reading, when a corner
    that no other voted block uses scored below :data:`MIN_LONE_SCORE`: an occluder's edge crossing the
    block's side two or three pixels from its hidden corner makes such a weak corner and only a slightly
    bent block (on rendered hands this removed 4 of the 6 wrong blocks left, for 1.3 % of the right ones).

    Parameters
    ----------
    quads : ndarray (B, 4) int
        Corner indices in image order (clockwise or anticlockwise around the block).
    tags : sequence of str
        Voted tags ("" for none).
    xy : ndarray (K, 2)
        Image corners, pixels.
    trusted : ndarray (B,) bool, optional
        Blocks whose own reading is the voted tag and turn, with a confidence the reader trusts alone
        (default: none).
    score : ndarray (K,), optional
        Each corner's probability (default: not tested).
    agreed : ndarray (B,) bool, optional
        Blocks the reader read as the voted tag and turn, at any confidence (default: none; needs ``score``).
    voted_probability : ndarray (B,), optional
        The reader's probability of each block's voted tag and turn
        (:func:`~handcap.detect.reader.tag_probability`; anything where no tag is voted).

    Returns
    -------
    ndarray (B,) bool
        True for a block to drop.
    """
    quads, voted, uses = corner_uses(quads, tags, len(xy))
    if not voted.any():
        return np.zeros(len(quads), bool)
    confirmed = (uses[quads] > 1).all(axis=1)
    pts = np.asarray(xy, dtype=np.float64)[quads]
    side = np.linalg.norm(np.roll(pts, -1, axis=1) - pts, axis=2).mean(axis=1)
    defect = np.linalg.norm(pts[:, 0] - pts[:, 1] + pts[:, 2] - pts[:, 3], axis=1) / np.maximum(side, 1e-9)
    drop = voted & ~confirmed & (defect > MAX_DEFECT)
    lone = uses[quads] <= 1
    corner_score = np.ones(quads.shape) if score is None else np.asarray(score, dtype=np.float64)[quads]
    if trusted is not None:
        sure = (~lone | (corner_score >= TRUSTED_CORNER_SCORE)).all(axis=1)
        drop &= ~(np.asarray(trusted, bool).reshape(-1) & sure)
    agreed = np.zeros(len(quads), bool) if agreed is None else np.asarray(agreed, bool).reshape(-1)
    if score is not None:
        sure = (~lone | (corner_score >= AGREED_CORNER_SCORE)).all(axis=1)
        drop &= ~(agreed & sure & (defect <= AGREED_MAX_DEFECT))
    drop |= voted & (lone & (corner_score < MIN_LONE_SCORE)).any(axis=1)
    if voted_probability is not None:
        unlike = np.asarray(voted_probability, dtype=np.float64).reshape(-1) < MIN_VOTED_PROBABILITY
        drop |= voted & ~agreed & (lone.sum(axis=1) >= 2) & unlike
    return drop


#: A lone corner of a voted block where the template puts a second white square diagonally across it must show
#: that square: its brightness and its own square's must both clear the two black squares beside the corner by
#: this share of the corner's contrast. A corner found where an occluder's edge crosses the square's side near
#: its hidden corner shows the occluder there instead. Set on 40 rendered hand scenes (seed 7 of
#: ``benchmarks/detect.py``: 0.2 dropped 7 of the 12 wrong blocks and 12 of 1,101 right ones, 0.3 8 and 23) and
#: checked on 50 others (seeds 99 and 123).
MIN_CROSS = 0.25
#: Where the four squares around a corner are sampled: these shares of the block's sides from the corner, along
#: the diagonals (the brightest sample of a white square, the darkest of a black one: glyphs and blur aside).
CROSS_AT = (0.15, 0.22, 0.3)


def uncrossed(pattern: Pattern, image: np.ndarray, quads: np.ndarray, tags, turns, xy: np.ndarray) -> np.ndarray:
    """Voted blocks with a lone corner where the white square the template puts across it does not show.

    A corner that only one voted block uses, and that the template makes the meeting point of two white
    squares (the block's own and the one diagonally across), is checked in the image: around a printed
    corner the four squares alternate, white, black, white, black. Seen through an occluder, the square
    across is the occluder (see :data:`MIN_CROSS`). Corners on a patch's edge are not checked.

    Parameters
    ----------
    pattern : Pattern
    image : ndarray (H, W)
        Grey image.
    quads : ndarray (B, 4) int
        Corner indices in image order.
    tags : sequence of str
        Voted tags ("" for none).
    turns : ndarray (B,) int
        Voted turns: reading-order corner ``j`` is image corner ``(j + turn) % 4``.
    xy : ndarray (K, 2)
        Image corners, pixels.

    Returns
    -------
    ndarray (B,) bool
        True for a block to drop.
    """
    return cross_margin(pattern, image, quads, tags, turns, xy) < MIN_CROSS


def cross_margin(pattern: Pattern, image: np.ndarray, quads: np.ndarray, tags, turns, xy: np.ndarray) -> np.ndarray:
    """How clearly each voted block's lone corners show the white square the template puts across them.

    At each corner :func:`uncrossed` checks, the darker of the two white squares (the block's own and the
    one across) less the brighter of the two black ones, as a share of the corner's contrast (the own
    square against the black ones' mean, at least one grey level): about 1 at a clean printed corner,
    0 or less where an occluder or the background shows across it.

    Parameters
    ----------
    pattern : Pattern
    image : ndarray (H, W)
        Grey image.
    quads : ndarray (B, 4) int
        Corner indices in image order.
    tags : sequence of str
        Voted tags ("" for none).
    turns : ndarray (B,) int
        Voted turns.
    xy : ndarray (K, 2)
        Image corners, pixels.

    Returns
    -------
    ndarray (B,)
        The least such share over the block's checked corners; inf where none is checked.
    """
    quads, voted, uses = corner_uses(quads, tags, len(xy))
    out = np.full(len(quads), np.inf)
    if not voted.any():
        return out
    share = np.asarray(CROSS_AT)[:, None]

    def sample(points):
        return map_coordinates(image, [points[:, 1], points[:, 0]], order=1, mode="nearest", output=np.float32)

    for k in np.flatnonzero(voted):
        place = pattern.locate(str(tags[k]))
        if place is None:
            continue
        patch, row, col = place
        q = quads[k][(np.arange(4) + max(int(turns[k]), 0)) % 4]
        pts = np.asarray(xy, dtype=np.float64)[q]
        for i, (vr, vc) in enumerate(patch.block_vertices(row, col)):
            across = 2 * vr - 1 - row, 2 * vc - 1 - col
            if uses[q[i]] > 1 or not (0 <= across[0] < patch.rows and 0 <= across[1] < patch.cols
                                      and patch.tags[across[0]][across[1]]):
                continue
            corner, u, v = pts[i], pts[(i + 1) % 4] - pts[i], pts[(i - 1) % 4] - pts[i]
            own, opposite = sample(corner + share * (u + v)).max(), sample(corner - share * (u + v)).max()
            black = sample(corner + share * (u - v)).min(), sample(corner + share * (v - u)).min()
            margin = (min(own, opposite) - max(black)) / max(own - 0.5 * sum(black), 1.0)
            out[k] = min(out[k], margin)
    return out
