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
confirm corner by corner is then checked (:mod:`handcap.detect.checks`, :mod:`handcap.detect.checker`).
The corners of the blocks that remain are named from the template
(``OWNER:PATCH_rRcC``); a corner given two different names by its blocks is
dropped.
"""

from __future__ import annotations

from collections import Counter, defaultdict, deque

import numpy as np
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
        Image corners (pixels): where the walk may step (:func:`tally`).

    Returns
    -------
    tags : ndarray (B,) str
        The voted tag of each block, "" where it is dropped.
    turns : ndarray (B,) int
        The voted rotation (-1 where dropped).
    changed : int
        Blocks whose reading the vote corrected.
    """
    votes, _ = tally(pattern, quads, text, rotation, score, xy)
    n = len(votes)
    tags = np.full(n, "", dtype="<U2")
    turns = np.full(n, -1)
    for b, counter in enumerate(votes):
        ranked = counter.most_common(1)
        if not ranked or ranked[0][1] < min_support or ranked[0][1] < MAJORITY * sum(counter.values()):
            continue
        tags[b], turns[b] = ranked[0][0]
    tags, turns = unique_tags(tags, turns)
    changed = int(sum(1 for b in range(n) if tags[b] and text[b] and tags[b] != text[b]))
    return tags, turns, changed


def unique_tags(tags, turns):
    """``tags`` and ``turns`` with every tag that two blocks of one image hold dropped from both (a tag seen twice
    in one image cannot be trusted; DexterCap drops such pairs too).

    Parameters
    ----------
    tags : ndarray (B,) str
        Voted tags ("" for none).
    turns : ndarray (B,) int

    Returns
    -------
    tags : ndarray (B,) str
    turns : ndarray (B,) int
        Copies, "" and -1 where dropped.
    """
    tags, turns = np.array(tags, dtype="<U2"), np.array(turns, dtype=int)
    seen = Counter(t for t in tags if t)
    twice = np.array([bool(t) and seen[t] > 1 for t in tags], bool)
    tags[twice], turns[twice] = "", -1
    return tags, turns


def tally(pattern: Pattern, quads: np.ndarray, text, rotation, score=None, xy=None) -> tuple[list, list]:
    """Every read block's walk over the template (see the module docstring): the votes each block gets.

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
    weights : list of Counter
        Per block, (tag, turn) -> the summed confidence of the readings whose walks placed it so.
    counts : list of Counter
        Per block, (tag, turn) -> how many readings placed it so.
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
    votes, counts = [Counter() for _ in range(n)], [Counter() for _ in range(n)]
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
            counts[b][(patch.tags[r][c], turn)] += 1
    return votes, counts


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
