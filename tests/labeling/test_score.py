"""Scoring a labeling (handcap.labeling.score), counted by hand."""

import numpy as np

from handcap import MarkerSequence
from handcap.labeling import score_labels


def test_score_counts_by_hand():
    nan = np.nan
    truth = MarkerSequence(np.array([[[0, 0, 0], [1, 0, 0]],
                                     [[0, 0, 1], [nan, nan, nan]],
                                     [[0, 0, 2], [1, 0, 2]],
                                     [[nan, nan, nan], [1, 0, 3]]], float), ["a", "b"], 10)
    out = MarkerSequence(np.array([[[0, 0, 0], [1, 0, 0]],          # a correct, b correct
                                   [[0, 0, 1], [5, 5, 5]],           # a correct, b false marker
                                   [[1, 0, 2], [nan, nan, nan]],     # a erroneous, b false occlusion
                                   [[nan, nan, nan], [1, 0, 3]]], float), ["b", "a"][::-1], 10)
    s = score_labels(out, truth)
    assert (s.correct.tolist(), s.erroneous.tolist(), s.false_marker.tolist(), s.false_occlusion.tolist()) == \
        ([3, 2], [1, 0], [0, 1], [0, 1])
    assert s.instances == 8 and s.gaps.tolist() == [0, 1]  # a's gap is at the end: not between segments
    assert "erroneous" in s.table()
