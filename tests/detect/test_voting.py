"""Voting over the template: misread tags and turns are corrected by their patch-mates, corners are named."""

from __future__ import annotations

import numpy as np

from handcap.patterns import session_pattern
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
    assert kept.mean() > 0.97  # patches of one or two blocks cannot outvote a misread
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
