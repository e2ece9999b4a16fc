"""Real images that hold no coded patch (../shared/data: checkerboards, a ChArUco board's video, photographs of
hands), none of them made by handcap: every tag the detector reads there would be wrong, so it must read none,
with the session's template and vote (with the hand-set checks and with the learned checker) and without, in
handcap's and DexterCap's alphabets.

A checkerboard's white squares are empty and a ChArUco board's hold ArUco markers' black and white cells; the
detector must find them no tag."""

from __future__ import annotations

import pytest

from handcap.detect.networks import load_checker, load_corner_net, load_reader, load_refiner
from handcap.detect.pipeline import Detector
from handcap.detect.sources import frame_sources
from handcap.patterns.alphabet import DEXTERCAP_ALPHABET
from handcap.patterns.session import session_pattern

pytestmark = pytest.mark.realdata


def _frames(shared_data):
    """(what, grey frame): the first frame of each real source, and a later one of the video."""
    calibration = shared_data / "calibration"
    paths = [calibration / "opencv_stereo" / "left01.jpg", calibration / "opencv_stereo" / "right08.jpg",
             calibration / "pose2sim_4cam" / "intrinsics" / "int_cam02_img",
             calibration / "caliscope_4cam" / "cam_1.mp4", shared_data / "images" / "gestures" / "four"]
    for source in frame_sources(paths):
        for t, image in source.frames():
            if t in (0, 30):
                yield f"{source.camera}[{t}]", image
            if t >= 30 or source.kind != "video":
                break


def test_real_images_without_patches_read_no_tag(shared_data):
    nets = load_corner_net(None, int8=True), load_reader(None)
    refiner = load_refiner(None, int8=True)  # as handcap detect runs
    voted = Detector(*nets, session_pattern(), refiner=refiner)
    checked = Detector(*nets, session_pattern(), refiner=refiner, checker=load_checker())  # as handcap detect runs
    alone = Detector(*nets, alphabet=DEXTERCAP_ALPHABET, refiner=refiner)
    seen = []
    for what, image in _frames(shared_data):
        seen.append(what)
        for detector in (voted, checked, alone):
            found = detector.image(image)
            assert list(found.block_text) == [], (what, detector.alphabet)
            assert not any(n is not None for n in found.names), what
    assert len(seen) == 6
