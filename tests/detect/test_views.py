"""Naming a camera's unread white squares from the other cameras (handcap.detect.views), against synth's truth."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from handcap import HandcapError
from handcap.detect.naming import GATE_PX
from handcap.detect.views import name_from_views, rebased
from handcap.multiview.detections import detections_of
from handcap.multiview.sync import Sync, estimate_sync

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


def test_cameras_not_triggered_together_name_on_their_own_clocks(square_take):
    # Eight cameras at 30 Hz, each started at its own moment: camera c's frame k is frame starts[c] + 3 k of a take
    # filmed at 90 Hz, so its offset is starts[c] / 3 frames.
    starts = [0, 1, 2, 3, 5, 6, 9, 2]
    take = square_take(rate=90.0, frames=60, cameras=8).unsynchronised(starts, 3)
    truth = np.array(starts) / 3
    d = take.capture.detections
    seen = np.zeros((take.frames, len(take.names), 8), bool)
    seen[d["frame"], d["marker"], d["camera"]] = True

    def views(frame, marker):  # cameras that see the marker at about the moment of camera 0's frame
        return sum(seen[min(max(round(frame - truth[c]), 0), take.frames - 1), marker, c] for c in range(8))

    mine = [k for k, b in enumerate(take.blocks)
            if b[1] == CAMERA and min(views(b[2], d["marker"][r]) for r in b[4]) >= 3]
    chosen = mine[:: max(len(mine) // 40, 1)][:40]
    arrays, unread = take.without(chosen)
    rig, pattern = take.capture.rig, take.pattern
    # Taken as synchronised, the views disagree: nothing is named, and the warning says what finds the offsets.
    plain = name_from_views(arrays, unread, rig, pattern, progress=False)
    assert plain.squares == 0 and "detect --sync auto" in plain.warnings[0]
    names = tuple(str(n) for n in arrays["camera_names"])
    given = name_from_views(arrays, unread, rig, pattern, progress=False,
                            sync=Sync(names, truth, names[0], np.nan, np.nan, 0))
    # Measured: 26 of the 40 (a square the other cameras saw only before their first frame stays unread).
    assert given.squares >= 20 and not given.warnings
    a, n0 = given.arrays, len(arrays["block_text"])
    want = {(take.blocks[k][0], take.blocks[k][2]): take.blocks[k][3] for k in chosen}
    for tag, c, f, xy in zip(a["block_text"][n0:], a["block_camera"][n0:], a["block_frame"][n0:], a["block_xy"][n0:]):
        assert c == CAMERA and (str(tag), int(f)) in want
        np.testing.assert_allclose(xy, want[(str(tag), int(f))], atol=1e-4)
    # The offsets found from the named corners name the same squares.
    found = estimate_sync(detections_of(arrays), rig)
    np.testing.assert_allclose(found.offsets, truth, atol=0.05)
    again = name_from_views(arrays, unread, rig, pattern, progress=False, sync=found)
    assert abs(again.squares - given.squares) <= 2
    np.testing.assert_array_equal(again.arrays["block_text"][n0:n0 + 10], a["block_text"][n0:n0 + 10])
    # A camera with no offset names nothing, and the others are named as before; offsets of other cameras, or of no
    # camera, are refused.
    unknown = name_from_views(arrays, unread, rig, pattern, progress=False,
                              sync=Sync(names, np.where(np.arange(8) == CAMERA, np.nan, truth), names[1], 0, 0, 0))
    assert unknown.squares == 0 and len(unknown.left) == len(unread)
    with pytest.raises(HandcapError, match="offsets are of cameras"):
        name_from_views(arrays, unread, rig, pattern, progress=False,
                        sync=Sync(names[:7], truth[:7], names[0], np.nan, np.nan, 0))
    with pytest.raises(HandcapError, match="no camera has an offset"):
        name_from_views(arrays, unread, rig, pattern, progress=False,
                        sync=Sync(names, np.full(8, np.nan), names[0], np.nan, np.nan, 0))


def test_offsets_counted_on_another_cameras_clock_name_the_same_moments():
    rng = np.random.default_rng(3)
    offsets, drift = rng.normal(0, 5, 4), rng.normal(0, 1e-3, 4)
    sync = Sync(("a", "b", "c", "d"), offsets, "a", 0.0, 0.0, 1, drift=drift)
    frames = np.arange(0.0, 500.0, 7.0)
    for c in range(4):
        on = rebased(sync, c)
        assert on.reference == sync.camera_names[c] and abs(on.offsets[c]) < 1e-12 and abs(on.drift[c]) < 1e-12
        for j in range(4):
            # Camera j's frame h and the frame of camera c that shows the same moment of the reference's clock.
            moment = frames + offsets[j] + drift[j] * frames
            mine = (moment - offsets[c]) / (1 + drift[c])
            np.testing.assert_allclose(frames + on.offsets[j] + on.drift[j] * frames, mine, atol=1e-9)
    assert rebased(None, 2) is None


def test_detect_finds_or_takes_the_offsets_it_names_with(square_take):
    from handcap.steps.detect import _offsets

    starts = [0, 2, 4, 1, 3, 5, 0, 2]
    take = square_take(rate=90.0, frames=60, cameras=8).unsynchronised(starts, 3)
    arrays, _ = take.without([])
    found, said = _offsets(arrays, take.capture.rig, None, 3.0)  # --sync auto
    np.testing.assert_allclose(found.offsets, np.array(starts) / 3, atol=0.05)
    assert not said and found.reference == "cam_0"
    # The hand turns between frames by more than the 0.1 px noise moves it: the views are moved along their curve,
    # and agree to 0.12 px (0.31 px along the straight line).
    assert found.after < 0.2
    # --sync CAM=FRAMES: counted from the first camera, however given.
    true = {f"cam_{c}": 1 + start / 3 for c, start in enumerate(starts)}
    given, said = _offsets(arrays, take.capture.rig, true, 3.0)
    np.testing.assert_allclose(given.offsets, np.array(starts) / 3)
    assert given.after < 0.5 < given.before and not said
    _, said = _offsets(arrays, take.capture.rig, {k: -v for k, v in true.items()}, 3.0)
    assert "agree worse with the given offsets" in said[0]
    mine = arrays["camera"] == 0
    one = dict(arrays, camera_names=arrays["camera_names"][:1],
               **{key: arrays[key][mine] for key in ("frame", "camera", "marker", "xy", "score")})
    assert _offsets(one, take.capture.rig, None, 3.0) == (None, [])
    # A hand that holds still tells no offset: nothing is named from the other cameras, and the warning says why.
    first = arrays["frame"] == 5
    still = dict(arrays, **{key: np.concatenate([arrays[key][first]] * 12)
                            for key in ("camera", "marker", "xy", "score")},
                 frame=np.repeat(np.arange(12), first.sum()), n_frames=np.array(12))
    found, said = _offsets(still, take.capture.rig, None, 3.0)
    assert found is None and "placed no camera" in said[0]
