"""Voting over the template: misread tags and turns are corrected by their patch-mates, corners are named."""

from __future__ import annotations

import numpy as np

from handcap.patterns import session_pattern
from handcap.detect.checks import unconfirmed
from handcap.detect.voting import name_corners, vote

PATTERN = session_pattern(("right",), ("cube2x2",))


def _reads(patches, rng):
    """Blocks of the given patches as a detector would report them: corner indices in a random image order."""
    index, quads, text, turn, truth_names = {}, [], [], [], []
    for patch in patches:
        for tag, r, c in patch.blocks():
            ids = []
            for v in patch.block_vertices(r, c):
                name = patch.corner_name(*v)
                if name not in index:
                    index[name] = len(index)
                    truth_names.append(name)
                ids.append(index[name])
            shift = int(rng.integers(4))
            quads.append(np.roll(ids, -shift))
            text.append(tag)
            turn.append((-shift) % 4)
    return np.array(quads), np.array(text), np.array(turn), np.array(truth_names, dtype=object)


def test_clean_reads_pass_and_name_every_corner():
    rng = np.random.default_rng(0)
    patches = PATTERN.of_owner("right")[:6] + PATTERN.of_owner("right")[15:]
    quads, text, turn, truth = _reads(patches, rng)
    tags, turns, changed = vote(PATTERN, quads, text, turn)
    assert (tags == text).all() and (turns == turn).all() and changed == 0
    names = name_corners(PATTERN, quads, tags, turns, len(truth))
    assert list(names) == list(truth)


def test_misreads_are_corrected_by_their_patch_mates():
    rng = np.random.default_rng(1)
    quads, text, turn, truth = _reads(PATTERN.of_owner("right"), rng)
    noisy_text, noisy_turn = text.copy(), turn.copy()
    bad = rng.random(len(text)) < 0.15
    tags_all = PATTERN.tags
    for b in np.flatnonzero(bad):
        kind = rng.integers(3)
        if kind == 0:
            noisy_text[b] = tags_all[int(rng.integers(len(tags_all)))]  # a wrong tag, maybe of another patch
        elif kind == 1:
            noisy_turn[b] = (turn[b] + int(rng.integers(1, 4))) % 4  # a wrong turn
        else:
            noisy_text[b], noisy_turn[b] = "", -1  # unread
    tags, turns, changed = vote(PATTERN, quads, noisy_text, noisy_turn)
    kept = tags != ""
    assert bad.sum() > 10 and changed > 0
    assert kept[noisy_text != ""].mean() > 0.97  # patches of one or two blocks cannot outvote a misread
    assert not kept[noisy_text == ""].any()  # a quad the reader saw no tag in is never placed
    assert (tags[kept] == text[kept]).all() and (turns[kept] == turn[kept]).all()
    names = name_corners(PATTERN, quads, tags, turns, len(truth))
    named = np.array([n is not None for n in names])
    assert named.mean() > 0.95 and all(n == t for n, t in zip(names[named], truth[named]))


def test_a_tag_read_twice_is_dropped_and_a_lone_block_keeps_its_reading():
    rng = np.random.default_rng(2)
    quads, text, turn, truth = _reads(PATTERN.of_owner("cube2x2")[:1], rng)
    tags, turns, _ = vote(PATTERN, quads, text, turn)
    assert (tags == text).all()
    # The same tag on a block far away (no shared corner) in the same image: both dropped.
    far = quads[:1] + 1000
    tags, _, _ = vote(PATTERN, np.r_[quads, far], np.r_[text, text[:1]], np.r_[turn, turn[:1]])
    assert tags[0] == "" and tags[-1] == ""


def test_a_false_quad_sharing_a_corner_is_not_placed_when_pixels_are_given():
    """A quad that shares one corner with a block but does not lie across it is no diagonal neighbour."""
    patch = PATTERN.of_owner("right")[0]
    (t0, r0, c0), (t1, r1, c1) = [b for b in patch.blocks() if b[1] == 0][:1] + \
        [b for b in patch.blocks() if (b[1], b[2]) == (1, 1)][:1]
    assert (r0, c0) == (0, 0)
    # Image: grid vertex (r, c) at pixel (10 c, 10 r); block (0, 0) and its true neighbour (1, 1) share (1, 1).
    xy = np.array([[0, 0], [10, 0], [10, 10], [0, 10], [20, 10], [20, 20], [10, 20],  # the two true blocks
                   [14, 3], [13, 8]], float)  # two false corners: a quad (1,1)-(14,3)-... beside block 0
    quads = np.array([[0, 1, 2, 3], [2, 4, 5, 6], [2, 1, 7, 8]])
    text = np.array([t0, "ZZ", "ZZ"])  # the other two misread (as no tag of the template)
    rotation = np.array([0, 1, 2])
    tags, turns, _ = vote(PATTERN, quads, text, rotation)
    # Without pixels the walk places the false quad at (1, 1) too: the tag is then seen twice, and both go.
    assert list(tags) == [t0, "", ""]
    tags, turns, _ = vote(PATTERN, quads, text, rotation, xy=xy)
    assert list(tags) == [t0, t1, ""] and list(turns[:2]) == [0, 0]
    # A quad the reader saw no tag in is not placed, even where it lies right.
    tags, _, _ = vote(PATTERN, quads, np.array([t0, "", "ZZ"]), rotation, xy=xy)
    assert list(tags) == [t0, "", ""]


def test_a_lone_unsure_reading_is_not_trusted():
    patch = PATTERN.of_owner("right")[0]
    tag = patch.blocks()[0][0]
    quads, text, rotation = np.array([[0, 1, 2, 3]]), np.array([tag]), np.array([0])
    assert vote(PATTERN, quads, text, rotation, np.array([0.4]), min_support=0.5)[0][0] == ""
    assert vote(PATTERN, quads, text, rotation, np.array([0.6]), min_support=0.5)[0][0] == tag


def test_the_two_squares_of_a_one_row_patch_confirm_each_other():
    # A 1 x 3 patch (a fingertip's) has two white squares that share no corner. Each read alone below the
    # trusted confidence is dropped; given the pixels, each is found where the other's corners put the square
    # two along the row, so their readings add up. A reading that does not match the template there, or a
    # block that lies elsewhere, is no confirmation.
    patch = next(p for p in PATTERN.patches if p.rows == 1 and p.cols == 3)
    (tag_a, _, ca), (tag_b, _, cb) = patch.blocks()
    assert (ca, cb) == (0, 2)
    xy = np.array([(c, r) for r in range(2) for c in range(4)], float) @ np.array([[24.0, 2.0], [-3.0, 22.0]])
    xy += (80.0, 60.0)
    quads = np.array([[0, 1, 5, 4], [2, 3, 7, 6]])  # image order = reading order (the patch upright)
    rotation, score = np.array([0, 0]), np.array([0.6, 0.6])
    text = np.array([tag_a, tag_b])
    assert list(vote(PATTERN, quads, text, rotation, score, min_support=0.9)[0]) == ["", ""]
    assert list(vote(PATTERN, quads, text, rotation, score, min_support=0.9, xy=xy)[0]) == [tag_a, tag_b]
    wrong = np.array([tag_a, tag_a])
    assert list(vote(PATTERN, quads, wrong, rotation, score, min_support=0.9, xy=xy)[0]) == ["", ""]
    far = xy.copy()
    far[[2, 3, 6, 7]] += (30.0, 0.0)  # the second square a whole square further along
    assert list(vote(PATTERN, quads, text, rotation, score, min_support=0.9, xy=far)[0]) == ["", ""]


def test_unconfirmed_blocks_must_be_parallelograms():
    # A flat 4 x 4 board, 20 px squares, slightly sheared (a parallelogram view): the white squares (r + c even)
    # share their inner corners with their diagonal neighbours.
    grid = np.array([(c, r) for r in range(5) for c in range(5)], float)
    xy = grid @ np.array([[20.0, 3.0], [4.0, 18.0]]) + 50.0
    quads = np.array([(r * 5 + c, r * 5 + c + 1, (r + 1) * 5 + c + 1, (r + 1) * 5 + c)
                      for r in range(4) for c in range(4) if (r + c) % 2 == 0])
    tags = np.array(["AB"] * len(quads))
    assert not unconfirmed(quads, tags, xy).any()
    # A false corner 3 px off (15 % of a side) on the board's outer corner, which only one block uses: that
    # block goes.
    moved = xy.copy()
    moved[0] += (3.0, 0.0)
    assert list(np.flatnonzero(unconfirmed(quads, tags, moved))) == [0]
    # The same shift on the corner that the blocks at (0, 0) and (1, 1) share: (1, 1) has all four corners
    # confirmed by its neighbours and stays; (0, 0), with its outer corners unconfirmed, goes.
    inner = xy.copy()
    inner[6] += (3.0, 0.0)
    assert list(np.flatnonzero(unconfirmed(quads, tags, inner))) == [0]
    # A 1 px shift keeps the shape within the bound.
    slight = xy.copy()
    slight[0] += (1.0, 0.0)
    assert not unconfirmed(quads, tags, slight).any()
    # Blocks not voted are never dropped.
    assert not unconfirmed(quads, np.array([""] * len(quads)), moved).any()
    # A block whose own reading the reader trusts is kept whatever its shape; the others are still tested.
    trusted = np.zeros(len(quads), bool)
    trusted[0] = True
    assert not unconfirmed(quads, tags, moved, trusted).any()
    trusted[:] = [False] + [True] * (len(quads) - 1)
    assert list(np.flatnonzero(unconfirmed(quads, tags, moved, trusted))) == [0]
    # A weak corner that only one voted block uses drops that block whatever its shape and reading; a weak
    # corner two voted blocks share does not.
    score = np.full(len(xy), 0.99)
    score[0] = 0.6
    assert list(np.flatnonzero(unconfirmed(quads, tags, xy, np.ones(len(quads), bool), score))) == [0]
    score[0], score[6] = 0.99, 0.6
    assert not unconfirmed(quads, tags, xy, np.ones(len(quads), bool), score).any()
    # A trusted reading vouches for the shape only when the block's lone corners are sure: with the bent
    # block's moved corner at 0.8 (above the weak bound) it goes again.
    score[6] = 0.99
    assert not unconfirmed(quads, tags, moved, np.ones(len(quads), bool), score).any()
    score[0] = 0.8
    assert list(np.flatnonzero(unconfirmed(quads, tags, moved, np.ones(len(quads), bool), score))) == [0]
    # A reading that agrees with the vote, below the reader's gate (not trusted), vouches for the shape when
    # the lone corners are surer still (0.98); at 0.97 the bent block goes, and without the agreement too.
    untrusted, agreed = np.zeros(len(quads), bool), np.ones(len(quads), bool)
    score[0] = 0.985
    assert not unconfirmed(quads, tags, moved, untrusted, score, agreed).any()
    assert list(np.flatnonzero(unconfirmed(quads, tags, moved, untrusted, score))) == [0]
    agreed[0] = False
    assert list(np.flatnonzero(unconfirmed(quads, tags, moved, untrusted, score, agreed))) == [0]
    agreed[0], score[0] = True, 0.97
    assert list(np.flatnonzero(unconfirmed(quads, tags, moved, untrusted, score, agreed))) == [0]
    # The weak-corner rule still wins over an agreeing reading.
    score[0] = 0.6
    assert list(np.flatnonzero(unconfirmed(quads, tags, xy, untrusted, score, agreed))) == [0]
    # An agreeing reading vouches for a bend up to AGREED_MAX_DEFECT (0.25 of a side) only: the corner moved
    # 4 px (0.2 of a side) keeps the block, 6 px (0.3) drops it.
    score[0] = 0.99
    for shift, dropped in ((4.0, []), (6.0, [0])):
        bent = xy.copy()
        bent[0] += (shift, 0.0)
        assert list(np.flatnonzero(unconfirmed(quads, tags, bent, untrusted, score, agreed))) == dropped


def test_a_block_read_as_another_tag_needs_some_probability_of_its_voted_one():
    grid = np.array([(c, r) for r in range(5) for c in range(5)], float)
    xy = grid @ np.array([[20.0, 3.0], [4.0, 18.0]]) + 50.0
    quads = np.array([(r * 5 + c, r * 5 + c + 1, (r + 1) * 5 + c + 1, (r + 1) * 5 + c)
                      for r in range(4) for c in range(4) if (r + c) % 2 == 0])
    tags, score = np.array(["AB"] * len(quads)), np.full(len(xy), 0.99)
    agreed = np.ones(len(quads), bool)
    unlikely = np.full(len(quads), 1e-6)
    # Blocks the reader read as their voted tags: the probability does not matter.
    assert not unconfirmed(quads, tags, xy, None, score, agreed, unlikely).any()
    # Read as other tags, with the block at (0, 0) not voted: (0, 2) has two lone corners (used by no other voted
    # block), the corner block (3, 3) three, (1, 1) one (the one it shared with (0, 0)), (2, 2) none. With its
    # voted tag at 1e-6 a block with two or more goes; at 1e-3 none does.
    agreed[:] = False
    tags[0] = ""
    uses = np.bincount(quads[1:].ravel(), minlength=len(xy))
    lone = np.array([(uses[q] <= 1).sum() for q in quads])
    assert list(lone[1:]) == [2, 1, 2, 2, 0, 2, 3]
    assert list(np.flatnonzero(unconfirmed(quads, tags, xy, None, score, agreed, unlikely))) \
        == [b for b in range(1, len(quads)) if lone[b] >= 2]
    assert not unconfirmed(quads, tags, xy, None, score, agreed, np.full(len(quads), 1e-3)).any()


def test_a_lone_corner_must_show_the_white_square_across_it():
    from handcap.detect.checks import uncrossed
    from handcap.patterns.pattern import Pattern, Patch

    # One patch of 2 x 2 squares: white "AC" at (0, 0) and "EF" at (1, 1) meet at vertex (1, 1).
    pattern = Pattern((Patch("p", "right", "palm", (("AC", ""), ("", "EF"))),))
    image = np.full((100, 100), 128, np.uint8)
    image[20:60, 20:60] = 30  # the patch's black squares ...
    image[20:40, 20:40] = 230  # ... and its two white ones, 20 px each
    image[40:60, 40:60] = 230
    xy = np.array([[20, 20], [40, 20], [40, 40], [20, 40]], float) - 0.5  # AC's corners, reading order
    quads, tags, turns = np.array([[0, 1, 2, 3]]), np.array(["AC"]), np.array([0])
    # Only AC is voted, so its corner (1, 1) is lone; the template puts EF across it, and the image shows it.
    assert not uncrossed(pattern, image, quads, tags, turns, xy).any()
    hidden = image.copy()
    hidden[40:70, 40:70] = 60  # a dark occluder over EF (a mid-grey one, 110, would pass: 0.25 of the contrast)
    assert uncrossed(pattern, hidden, quads, tags, turns, xy).all()
    # The same turned block (its corners listed from another one) is judged the same.
    turned = np.array([[1, 2, 3, 0]])
    assert uncrossed(pattern, hidden, turned, tags, np.array([3]), xy).all()
    assert not uncrossed(pattern, image, turned, tags, np.array([3]), xy).any()
    # A corner on the patch's edge is not checked, nor one another voted block confirms, nor an unvoted block.
    edge = Pattern((Patch("p", "right", "palm", (("AC", ""), ("", ""))),))
    assert not uncrossed(edge, hidden, quads, tags, turns, xy).any()
    assert not uncrossed(pattern, hidden, quads, np.array([""]), turns, xy).any()
    both = np.array([[0, 1, 2, 3], [2, 4, 5, 6]])
    xy2 = np.vstack([xy, np.array([[60, 40], [60, 60], [40, 60]]) - 0.5])
    assert not uncrossed(pattern, hidden, both, np.array(["AC", "EF"]), np.array([0, 0]), xy2).any()
