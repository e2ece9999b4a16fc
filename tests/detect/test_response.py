"""A camera's response to light: sRGB decoded to linear light as the standard says, and each camera's response
chosen on its own frames, so display-encoded frames read as their linear originals do and linear ones stay."""

from __future__ import annotations

from dataclasses import replace

import cv2
import numpy as np
import pytest

from handcap import HandcapError
from handcap.cli import main
from handcap.detect.capture import detect_capture
from handcap.detect.pipeline import ImageDetections
from handcap.detect.response import LOOKS, MOST_LOOKS, NEAR, ResponseChoice, block_contrast, linear_light
from handcap.detect.sources import ArrayFrames, frame_sources
from handcap.patterns import session_pattern

DEXTERCAP = "0123456789ACEFHPUY"  # the alphabet of the shared rendered scenes (tests/detect/conftest.py)


def _srgb(image: np.ndarray) -> np.ndarray:
    """Linear grey levels encoded as sRGB (IEC 61966-2-1's encoding, the inverse of what is tested)."""
    light = np.arange(256) / 255.0
    code = np.where(light <= 0.0031308, 12.92 * light, 1.055 * light ** (1 / 2.4) - 0.055)
    return cv2.LUT(image, np.clip(np.rint(255 * code), 0, 255).astype(np.uint8))


def test_linear_light_decodes_srgb_as_the_standard_says():
    levels = np.arange(256, dtype=np.uint8).reshape(16, 16)
    back = linear_light(_srgb(levels)).astype(int)
    assert np.abs(back - levels).max() <= 1  # sRGB holds the dark levels finer than linear: nothing lost
    ramp = linear_light(levels).ravel().astype(int)
    assert ramp[0] == 0 and ramp[255] == 255 and (np.diff(ramp) >= 0).all()
    assert ramp[128] == 55 and ramp[10] == 1  # 0.2159 and 0.0030 of white (the standard's table)
    with pytest.raises(HandcapError, match="--response 'gamma'"):
        ResponseChoice("gamma")


class _Counting:
    """A stand-in for the detector: an image whose first pixel is 200 (as recorded) reads 2 tags, decoded (147) 5,
    any other none; it counts its searches."""

    def __init__(self):
        self.searches = 0

    def image(self, image, region=None):
        self.searches += 1
        tags = {200: 2, 147: 5}.get(int(image[0, 0]), 0)
        return ImageDetections(np.zeros((0, 2)), np.zeros(0), np.zeros(0, object), np.array(["A0"] * tags),
                               np.zeros((tags, 4, 2)), np.ones(tags), 0)


@pytest.mark.parametrize("grey, response, searches", [(200, "srgb", 2 * LOOKS), (0, "linear", 2 * MOST_LOOKS)])
def test_the_choice_looks_at_a_few_frames_only(grey, response, searches):
    # Tags read both ways: chosen after LOOKS frames; none read: linear after MOST_LOOKS, not searched twice all take.
    fake, choice = _Counting(), ResponseChoice()
    frame = np.full((4, 4), grey, np.uint8)
    for _ in range(30):
        if choice.response is not None:
            break
        choice.look(fake, frame)
    assert choice.response == response and fake.searches == searches
    assert choice.prepared(frame)[0, 0] == (147 if response == "srgb" else grey)


def test_the_frames_looked_at_are_read_the_way_chosen():
    # Frame 0 reads more decoded (3 against 1), but the first three frames read more as recorded (9 against 5): the
    # camera is linear, and frame 0 is read as recorded too. Its second pixel tells the frame (100 + 10 t, decoded
    # 32, 40, 48).
    tags = {(200, 100): 1, (147, 32): 3, (200, 110): 4, (147, 40): 1, (200, 120): 4, (147, 48): 1}

    class Fake(_Counting):
        def image(self, image, region=None):
            found = super().image(image)
            n = tags.get((int(image[0, 0]), int(image[0, 1])), 0)
            return replace(found, block_text=np.array([f"A{k}" for k in range(n)]), block_xy=np.zeros((n, 4, 2)),
                           block_score=np.ones(n))

    frames = [np.full((4, 4), 200, np.uint8) for _ in range(4)]
    for t, frame in enumerate(frames[:3]):
        frame[0, 1] = 100 + 10 * t
    run = detect_capture(Fake(), [ArrayFrames("cam", frames)], [], 20.0, progress=False)
    assert run.responses == ("linear",) and run.looked == ((9, 5),)
    assert np.bincount(run.arrays["block_frame"], minlength=4).tolist() == [1, 4, 4, 0]


def test_the_ink_is_measured_against_the_paper_in_each_block():
    from handcap.detect.scenes import PageMaker
    from handcap.synth.images import ImageStyle
    from handcap.synth.pages import PageLook

    maker = PageMaker(3, look=PageLook(square_px=(24.0, 30.0), tilt_deg=(0.0, 20.0), curl=(0.0, 0.0), ink=(0.1, 0.1),
                                       shade=(1.0, 1.0), occluders=(0, 0), size=(640, 480), glint=0.0),
                      style=ImageStyle.clean())
    scene = maker.scene()
    ink = block_contrast(scene.image, scene.blocks)
    assert len(ink) > 20 and np.nanmedian(ink) == pytest.approx(0.1, abs=0.015)  # the ink printed at 0.1
    # Encoded as sRGB: the ink over the paper as the standard's encoding gives it, for this photograph's paper.
    paper = np.percentile(scene.image, 95) / 255.0
    expected = _srgb_level(0.1 * paper) / _srgb_level(paper)
    assert np.nanmedian(block_contrast(_srgb(scene.image), scene.blocks)) == pytest.approx(expected, rel=0.1)
    assert 0.3 < expected < 0.4
    # Blocks it cannot measure: too small, off the image.
    odd = np.array([np.zeros((4, 2)), scene.blocks[0] + 5000.0, [[0, 0], [1, 0], [1, 1], [0, 1]]])
    assert np.isnan(block_contrast(scene.image, odd)).all()


def _srgb_level(x):
    from handcap.core.srgb import srgb_encoded

    return float(srgb_encoded(np.array(x)))


def test_where_both_ways_read_as_many_tags_the_ink_decides(detector):
    from handcap.detect.scenes import PageMaker
    from handcap.synth.images import ImageStyle
    from handcap.synth.pages import PageLook

    maker = PageMaker(4, alphabet=DEXTERCAP, look=PageLook(square_px=(26.0, 30.0), tilt_deg=(0.0, 10.0),
                                                           occluders=(0, 0), size=(640, 480), glint=0.0),
                      style=ImageStyle.clean())
    images = [maker.scene().image for _ in range(LOOKS)]
    for given, frames in (("linear", images), ("srgb", [_srgb(i) for i in images])):
        choice = ResponseChoice()
        for image in frames:
            choice.look(detector, image)
        assert abs(int(choice.tags[0]) - int(choice.tags[1])) <= NEAR * max(choice.tags)  # as many either way
        assert choice.tags.min() > 20 and choice.response == given


@pytest.fixture(scope="module")
def detector():
    from handcap.detect.networks import load_corner_net, load_reader, load_refiner  # loads torch
    from handcap.detect.pipeline import Detector

    return Detector(load_corner_net(int8=True), load_reader(), session_pattern(("right",), (), alphabet=DEXTERCAP),
                    refiner=load_refiner(int8=True))


def _camera(folder, image):
    """A camera folder of LOOKS frames of ``image``, each moved by a pixel."""
    folder.mkdir()
    for t in range(LOOKS):
        cv2.imwrite(str(folder / f"{t:06d}.png"), np.roll(image, t, axis=1))
    return folder


def test_each_cameras_response_is_chosen_on_its_frames(scenes, detector, tmp_path):
    names = detector.pattern.corner_names()
    image = scenes[0].image
    linear, encoded = _camera(tmp_path / "linear", image), _camera(tmp_path / "phone", _srgb(image))
    run = detect_capture(detector, frame_sources([linear, encoded]), names, 30.0, progress=False, track=False)
    assert run.responses == ("linear", "srgb")
    as_recorded = detect_capture(detector, frame_sources([linear, encoded]), names, 30.0, progress=False, track=False,
                                 response="linear")
    tags = [np.bincount(r.arrays["block_camera"], minlength=2) for r in (run, as_recorded)]
    # The linear camera reads what it reads as recorded; the sRGB one, decoded, reads more than as recorded and
    # within a tag a frame of what its linear original reads.
    assert tags[0][0] == tags[1][0] and tags[0][1] > tags[1][1] and abs(tags[0][1] - tags[0][0]) <= LOOKS
    np.testing.assert_array_equal(run.arrays["marker"][run.arrays["camera"] == 0],
                                  as_recorded.arrays["marker"][as_recorded.arrays["camera"] == 0])
    # Given, the response is kept from the first frame: the encoded camera read as sRGB reads as it did chosen.
    given = detect_capture(detector, frame_sources([encoded]), names, 30.0, progress=False, track=False,
                           response="srgb")
    assert given.responses == ("srgb",) and len(given.arrays["block_text"]) == tags[0][1]


def test_the_command_says_which_cameras_it_read_as_srgb(tmp_path, capsys):
    from handcap.detect.scenes import PageMaker
    from handcap.synth.pages import PageLook

    maker = PageMaker(7, look=PageLook(square_px=(11.0, 14.0), tilt_deg=(0.0, 15.0), occluders=(0, 0),
                                       size=(640, 480), glint=0.0))
    pattern = tmp_path / "pattern.toml"
    session_pattern().save(pattern)
    scene = maker.scene()
    maker.close()
    image, truth = scene.image, dict(zip(scene.corner_names, scene.corners))
    counts, error, said = {}, {}, {}
    for name, pixels in (("machine", image), ("phone", _srgb(image))):
        (tmp_path / name).mkdir()
        cv2.imwrite(str(tmp_path / name / "0.jpg"), pixels, [cv2.IMWRITE_JPEG_QUALITY, 95])
        for response in ("auto", "linear"):
            out = tmp_path / f"{name}-{response}.npz"
            assert main(["detect", str(tmp_path / name), "--pattern", str(pattern), "--out", str(out), "--rate", "30",
                         "--response", response]) == 0
            data = np.load(out)
            counts[name, response] = len(data["block_text"])
            named = data["marker_names"][data["marker"]]
            error[name, response] = np.median([np.linalg.norm(xy - truth[n])
                                               for n, xy in zip(named, data["xy"]) if n in truth])
            said[name, response] = [w for w in data["warnings"] if "read as display-encoded (sRGB" in w]
    assert "camera phone read as display-encoded" in capsys.readouterr().err
    assert [len(v) for v in said.values()] == [0, 0, 1, 0]  # the phone's, chosen; stored with the result
    # The one image was searched both ways: the tags read each way are those of the two runs.
    assert (f"which read {counts['phone', 'auto']} tags decoded against {counts['phone', 'linear']} as recorded"
            in said["phone", "auto"][0])
    assert counts["machine", "auto"] == counts["machine", "linear"] > 20
    assert counts["phone", "auto"] > counts["phone", "linear"]
    # Decoded, the phone's corners are placed as the machine's are (0.115 and 0.119 px from the truth, median); as
    # recorded, 0.345 px: its blurred edges' middle grey is not the middle of the light.
    assert error["phone", "auto"] < 0.5 * error["phone", "linear"]
    assert error["phone", "auto"] < 1.1 * error["machine", "auto"] and error["machine", "auto"] < 0.2
    with pytest.raises(SystemExit) as exit_:
        main(["detect", str(tmp_path / "phone"), "--out", str(tmp_path / "x.npz"), "--response", "log"])
    assert exit_.value.code == 2 and "invalid choice: 'log'" in capsys.readouterr().err


def test_the_adapted_readers_views_are_decoded_where_the_camera_is_srgb():
    from handcap.steps.detect import _spread

    frames = [np.full((4, 4), 128, np.uint8), np.full((4, 4), 200, np.uint8)]
    linear, phone = ArrayFrames("linear", frames), ArrayFrames("phone", frames)
    images = _spread([linear, phone], ("linear", "srgb"))
    assert [int(im[0, 0]) for im in images] == [128, 200, 55, 147]

