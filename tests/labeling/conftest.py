"""Shared by the labeling tests: the real glove recording and a labeling model trained on its first 20 s, and a
model of synthetic subject 3 in joints-19."""

import pytest

from handcap.io import read_markers
from handcap.labeling import LabelingModel
from handcap.layouts import load_layout


@pytest.fixture(scope="session")
def glove(shared_data):
    layout = load_layout("glove-13")
    take = read_markers(shared_data / "markers" / "hand_embodiment_glove" / "recording.tsv").select(layout.names)
    model = LabelingModel.train(take[:2000], layout.names, layout.rigid)
    return take, model, layout


@pytest.fixture(scope="session")
def joints_model():
    """A joints-19 labeling model trained on 5 s (600 frames at 120 Hz) of synthetic subject 3's range of motion."""
    from handcap.synth.scene import SynthConfig, synthesize

    layout = load_layout("joints-19")
    rom = synthesize(SynthConfig(layout=layout.name, motion="random", frames=600, rate=120.0, seed=11,
                                 subject_seed=3), progress=False)
    return LabelingModel.train(rom.markers, layout.names, layout.rigid)
