"""Voting over the patch template: fix misread tags, then name every corner (DexterCap Sec. 3.2.4).

Blocks that share an image corner are diagonal neighbours on a patch: if block
A sits at square ``(r, c)`` and its corner ``k`` (reading order: top-left,
top-right, bottom-right, bottom-left) is also a corner of block B, then B is
the square across that corner, ``(r + 2 dr_k - 1, c + 2 dc_k - 1)``, and the
shared corner is B's opposite corner ``(k + 2) % 4`` (with pixels given, blocks two
squares along a row or column are also reached, to confirm their own readings). So every block that was
read places, by a walk over the blocks it is connected to, every other block
of its patch that the reader saw a tag in (right or not; a quad it saw none in
is often one shifted over a black square): its square (hence its tag) and its turn. Each read block casts
one such vote, weighed by its confidence, for every block it reaches, itself
included; a block takes the (tag, turn) with most votes, and is dropped when
the best holds less than two thirds of the block's votes or weighs less than
``min_support`` (a lone, unsure reading is not trusted), and a tag kept by two blocks of one image is dropped from both
(DexterCap drops such pairs too). A voted block that its neighbours do not
confirm corner by corner must be nearly a parallelogram (:func:`unconfirmed`).
The corners of the blocks that remain are named from the template
(``OWNER:PATCH_rRcC``); a corner given two different names by its blocks is
dropped.
"""

from __future__ import annotations

from collections import Counter, defaultdict, deque

import numpy as np
from scipy.ndimage import map_coordinates
from scipy.spatial import cKDTree

from handcap.detect.blocks import unit_square_homographies
from handcap.patterns.pattern import Pattern

#: Share of a block's votes the winning (tag, turn) must hold.
MAJORITY = 2 / 3
#: (row, column) of each reading-order corner of a square relative to its top-left vertex.
STEP = ((0, 0), (0, 1), (1, 1), (1, 0))


def vote(pattern: Pattern, quads: np.ndarray, text, rotation, score=None, min_support: float = 0.0, xy=None):
    """Vote over the template (see the module docstring).

    Parameters
    ----------
    pattern : Pattern
    quads : ndarray (B, 4) int
        Each block's corner indices in image order (the order the rotations refer to).
    text : sequence of str
        Each block's reading ("" when unread).
    rotation : ndarray (B,) int
        Index of the tag's top-left among the block's corners (-1 when unread).
    score : ndarray (B,), optional
        Reading confidences; a vote weighs its seed's confidence (default 1).
    min_support : float
        Least total weight of the winning vote.
    xy : ndarray (K, 2), optional
        Image corners (pixels). Given, a walk steps only to a block that lies where a diagonal
        neighbour must: its centre within a third of a side of the mirror image of the current block's
        centre through the shared corner (a false quad that happens to share a corner is not placed).
        It also steps to the white squares two squares along the current block's row and column, which
        share no corner with it, where the block's own corners put them (:func:`_along`), when they
        were read as the tag and turn the template gives there: the two squares of a 1 x 3 patch, or
        a block whose diagonal neighbours were not found, confirm each other.

    Returns
    -------
    tags : ndarray (B,) str
        The voted tag of each block, "" where it is dropped.
    turns : ndarray (B,) int
        The voted rotation (-1 where dropped).
    changed : int
        Blocks whose reading the vote corrected.
    """
    quads = np.asarray(quads, dtype=int).reshape(-1, 4)
    n = len(quads)
    weight = np.ones(n) if score is None else np.asarray(score, dtype=float)
    by_corner = defaultdict(list)
    for b, quad in enumerate(quads):
        for p, corner in enumerate(quad):
            by_corner[corner].append((b, p))
    # The blocks each block's walk may step to across each of its corners: (corner position, block, its position).
    steps = [[[(b, q) for b, q in by_corner[corner] if b != a and text[b]] for corner in quads[a]] for a in range(n)]
    if xy is not None:
        pts = np.asarray(xy, dtype=float)[quads]
        centre = pts.mean(axis=1)
        side = np.linalg.norm(pts - np.roll(pts, 1, axis=1), axis=-1).mean(axis=1)
        along = _along(pts, centre, side)
        steps = _mirrored(steps, quads, np.asarray(xy, dtype=float), centre, side)
    votes = [Counter() for _ in range(n)]
    for seed in range(n):
        located = pattern.locate(str(text[seed])) if text[seed] else None
        if located is None or rotation[seed] < 0:
            continue
        patch, r0, c0 = located
        placed = {seed: (r0, c0, int(rotation[seed]))}
        queue = deque([seed])
        while queue:
            a = queue.popleft()
            r, c, turn = placed[a]
            for p in range(4):
                k = (p - turn) % 4  # reading-order index of this corner in block a
                dr, dc = STEP[k]
                for b, q in steps[a][p]:
                    if b in placed:
                        continue
                    rb, cb = r + 2 * dr - 1, c + 2 * dc - 1
                    if not (0 <= rb < patch.rows and 0 <= cb < patch.cols) or not patch.tags[rb][cb]:
                        continue
                    placed[b] = (rb, cb, (q - (k + 2)) % 4)
                    queue.append(b)
            for (dr, dc), (b, turn_b) in (along(a, turn) if xy is not None else {}).items():
                rb, cb = r + dr, c + dc
                if b in placed or not (0 <= rb < patch.rows and 0 <= cb < patch.cols) or not patch.tags[rb][cb]:
                    continue
                if text[b] != patch.tags[rb][cb] or rotation[b] != turn_b:
                    continue  # a step that crosses no shared corner only confirms a reading, never makes one
                placed[b] = (rb, cb, turn_b)
                queue.append(b)
        for b, (r, c, turn) in placed.items():
            votes[b][(patch.tags[r][c], turn)] += weight[seed]
    tags = np.full(n, "", dtype="<U2")
    turns = np.full(n, -1)
    for b, counter in enumerate(votes):
        ranked = counter.most_common(1)
        if not ranked or ranked[0][1] < min_support or ranked[0][1] < MAJORITY * sum(counter.values()):
            continue
        tags[b], turns[b] = ranked[0][0]
    # A tag seen twice in one image: neither can be trusted.
    seen = Counter(t for t in tags if t)
    for b in range(n):
        if tags[b] and seen[tags[b]] > 1:
            tags[b], turns[b] = "", -1
    changed = int(sum(1 for b in range(n) if tags[b] and text[b] and tags[b] != text[b]))
    return tags, turns, changed


def _mirrored(steps, quads: np.ndarray, xy: np.ndarray, centre: np.ndarray, side: np.ndarray):
    """``steps`` (per block, per corner position, the (block, its corner position) pairs sharing that corner) kept
    only where the other block's centre lies within a third of a side of the mirror image of this block's centre
    through the shared corner: where a diagonal neighbour must be (a false quad that shares a corner is not)."""
    out = []
    for a, per_corner in enumerate(steps):
        kept = []
        for p, pairs in enumerate(per_corner):
            if pairs:
                b = np.array([b for b, _ in pairs])
                near = np.linalg.norm(centre[b] - (2 * xy[quads[a, p]] - centre[a]), axis=1) <= (side[a] + side[b]) / 6
                pairs = [pair for pair, ok in zip(pairs, near) if ok]
            kept.append(pairs)
        out.append(kept)
    return out


#: Squares of the patch grid two along a block's row or column: (rows, columns) from it.
ALONG = ((0, 2), (0, -2), (2, 0), (-2, 0))


def _along(pts: np.ndarray, centre: np.ndarray, side: np.ndarray):
    """For the walk of :func:`vote`: the blocks two squares along a block's row and column, and their turns.

    Block ``a`` read with turn ``t`` (its reading-order corners ``pts[a][(arange(4) + t) % 4]``) maps its
    square's grid to the image by the homography of its four corners; the blocks at ``ALONG`` must lie
    where it maps those squares: centre within a third of a side, and each corner within half a side
    (which also gives their turn). Every block, turn and direction is mapped at once.

    Returns a function ``(a, t) -> {(dr, dc): (b, turn_b)}``.
    """
    n = len(pts)
    roll = (np.arange(4)[None] + np.arange(4)[:, None]) % 4  # (turn, reading-order corner) -> corner
    homs = unit_square_homographies(pts[:, roll].reshape(-1, 4, 2))  # (n * 4, 3, 3): block-major, then turn
    unit = np.array([(0.0, 0.0), (1.0, 0.0), (1.0, 1.0), (0.0, 1.0)])
    grid = np.array([unit + (dc, dr) for dr, dc in ALONG])  # (4 directions, 4 corners, 2)
    mapped = np.einsum("hij,dkj->hdki", homs, np.concatenate([grid, np.ones((4, 4, 1))], axis=2))
    guess = (mapped[..., :2] / mapped[..., 2:]).reshape(n, 4, len(ALONG), 4, 2)  # block, turn, direction, corner
    distance, b = cKDTree(centre).query(guess.mean(axis=3)) if n else (np.zeros((0, 4, 4)), np.zeros((0, 4, 4), int))
    a = np.arange(n)[:, None, None]
    near = (b != a) & (distance <= (side[a] + side[b]) / 6)
    # The other block's corners against the guess, in each of its four turns: the best turn and its largest gap.
    other = pts[b][..., roll, :]  # (n, turn, direction, its turn, corner, 2)
    gap = np.linalg.norm(other - guess[:, :, :, None], axis=-1).max(axis=-1)
    turn_b = gap.argmin(axis=-1)
    near &= np.take_along_axis(gap, turn_b[..., None], axis=-1)[..., 0] <= (side[a] + side[b]) / 4
    found = {}
    for i, t, d in zip(*np.nonzero(near)):
        found.setdefault((int(i), int(t)), {})[ALONG[d]] = (int(b[i, t, d]), int(turn_b[i, t, d]))
    return lambda block, turn: found.get((block, turn), {})


def name_corners(pattern: Pattern, quads: np.ndarray, tags, turns, n_corners: int) -> np.ndarray:
    """The template name of every image corner, from the voted blocks.

    Parameters
    ----------
    pattern : Pattern
    quads : ndarray (B, 4) int
        Corner indices in image order.
    tags : sequence of str
        Voted tags ("" for none).
    turns : ndarray (B,) int
    n_corners : int
        Corners in the image.

    Returns
    -------
    ndarray (n_corners,) object
        ``OWNER:PATCH_rRcC``, or None for a corner no block names or two blocks name differently.
    """
    names = np.full(n_corners, None, dtype=object)
    conflict = np.zeros(n_corners, bool)
    for quad, text, turn in zip(np.asarray(quads, dtype=int).reshape(-1, 4), tags, turns):
        located = pattern.locate(str(text)) if text else None
        if located is None or turn < 0:
            continue
        patch, r, c = located
        for p, corner in enumerate(quad):
            vr, vc = patch.block_vertices(r, c)[(p - turn) % 4]
            name = patch.corner_name(vr, vc)
            if names[corner] is None:
                names[corner] = name
            elif names[corner] != name:
                conflict[corner] = True
    names[conflict] = None
    # One name on two image corners: neither is trusted.
    count = Counter(n for n in names if n is not None)
    for k, name in enumerate(names):
        if name is not None and count[name] > 1:
            names[k] = None
    return names


def _uses(quads, tags, n_corners: int):
    """Blocks as (B, 4) corner indices, which of them are voted (B,), and how many voted blocks use each corner (K,)."""
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
    quads, voted, uses = _uses(quads, tags, len(xy))
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
    quads, voted, uses = _uses(quads, tags, len(xy))
    out = np.zeros(len(quads), bool)
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
            if min(own, opposite) - max(black) < MIN_CROSS * max(own - 0.5 * sum(black), 1.0):
                out[k] = True
                break
    return out
