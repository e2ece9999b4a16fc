"""The real glove recording and a labeling model trained on its first 20 s, shared by the labeling tests."""

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
