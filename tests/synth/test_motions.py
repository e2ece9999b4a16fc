"""Motions' bounds: a take too short for its motion names the frames it needs."""

import numpy as np
import pytest

from handcap import HandcapError
from handcap.hand import load_hand_model
from handcap.synth.motions import MIN_OBJECT_SECONDS, make_motion
from handcap.synth.objects import make_object


@pytest.mark.parametrize("rate", [100.0, 30.0])
def test_a_grasp_too_short_names_the_frames_it_needs(rate):
    hand, obj = load_hand_model(), make_object("cuboid")
    need = int(np.ceil(MIN_OBJECT_SECONDS * rate)) + 1  # frames 0 .. need - 1 span MIN_OBJECT_SECONDS
    with pytest.raises(HandcapError, match=f"give {need} frames or more"):
        make_motion("grasp", hand, need - 1, rate, np.random.default_rng(0), obj)
    motion = make_motion("grasp", hand, need, rate, np.random.default_rng(0), obj)
    assert len(motion.phi) == need
