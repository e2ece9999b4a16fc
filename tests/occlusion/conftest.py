"""Fixtures: the real Qualisys glove take and a small marker predictor trained on its first 60 %."""

import pytest

from handcap.io import read_markers
from handcap.occlusion.data import PosedTake
from handcap.occlusion.train import train_occlusion_model

HAND = ("hand_top", "hand_left", "hand_right", "thumb_middle", "thumb_tip", "index_middle", "index_tip",
        "middle_middle", "middle_tip", "ring_middle", "ring_tip", "little_middle", "little_tip")


@pytest.fixture(scope="session")
def glove(shared_data):
    """The glove recording's 13 hand markers (MarkerSequence, metres, 100 Hz)."""
    markers = read_markers(shared_data / "markers" / "hand_embodiment_glove" / "recording.tsv")
    return markers.select(HAND)


@pytest.fixture(scope="session")
def glove_split(glove):
    n = int(0.6 * glove.n_frames)
    return glove.positions[:n], glove.positions[n:]


@pytest.fixture(scope="session")
def glove_model(glove, glove_split):
    """A marker predictor trained briefly (seconds) on the first 60 % of the glove take."""
    train, _ = glove_split
    return train_occlusion_model([PosedTake(train, HAND, glove.rate)], "glove-13", seed=0, epochs=12,
                                 samples_per_epoch=20_000)
