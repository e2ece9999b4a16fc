"""Naming a camera's unread white squares from the other cameras (handcap.detect.views), against synth's truth."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from handcap.detect.naming import GATE_PX
from handcap.detect.views import name_from_views

CAMERA = 0  # the camera whose squares are left unread


@pytest.fixture(scope="module")
def take(square_take):
    """A calibration take of 8 cameras at 4 Hz (see ``square_take``)."""
    return square_take(rate=4.0, frames=4, cameras=8)


def _chosen(take, count=40):
    """``count`` of the blocks camera CAMERA sees whole and two other cameras see too, spread over the take."""
    d = take.capture.detections
    views = np.zeros((4, len(take.names)), int)
    np.add.at(views, (d["frame"], d["marker"]), 1)
    mine = [k for k, b in enumerate(take.blocks) if b[1] == CAMERA and views[b[2], d["marker"][b[4]]].min() >= 3]
    return mine[:: max(len(mine) // count, 1)][:count]


def test_unread_squares_take_the_tags_and_corner_names_the_other_cameras_give(take):
    capture, pattern, names, blocks = take.capture, take.pattern, take.names, take.blocks
    chosen = _chosen(take)
    arrays, unread = take.without(chosen)
    named = name_from_views(arrays, unread, capture.rig, pattern, progress=False)
    # Refused: squares with a corner within the gate of another patch's corner (two patches that abut).
    assert named.squares + named.refused == named.unread == len(chosen) and named.refused <= 3
    assert not named.warnings
    a, n0 = named.arrays, len(arrays["block_text"])
    assert a["block_from_views"].sum() == named.squares and not a["block_from_views"][:n0].any()
    got = {(str(t), int(c), int(f)): xy for t, c, f, xy in zip(a["block_text"][n0:], a["block_camera"][n0:],
                                                                a["block_frame"][n0:], a["block_xy"][n0:])}
    assert len(got) == named.squares
    for k in chosen:
        tag, c, f, xy, _ = blocks[k]
        if (tag, c, f) in got:  # the tag, its corners in reading order
            np.testing.assert_allclose(got[(tag, c, f)], xy, atol=1e-4)
    # Every corner row added names the corner the truth gives at that pixel.
    d, r0 = capture.detections, len(arrays["frame"])
    truth = {(int(f), int(c), f"right:{d['marker_names'][m]}"): xy
             for f, c, m, xy in zip(d["frame"], d["camera"], d["marker"], d["xy"])}
    added = [truth[(int(f), int(c), str(names[m]))] - xy
             for f, c, m, xy in zip(a["frame"][r0:], a["camera"][r0:], a["marker"][r0:], a["xy"][r0:])]
    assert named.corners == len(added) >= 3 * named.squares and np.abs(added).max() < 1e-4


def test_a_square_off_its_place_or_a_tag_read_elsewhere_names_nothing(take):
    capture, pattern, blocks = take.capture, take.pattern, take.blocks
    chosen = _chosen(take, 12)
    arrays, unread = take.without(chosen)
    moved = [replace(u, xy=u.xy + np.array([2 * GATE_PX, 0.0])) for u in unread]
    assert name_from_views(arrays, moved, capture.rig, pattern, progress=False).squares == 0
    # The camera read the square's tag at another white square of the frame: refused.
    elsewhere = dict(arrays)
    extra = np.array([blocks[k][0] for k in chosen], dtype="<U2")
    elsewhere["block_text"] = np.concatenate([arrays["block_text"], extra])
    elsewhere["block_camera"] = np.concatenate([arrays["block_camera"], [blocks[k][1] for k in chosen]])
    elsewhere["block_frame"] = np.concatenate([arrays["block_frame"], [blocks[k][2] for k in chosen]])
    elsewhere["block_xy"] = np.concatenate([arrays["block_xy"], np.array([blocks[k][3] + 50 for k in chosen])])
    elsewhere["block_score"] = np.ones(len(elsewhere["block_text"]))
    assert name_from_views(elsewhere, unread, capture.rig, pattern, progress=False).squares == 0


def test_a_camera_off_its_pose_is_mended_on_its_own_named_corners(take):
    capture, pattern = take.capture, take.pattern
    arrays, unread = take.without(_chosen(take, 12))
    truth = name_from_views(arrays, unread, capture.rig, pattern, progress=False)
    # The rig's camera turned by a degree (its projections 50-80 px off): the affine map that takes them onto the
    # corners the camera named in the image takes the unread squares' too, so the same squares get the same tags.
    cameras = list(capture.rig.cameras)
    cameras[CAMERA] = replace(cameras[CAMERA], rotation=np.asarray(cameras[CAMERA].rotation) + [0.0, 0.0175, 0.0])
    turned = replace(capture.rig, cameras=tuple(cameras))
    mended = name_from_views(arrays, unread, turned, pattern, progress=False)
    assert mended.squares == truth.squares > 0
    for key in ("block_text", "block_frame", "block_xy", "marker", "xy"):
        np.testing.assert_array_equal(mended.arrays[key], truth.arrays[key])
    # Without the camera's named corners nothing mends it, and its projections miss the squares by far.
    alone = dict(arrays)
    mine = arrays["camera"] == CAMERA
    for key in ("frame", "camera", "marker", "xy", "score"):
        alone[key] = arrays[key][~mine]
    assert name_from_views(alone, unread, turned, pattern, progress=False).squares == 0
    assert name_from_views(alone, unread, capture.rig, pattern, progress=False).squares > 0


def test_squares_facing_away_are_not_taken_and_views_that_disagree_are_said(take):
    capture, pattern = take.capture, take.pattern
    arrays, unread = take.without(_chosen(take, 12))
    # The camera's read squares go round the other way (a mirrored image): every square faces away from it.
    mirrored = dict(arrays, block_xy=np.where((arrays["block_camera"] == CAMERA)[:, None, None],
                                              arrays["block_xy"][:, ::-1], arrays["block_xy"]))
    assert name_from_views(mirrored, unread, capture.rig, pattern, progress=False).squares == 0
    # A rig whose other cameras are turned by a degree or two each: no two of them agree on the corners.
    rng = np.random.default_rng(1)
    cameras = [camera if c == CAMERA else replace(camera, rotation=np.asarray(camera.rotation) + rng.normal(0, 0.03, 3))
               for c, camera in enumerate(capture.rig.cameras)]
    named = name_from_views(arrays, unread, replace(capture.rig, cameras=tuple(cameras)), pattern, progress=False)
    assert named.squares == 0 and "disagree" in named.warnings[0]


def test_one_camera_names_nothing_and_raises_nothing(take):
    capture, pattern = take.capture, take.pattern
    arrays, unread = take.without(_chosen(take, 4))
    mine = arrays["camera"] == CAMERA
    alone = dict(arrays, camera_names=arrays["camera_names"][:1], frame=arrays["frame"][mine],
                 camera=arrays["camera"][mine], marker=arrays["marker"][mine], xy=arrays["xy"][mine],
                 score=arrays["score"][mine])
    named = name_from_views(alone, unread, capture.rig, pattern, progress=False)
    assert named.squares == 0 and named.unread == 4 and not named.warnings
