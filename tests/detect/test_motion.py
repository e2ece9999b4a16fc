"""Naming a camera's unread white squares from its neighbouring frames (handcap.detect.motion), against synth's
truth."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from handcap.detect.motion import name_from_frames
from handcap.detect.naming import GATE_PX, square_corners

FRAME = 60  # the frame whose squares camera 0 leaves unread


@pytest.fixture(scope="module")
def take(square_take):
    """A calibration take of 2 cameras filmed at 60 Hz, 2 s (see ``square_take``)."""
    return square_take(rate=60.0, frames=120, cameras=2)


def _chosen(take, count=30):
    """``count`` of the blocks camera 0 sees whole in frame FRAME and in the frames either side."""
    whole = {(b[0], b[1], b[2]) for b in take.blocks}
    mine = [k for k, b in enumerate(take.blocks) if b[1] == 0 and b[2] == FRAME
            and (b[0], 0, FRAME - 1) in whole and (b[0], 0, FRAME + 1) in whole]
    return mine[:: max(len(mine) // count, 1)][:count]


def test_unread_squares_take_the_tags_their_neighbouring_frames_give(take):
    chosen = _chosen(take)
    arrays, unread = take.without(chosen)
    named = name_from_frames(arrays, unread, take.pattern, progress=False)
    assert named.source == "the neighbouring frames" and named.unread == len(chosen) and not named.warnings
    # Most are named; the others lie where the camera names too few corners around them to fit the motion (synth
    # sees this camera's patches only in part).
    assert named.squares >= 0.6 * len(chosen) and len(named.left) == len(chosen) - named.squares - named.refused
    a, n0 = named.arrays, len(arrays["block_text"])
    truth = {(b[0], b[1], b[2]): b[3] for b in take.blocks}
    for text, c, f, xy in zip(a["block_text"][n0:], a["block_camera"][n0:], a["block_frame"][n0:],
                              a["block_xy"][n0:]):
        np.testing.assert_allclose(xy, truth[(str(text), int(c), int(f))], atol=1e-4)  # the tag, reading order
    assert a["block_from_views"][n0:].all() and not a["block_from_views"][:n0].any()
    # Every corner row added names the corner the truth gives at that pixel.
    d, r0 = take.capture.detections, len(arrays["frame"])
    true_xy = {(int(f), int(c), str(take.names[m])): xy for f, c, m, xy in zip(d["frame"], d["camera"], d["marker"],
                                                                                d["xy"])}
    added = [true_xy[(int(f), int(c), str(take.names[m]))] - xy
             for f, c, m, xy in zip(a["frame"][r0:], a["camera"][r0:], a["marker"][r0:], a["xy"][r0:])]
    assert named.corners == len(added) >= 3 * named.squares and np.abs(added).max() < 1e-4


def test_squares_off_their_place_or_without_neighbouring_frames_stay_unread(take):
    chosen = _chosen(take, 10)
    arrays, unread = take.without(chosen)
    moved = [replace(u, xy=u.xy + np.array([2 * GATE_PX, 0.0])) for u in unread]
    assert name_from_frames(arrays, moved, take.pattern, progress=False).squares == 0
    # The frames either side gone (the camera dropped them): nothing to map from.
    alone = dict(arrays)
    kept = ~((arrays["camera"] == 0) & (np.abs(arrays["frame"] - FRAME) == 1))
    for key in ("frame", "camera", "marker", "xy", "score"):
        alone[key] = arrays[key][kept]
    named = name_from_frames(alone, unread, take.pattern, progress=False)
    assert named.squares == 0 and len(named.left) == len(unread) and named.arrays["block_from_views"].sum() == 0


def test_frames_that_disagree_name_nothing(take):
    chosen = _chosen(take, 20)
    arrays, unread = take.without(chosen)
    before = name_from_frames(arrays, unread, take.pattern, progress=False)
    # In the frame after, the chosen squares' corners trade places in pairs (tags misread there, say): that frame
    # places each unread square's partner where the frame before places the square itself.
    tags, corners = square_corners(take.pattern, take.names)
    after = np.flatnonzero((arrays["camera"] == 0) & (arrays["frame"] == FRAME + 1))
    row = {int(arrays["marker"][r]): r for r in after}
    traded = dict(arrays, xy=arrays["xy"].copy())
    pairs = [[row[int(m)] for m in corners[list(tags).index(take.blocks[k][0])]] for k in chosen]
    for a, b in zip(pairs[0::2], pairs[1::2]):
        traded["xy"][a], traded["xy"][b] = arrays["xy"][b], arrays["xy"][a]
    named = name_from_frames(traded, unread, take.pattern, progress=False)
    assert before.squares >= 10 and named.squares < before.squares  # the rest: the frame before alone, right
    truth = {(b[0], b[1], b[2]): b[3] for b in take.blocks}
    a, n0 = named.arrays, len(arrays["block_text"])
    for text, c, f, xy in zip(a["block_text"][n0:], a["block_camera"][n0:], a["block_frame"][n0:],
                              a["block_xy"][n0:]):
        np.testing.assert_allclose(xy, truth[(str(text), int(c), int(f))], atol=1e-4)
