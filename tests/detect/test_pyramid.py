"""Large squares (a photograph taken close to the patches) are read at a halved level of the image, their positions
mapped back to the image's pixels; frames with small squares are searched once, as before."""

from __future__ import annotations

from dataclasses import replace

import cv2
import numpy as np
import pytest

from handcap.detect import pipeline
from handcap.detect.evaluation import evaluate_detector
from handcap.detect.networks import load_corner_net, load_reader, load_refiner
from handcap.detect.pipeline import HALVABLE, LARGE_SQUARE, Detector, ImageDetections, _halvable, _too_large, look_again
from handcap.detect.scenes import PageMaker
from handcap.patterns import session_pattern
from handcap.synth.pages import PageLook


@pytest.fixture(scope="module")
def networks():
    return {"corner_net": load_corner_net(int8=True), "reader": load_reader(), "refiner": load_refiner(int8=True)}


@pytest.fixture(scope="module")
def close_photos():
    """Two photographs of a printed sheet with 60 px squares (a phone about 20 cm from 5 mm squares)."""
    maker = PageMaker(21, look=PageLook(square_px=(60.0, 60.0), tilt_deg=(0.0, 25.0), curl=(0.0, 0.5),
                                        occluders=(0, 0), size=(1600, 1200), glint=0.0))
    return [maker.scene() for _ in range(2)]


def test_large_squares_are_read_at_a_halved_level(networks, close_photos):
    pattern = session_pattern()
    single = evaluate_detector(Detector(**networks, pattern=pattern, pyramid=False), close_photos)
    pyramid = evaluate_detector(Detector(**networks, pattern=pattern), close_photos)
    assert pyramid.blocks > 60
    # Searched at their own size, the glyphs' strokes break the blocks up; halved, the squares are 30 px.
    assert single.right < 0.5 * pyramid.right
    assert pyramid.right >= 0.9 * pyramid.blocks and pyramid.wrong == 0


def test_positions_from_a_halved_level_are_in_the_images_pixels(networks, close_photos):
    detector = Detector(**networks, pattern=session_pattern())
    errors = []
    for scene in close_photos:
        found = detector.image(scene.image)
        named = [(n, xy) for n, xy in zip(found.names, found.corners) if n is not None and n in scene.projected]
        assert len(named) > 50
        errors += [xy - scene.projected[n] for n, xy in named]
    errors = np.array(errors)
    # Pixel centres mapped right: no half-pixel bias, and a tenth of a pixel typical (measured 0.08 px).
    assert np.abs(np.median(errors, axis=0)).max() < 0.1
    assert np.median(np.linalg.norm(errors, axis=1)) < 0.2


def test_frames_with_small_squares_are_searched_once(networks, scenes):
    alphabet = "0123456789ACEFHPUY"
    single = Detector(**networks, alphabet=alphabet, pyramid=False)
    pyramid = Detector(**networks, alphabet=alphabet)
    for scene in scenes[:2]:
        a, b = single.image(scene.image), pyramid.image(scene.image)
        assert len(a.block_text) > 5 and not _too_large(a)
        np.testing.assert_array_equal(b.corners, a.corners)
        np.testing.assert_array_equal(b.block_text, a.block_text)


def _blocks(side: float, count: int) -> ImageDetections:
    """``count`` blocks of ``side`` pixels, among 10 corners."""
    square = np.array([[0.0, 0.0], [side, 0.0], [side, side], [0.0, side]])
    return ImageDetections(np.zeros((10, 2)), np.zeros(10), np.zeros(10, object), np.full(count, "AB"),
                           np.repeat(square[None], count, axis=0), np.ones(count), 0)


def test_a_level_is_too_large_without_blocks_or_with_large_ones():
    # Without a block even where it found no corner: a photograph taken very close has corners too soft at its size.
    assert _too_large(_blocks(10.0, 0)) and _too_large(replace(_blocks(10.0, 0), corners=np.zeros((0, 2))))
    assert _too_large(_blocks(LARGE_SQUARE + 1.0, 3)) and not _too_large(_blocks(LARGE_SQUARE - 1.0, 3))


def _named_errors(detector, photos) -> np.ndarray:
    """Distances of the named corners from their truth, pixels."""
    errors = []
    for scene in photos:
        found = detector.image(scene.image)
        errors += [np.linalg.norm(xy - scene.projected[n]) for n, xy in zip(found.names, found.corners)
                   if n is not None and n in scene.projected]
    return np.array(errors)


def test_corners_found_at_a_halved_level_are_placed_again_in_the_finer_ones(networks, monkeypatch):
    # 120 px squares are read at a quarter of the image's size, where a corner is placed to a fraction of a pixel
    # four times the image's; placed again at half size (60 px squares), they land twice as close to the truth.
    maker = PageMaker(22, look=PageLook(square_px=(120.0, 120.0), tilt_deg=(0.0, 25.0), curl=(0.0, 0.5),
                                        occluders=(0, 0), size=(2400, 1800), glint=0.0))
    photos = [maker.scene() for _ in range(2)]
    detector = Detector(**networks, pattern=session_pattern())
    placed = _named_errors(detector, photos)
    monkeypatch.setattr(pipeline, "FINER_SIDE", 0.0)  # no finer level looked at: the positions only mapped back
    mapped = _named_errors(detector, photos)
    assert len(placed) == len(mapped) > 150 and placed.max() < 2.0
    assert np.median(placed) < 0.12 and np.median(mapped) > 1.4 * np.median(placed)  # measured 0.083 and 0.152


def test_a_photograph_too_close_for_any_corner_at_its_size_is_read_halved(networks):
    # 400 px squares out of focus (a phone a few cm away: blur of 6 px): at the image's size no corner is sharp enough
    # for the networks; halved four times the squares are 25 px and the blur a third of a pixel.
    maker = PageMaker(4, look=PageLook(square_px=(400.0, 400.0), tilt_deg=(0.0, 25.0), curl=(0.0, 0.5),
                                       occluders=(0, 0), size=(3000, 2250), glint=0.0))
    photos = [replace(p, image=cv2.GaussianBlur(p.image, (0, 0), 6.0)) for p in (maker.scene(), maker.scene())]
    single = Detector(**networks, pattern=session_pattern(), pyramid=False)
    assert sum(len(single.image(p.image).corners) for p in photos) == 0
    score = evaluate_detector(Detector(**networks, pattern=session_pattern()), photos)
    assert score.blocks > 20 and score.right >= 0.4 * score.blocks and score.wrong == 0  # measured 17 of 27


def test_look_again_places_points_near_corners_and_leaves_the_others(networks, close_photos):
    # Points 0.3-1 px from true corners (at their own, halved level: 30 px squares) go back to them; points in the
    # middle of white squares, where no corner is, stay.
    rng = np.random.default_rng(3)
    scene = close_photos[0]
    image = cv2.resize(scene.image, (scene.image.shape[1] // 2, scene.image.shape[0] // 2),
                       interpolation=cv2.INTER_AREA)
    truth = (scene.blocks.reshape(-1, 2) + 0.5) / 2 - 0.5
    truth = truth[(truth > 20).all(axis=1) & (truth < np.array(image.shape[::-1]) - 20).all(axis=1)][:200]
    angle = rng.uniform(0, 2 * np.pi, len(truth))
    near = truth + rng.uniform(0.3, 1.0, len(truth))[:, None] * np.c_[np.cos(angle), np.sin(angle)]
    inside = ((scene.blocks[:20].mean(axis=1) + 0.5) / 2 - 0.5)
    xy, moved = look_again(networks["refiner"], image, np.vstack([near, inside]))
    assert len(truth) > 100 and moved[:len(near)].mean() > 0.95 and not moved[len(near):].any()
    back = np.linalg.norm(xy[:len(near)][moved[:len(near)]] - truth[moved[:len(near)]], axis=1)
    assert np.median(back) < 0.15 and np.percentile(back, 90) < 0.4
    np.testing.assert_array_equal(xy[len(near):], np.vstack([near, inside])[len(near):])


def test_a_blurred_photograph_is_read_at_half_its_size_too(networks):
    # Squares of 20-30 px out of focus by 2 px (more than the networks learned): halved, the blur is 1 px and the
    # squares 10-15 px, and clearly more tags are read there.
    maker = PageMaker(41, look=PageLook(square_px=(20.0, 30.0), tilt_deg=(0.0, 30.0), occluders=(0, 1),
                                        size=(800, 600)))
    photos = [replace(p, image=cv2.GaussianBlur(p.image, (0, 0), 2.0)) for p in (maker.scene() for _ in range(4))]
    single = evaluate_detector(Detector(**networks, pattern=session_pattern(), pyramid=False), photos)
    halved = evaluate_detector(Detector(**networks, pattern=session_pattern()), photos)
    assert halved.blocks > 100 and halved.wrong == 0
    assert halved.right > 1.2 * single.right and halved.right >= 0.8 * halved.blocks, (single.right, halved.right)


def test_a_level_of_learned_squares_gives_way_only_to_clearly_more_tags():
    assert _halvable(_blocks(HALVABLE, 3)) and not _halvable(_blocks(HALVABLE - 1.0, 3))
    assert not _halvable(_blocks(HALVABLE, 0))
