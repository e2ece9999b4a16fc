"""Two hands in one stream (handcap.labeling.multihand), from the real glove recording."""

import numpy as np
import pytest

from handcap import HandcapError, MarkerSequence
from handcap.labeling import LabelingModel, corrupt, label_take, score_labels


def two_hands(take, layout, offset):
    """Two real hands in one stream: the glove's test range, and a later range mirrored into a left hand
    (x -> -x), turned about the vertical and moved ``offset`` metres away; with a model for each."""
    from scipy.spatial.transform import Rotation
    mirrored = MarkerSequence(take.positions * [-1.0, 1.0, 1.0], take.names, take.rate)
    left_model = LabelingModel.train(mirrored[:2000], layout.names, layout.rigid)
    right = take[2000:2800].positions
    left = mirrored[3500:4300].positions
    centre = np.nanmean(left.reshape(-1, 3), axis=0)
    left = (left - centre) @ Rotation.from_euler("z", 180, degrees=True).as_matrix().T + centre + [offset, 0, 0]
    names = tuple("R_" + n for n in layout.names) + tuple("L_" + n for n in layout.names)
    return MarkerSequence(np.concatenate([right, left], axis=1), names, take.rate), left_model


@pytest.mark.parametrize("offset", [0.15, 0.4])
def test_two_hands_in_one_stream(glove, offset):
    take, model, layout = glove
    both, left_model = two_hands(take, layout, offset)
    unlabeled, truth = corrupt(both, ghost_rate=4.0, dropout=0.05, seed=2)
    result = label_take(unlabeled, [model, left_model], prefixes=("R_", "L_"))
    assert result.markers.names == truth.names
    score = score_labels(result.markers, truth)
    assert score.fraction("correct") > 0.995 and score.fraction("erroneous") < 0.001
    assert len(result.lost_frames) < 5


def test_two_hands_need_telling_apart(glove):
    _, model, _ = glove
    from handcap.labeling import MultiHandLabeler
    with pytest.raises(HandcapError, match="prefixes"):
        MultiHandLabeler([model, model])
    with pytest.raises(HandcapError, match="2 prefixes for 1 hands"):
        MultiHandLabeler([model], prefixes=("a", "b"))
    labeler = MultiHandLabeler([model, model], prefixes=("a_", "b_"))
    with pytest.raises(HandcapError, match="transform"):
        labeler.update(np.zeros((3, 3)), (np.eye(3), np.zeros(3)))
    assert labeler.update(np.zeros((0, 3))).shape == (0,)
