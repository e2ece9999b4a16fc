"""The online labeler (handcap.labeling.online) on the real Qualisys glove recording, and its bad inputs."""

import numpy as np
import pytest

from handcap import HandcapError, MarkerSequence
from handcap.labeling import LabelingModel, OnlineLabeler, corrupt, label_take, score_labels


def test_real_glove_corrupted_is_labeled_online(glove):
    # Issue 4 on part of the test range: 2 ghosts/s near the hand, 5 % extra dropouts, strictly online.
    take, model, _ = glove
    unlabeled, truth = corrupt(take[2000:3500], ghost_rate=2.0, dropout=0.05, seed=0)
    result = label_take(unlabeled, model, lag=0)
    score = score_labels(result.markers, truth)
    assert score.instances == 1500 * 13
    assert score.fraction("correct") > 0.995
    assert score.fraction("erroneous") < 0.001


def test_streaming_api_returns_labels_for_the_points_given(glove):
    take, model, _ = glove
    labeler = OnlineLabeler(model, lag=2)
    frames = take.positions[2000:2010]
    out = []
    for t, frame in enumerate(frames):
        shuffled = frame[np.random.default_rng(t).permutation(len(frame))]
        labels = labeler.update(shuffled)
        assert (labels is None) == (t < 2)
        if labels is not None:
            out.append(labels)
    out += labeler.flush()
    assert len(out) == 10 and all(len(lab) == 13 for lab in out)  # NaN rows stay in place, labelled -1


def test_bad_inputs(glove):
    take, model, layout = glove
    labeler = OnlineLabeler(model)
    assert (labeler.update(np.zeros((0, 3))) == np.zeros(0)).all()  # a frame with no points
    crowd = np.random.default_rng(0).normal(0, 0.3, (200, 3))
    assert labeler.update(crowd).shape == (200,)  # far more points than markers
    with_nan = take.positions[2000].copy()
    assert labeler.update(with_nan).shape == (13,)  # NaN rows are no points
    with pytest.raises(HandcapError, match=r"shape \(K, 3\)"):
        labeler.update(np.zeros((4, 2)))
    with pytest.raises(HandcapError, match="hypotheses"):
        OnlineLabeler(model, hypotheses=0)
    with pytest.raises(HandcapError, match="lag"):
        OnlineLabeler(model, lag=-1)
    positions = take.positions[:2000].copy()
    positions[:, layout.names.index("ring_tip")] = np.nan
    with pytest.raises(HandcapError, match="'ring_tip' never appears"):
        LabelingModel.train(MarkerSequence(positions, take.names, take.rate), layout.names, layout.rigid)
    with pytest.raises(HandcapError, match="not in the training take"):
        LabelingModel.train(take[:2000], ["hand_top", "elbow"], ["hand_top"])
    with pytest.raises(HandcapError, match="rigid back-of-hand"):
        LabelingModel.train(take[:2000], layout.names)
    with pytest.raises(HandcapError, match="dropout"):
        corrupt(take[:100], dropout=1.0)
