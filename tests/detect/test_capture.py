"""The detector over a camera's frames: searching around the previous frame's patches finds what a search of
the whole frame finds, and a hand that jumps away is searched for again on the whole frame."""

from __future__ import annotations

from dataclasses import replace

import cv2
import numpy as np
import pytest

from handcap import HandcapError
from handcap.detect.capture import FULL_EVERY, Tracker, detect_capture
from handcap.detect.pipeline import ImageDetections, region_box
from handcap.detect.sources import frame_sources
from handcap.patterns import session_pattern

DEXTERCAP = "0123456789ACEFHPUY"  # the alphabet of the shared rendered scenes (tests/detect/conftest.py)
#: Where the scene sits in each frame, pixels: a slow drift, then a jump across the frame, then a drift again.
SHIFTS = [(0, 0), (6, 4), (12, 8), (18, 12), (640, 520), (646, 524)]


@pytest.fixture(scope="module")
def detector():
    from handcap.detect.networks import load_corner_net, load_reader, load_refiner  # loads torch
    from handcap.detect.pipeline import Detector

    return Detector(load_corner_net(int8=True), load_reader(), session_pattern(("right",), (), alphabet=DEXTERCAP),
                    refiner=load_refiner(int8=True))


def _film(scene, folder, shifts=SHIFTS):
    """The scene's image moved across a larger grey frame, one PNG per entry of ``shifts`` (default SHIFTS)."""
    h, w = scene.image.shape
    border = np.r_[scene.image[0], scene.image[-1], scene.image[:, 0], scene.image[:, -1]]
    rng = np.random.default_rng(5)
    folder.mkdir()
    for t, (dx, dy) in enumerate(shifts):
        frame = np.clip(rng.normal(np.median(border), 2.0, (h + 560, w + 680)), 0, 255).astype(np.uint8)
        frame[dy:dy + h, dx:dx + w] = scene.image
        cv2.imwrite(str(folder / f"{t:06d}.png"), frame)
    return folder


def test_tracked_frames_find_what_whole_frames_find(scenes, detector, tmp_path):
    sources = frame_sources([_film(scenes[0], tmp_path / "cam_0")])
    names = detector.pattern.corner_names()
    # The frames are searched as recorded (linear, as rendered): an auto response would search the first three both
    # ways, and whole (tests/detect/test_response.py).
    whole = detect_capture(detector, sources, names, 30.0, track=False, progress=False, response="linear")
    tracked = detect_capture(detector, sources, names, 30.0, progress=False, response="linear")
    # Frame 1 is searched whole (no motion seen yet); from frame 0 to 1 the patches moved little, so frames 2
    # and 3 are searched in the region. Frame 4 jumps: the region finds too little and the frame is searched
    # whole; frame 5 is searched whole too (the tracker waits two frames after a miss).
    assert whole.regions == 0 and tracked.regions == 2
    a, b = whole.arrays, tracked.arrays
    assert np.bincount(a["frame"], minlength=len(SHIFTS)).min() > 40  # named corners in every frame
    order_a = np.lexsort((a["marker"], a["frame"]))
    order_b = np.lexsort((b["marker"], b["frame"]))
    for key in ("frame", "marker"):
        np.testing.assert_array_equal(a[key][order_a], b[key][order_b])
    np.testing.assert_allclose(a["xy"][order_a], b["xy"][order_b], atol=1e-4)
    assert sorted(zip(a["block_frame"], a["block_text"])) == sorted(zip(b["block_frame"], b["block_text"]))
    # The drift moves the corners by the shift: positions in the whole frame's pixels.
    first = {m: xy for f, m, xy in zip(b["frame"], b["marker"], b["xy"]) if f == 0}
    moved = [xy - first[m] for f, m, xy in zip(b["frame"], b["marker"], b["xy"]) if f == 2 and m in first]
    np.testing.assert_allclose(np.median(moved, axis=0), SHIFTS[2], atol=0.05)


def _found(blocks: np.ndarray) -> ImageDetections:
    """Detections holding only the given blocks' corners (B, 4, 2), tagged "A0", "A1", ..."""
    b = len(blocks)
    return ImageDetections(blocks.reshape(-1, 2), np.ones(4 * b), np.full(4 * b, None, object),
                           np.array([f"A{k}" for k in range(b)]), blocks, np.ones(b), 0)


def test_the_tracker_searches_whole_when_the_region_may_miss():
    square = np.array([[0, 0], [10, 0], [10, 10], [0, 10]], float)
    hand = np.stack([square + [500 + 20 * k, 400 + 15 * k] for k in range(10)])  # 10 blocks, 190 x 145 px
    tracker = Tracker((1000, 1200))
    assert tracker.region() is None  # nothing seen yet: the whole frame
    tracker.update(_found(hand), whole=True)
    assert tracker.region() is None  # one frame: no motion seen yet
    tracker.update(_found(hand + [30, 20]), whole=True)
    assert tracker.region() is None  # moved 30 px where no motion was predicted: more than half the widening (24 px)
    tracker.update(_found(hand + [30, 20]), whole=True)
    assert tracker.region() is None  # stopped: the motion changed by 30 px again
    tracker.update(_found(hand + [30, 20]), whole=True)  # still again: search the region next
    box = tracker.region()
    pad = max(0.25 * 190, 48)
    np.testing.assert_allclose(box, [530 - pad, 420 - pad, 720 + pad, 565 + pad])
    hand = hand + [30, 20]
    assert not tracker.missed(_found(hand), box)
    assert not tracker.missed(_found(hand[:6]), box)
    assert tracker.missed(_found(hand[:5]), box)  # fewer than 60 % of the previous frame's blocks
    assert tracker.missed(_found(hand + [30, 0]), box)  # within two squares (20 px) of the right edge
    assert not tracker.missed(_found(hand + [-20, 0]), box)
    # A block read now that the last frame did not read, 20 px beyond the last frame's blocks: no sign.
    assert not tracker.missed(_found(np.concatenate([hand, [square + [510, 560]]])), box)
    assert tracker.missed(_found(hand[:0]), box)
    # At the image's own edge nothing lies beyond: no miss.
    edge = Tracker((585, 730))
    edge.update(_found(hand), whole=True)
    edge.update(_found(hand), whole=True)
    assert not edge.missed(_found(hand + [0, 10]), edge.region())
    # After a miss the frame is searched whole for 2 frames; a second miss in a row makes it 4.
    tracker.update(_found(hand), whole=True, missed=True)
    plan = []
    for _ in range(3):
        region = tracker.region()
        plan.append(region is None)
        tracker.update(_found(hand), whole=True, missed=region is not None)  # the region search misses again
    assert plan == [True, True, False] and tracker.wait == 4
    # Every FULL_EVERY-th frame is searched whole.
    steady = Tracker((1000, 1200))
    steady.update(_found(hand), whole=True)
    steady.update(_found(hand), whole=True)
    whole = []
    for _ in range(2 * FULL_EVERY):
        region = steady.region()
        whole.append(region is None)
        steady.update(_found(hand), whole=region is None)
    assert [k for k, w in enumerate(whole) if w] == [FULL_EVERY - 1, 2 * FULL_EVERY - 1]


def test_the_box_moves_on_with_a_steady_hand():
    # A hand moving 40 px a frame (more than half the widening, 24 px) at a steady pace: from the third frame
    # the box is searched, moved on by 40 px, and the blocks lie as far inside it as a still hand's do.
    square = np.array([[0, 0], [10, 0], [10, 10], [0, 10]], float)
    hand = np.stack([square + [500 + 20 * k, 400 + 15 * k] for k in range(10)])
    tracker = Tracker((1000, 1400))
    pad = max(0.25 * 190, 48)
    plan = []
    for k in range(5):
        region = tracker.region()
        moved = hand + [40 * k, 0]
        plan.append(region is not None)
        if region is not None:
            np.testing.assert_allclose(region, [500 + 40 * k - pad, 400 - pad, 690 + 40 * k + pad, 545 + pad])
            assert not tracker.missed(_found(moved), region)
        tracker.update(_found(moved), whole=region is None)
    assert plan == [False, False, False, True, True]
    np.testing.assert_allclose(tracker.motion, [40, 0])
    # The hand stops: the box searched next was moved on, and the hand sits at its edge, so that search missed.
    region = tracker.region()
    assert tracker.missed(_found(hand + [160, 0]), region)
    tracker.update(_found(hand + [160, 0]), whole=False, missed=True)
    assert tracker.region() is None and not tracker.steady


def test_the_motion_is_read_from_the_tags_both_frames_show():
    square = np.array([[0, 0], [10, 0], [10, 10], [0, 10]], float)
    hand = np.stack([square + [500 + 20 * k, 400 + 15 * k] for k in range(10)])
    tracker = Tracker((1000, 1200))
    tracker.update(_found(hand), whole=True)
    # Half the blocks hidden, the rest moved 5 px and listed in another order: the box's centre moved about
    # 50 px, the tags both frames read only 5.
    half = _found(hand[:5] + [5, 0])
    order = np.array([3, 0, 4, 1, 2])
    tracker.update(replace(half, block_text=half.block_text[order], block_xy=half.block_xy[order]), whole=True)
    assert tracker.steady and tracker.region() is not None
    # No tag in common: the box's centre says how far they moved.
    tracker.update(replace(half, block_text=np.array(["B0", "B1", "B2", "B3", "B4"])), whole=True)
    assert tracker.steady
    tracker.update(replace(_found(hand), block_text=np.array([f"C{k}" for k in range(10)])), whole=True)
    assert not tracker.steady and tracker.region() is None


@pytest.mark.parametrize("region, expected", [
    ((101.7, 51.2, 300.2, 200.9), (100, 50, 301, 201)),  # top-left down to even pixels, bottom-right up
    ((-50, -20, 90000, 90000), (0, 0, 640, 480)),  # clipped to the image
    ((630, 470, 640, 480), (608, 448, 640, 480)),  # at least MIN_REGION (32) pixels
])
def test_region_box(region, expected):
    assert region_box(region, (480, 640)) == expected


@pytest.mark.parametrize("region", [(0, 0, 10), (0, np.nan, 5, 5), "box"])
def test_bad_region_is_one_clear_error(region):
    with pytest.raises(HandcapError, match="a region is"):
        region_box(region, (480, 640))


class _Listed:
    """A stand-in for the detector: frame t (its first pixel's grey) shows the blocks ``shown(t)`` (B, 4, 2), tagged
    by their place in the list; a search of a region finds those wholly inside it."""

    def __init__(self, shown):
        self.shown, self.searches = shown, []

    def image(self, image, region=None):
        t = int(image[0, 0])
        blocks = self.shown(t)
        keep = ~np.isnan(blocks).any(axis=(1, 2))
        if region is not None:
            x0, y0, x1, y1 = region_box(region, image.shape)
            with np.errstate(invalid="ignore"):
                keep &= (blocks >= (x0, y0)).all(axis=(1, 2)) & (blocks < (x1, y1)).all(axis=(1, 2))
        self.searches.append((t, region is not None))
        return replace(_found(blocks[keep]), block_text=np.array([f"A{k}" for k in np.flatnonzero(keep)]))


def test_a_miss_the_whole_frame_does_not_confirm_makes_no_wait(tmp_path):
    # Frame 4 is blurred: half the blocks read, in the region and in the whole frame alike. That region search
    # "missed" (under 60 % of the last frame's blocks), but the whole frame read no more: frame 5 tries a region
    # again. In frame 9 the hand jumps away: the whole frame confirms that miss, so frames 10 and 11 are searched
    # whole before a region again.
    square = np.array([[0, 0], [10, 0], [10, 10], [0, 10]], float)
    hand = np.stack([square + [300 + 20 * k, 200 + 15 * k] for k in range(10)])
    folder = tmp_path / "cam_0"
    folder.mkdir()
    for t in range(13):
        cv2.imwrite(str(folder / f"{t:06d}.png"), np.full((500, 700), t, np.uint8))

    def shown(t):
        if t == 4:
            return np.where(np.isin(np.arange(10), [0, 2, 4, 6, 9])[:, None, None], hand, np.nan)
        return hand + [-250, 150] if t >= 9 else hand

    fake = _Listed(shown)
    run = detect_capture(fake, frame_sources([folder]), [], 20.0, progress=False, response="linear")
    searched = {}
    for t, in_region in fake.searches:
        searched.setdefault(t, []).append("region" if in_region else "whole")
    assert searched[4] == ["region", "whole"] and searched[5] == ["region"]
    assert searched[9] == ["region", "whole"] and searched[10] == ["whole"] and searched[11] == ["whole"]
    assert searched[12] == ["region"]
    assert run.regions == sum(v == ["region"] for v in searched.values())
    assert len(run.arrays["block_text"]) == 12 * 10 + 5


def _same_detections(a, b):
    """Two detections files' arrays alike: ids and texts exactly, pixels to float rounding (threads sum apart)."""
    assert a.keys() == b.keys()
    for key in a:
        if a[key].dtype.kind == "f":
            np.testing.assert_allclose(a[key], b[key], atol=1e-6, err_msg=key)
        else:
            np.testing.assert_array_equal(a[key], b[key], err_msg=key)


def test_cameras_in_processes_or_on_dask_give_the_same_detections(scenes, detector, tmp_path):
    # Two cameras, each its own drifting and jumping scene; the tracker's state is a camera's own, so detecting
    # them one per process (or on a Dask cluster) gives the rows of one camera after the other, as in one process.
    # The drift only (frames 2 and 3 searched in the region): the jump is the test above's.
    sources = frame_sources([_film(scenes[0], tmp_path / "cam_0", SHIFTS[:4]),
                             _film(scenes[1], tmp_path / "cam_1", SHIFTS[:4])])
    names = detector.pattern.corner_names()
    serial = detect_capture(detector, sources, names, 30.0, progress=False, response="linear")
    apart = detect_capture(detector, sources, names, 30.0, progress=False, response="linear", workers=2)
    assert np.bincount(serial.arrays["camera"]).min() > 100 and serial.regions == 4
    _same_detections(serial.arrays, apart.arrays)
    assert (apart.regions, apart.frames, apart.responses, apart.images) == (serial.regions, serial.frames,
                                                                           serial.responses, serial.images)
    assert [(u.camera, u.frame) for u in apart.unread] == [(u.camera, u.frame) for u in serial.unread]
    distributed = pytest.importorskip("distributed")
    with (distributed.LocalCluster(n_workers=1, threads_per_worker=2, processes=False,
                                   dashboard_address=None) as cluster,
          distributed.Client(cluster, set_as_default=False) as client):
        on_dask = detect_capture(detector, sources, names, 30.0, progress=False, response="linear", scheduler=client)
    _same_detections(serial.arrays, on_dask.arrays)


def test_a_bad_frame_in_a_worker_is_the_same_one_line_error(scenes, detector, tmp_path):
    sources = frame_sources([_film(scenes[0], tmp_path / "cam_0"), _film(scenes[1], tmp_path / "cam_1")])
    (h0, w0), (h1, w1) = scenes[0].image.shape, scenes[1].image.shape
    sizes = [(w0 + 680, h0 + 561), (w1 + 680, h1 + 561)]  # both cameras were calibrated a pixel taller
    with pytest.raises(HandcapError, match=r"^cam_0 frame 0: the image is \d+x\d+ px but the rig calibrated"):
        detect_capture(detector, sources, detector.pattern.corner_names(), 30.0, progress=False, sizes=sizes,
                       response="linear", workers=2)
