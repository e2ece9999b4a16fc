"""The plausibility warnings of a labelling (handcap.labeling.plausible), from counts with known answers."""

import numpy as np

from handcap.labeling.frame import RigidSet
from handcap.labeling.plausible import (REVERSED_LEAST, LabelTally, label_warnings, missing_labels, reversed_pairs,
                                        unnamed_body_warning)
from handcap.labeling.release import Release

TRIAD = np.array([[0.0, 0.03, 0.0], [-0.03, -0.02, 0.0], [0.035, -0.015, 0.0]])


def test_a_tally_counts_frames_points_and_labels():
    tally = LabelTally(4)
    tally.add(np.array([0, 2, -1, 2]))  # a label given twice in a frame counts one frame
    tally.add(np.array([1, -1, -1]), np.array([True, True, False]))  # a NaN row is no point
    assert tally.frames == 2 and tally.points == 6 and tally.labelled == 4
    np.testing.assert_array_equal(tally.given, [1, 1, 1, 0])
    np.testing.assert_allclose(tally.shares([2, 3]), [0.5, 0.0])
    assert tally.labelled_share == 4 / 6
    assert np.isnan(LabelTally(2).labelled_share)


def test_each_implausible_figure_is_one_line_and_a_plausible_labelling_none():
    names = ("a", "b", "c", "d")
    rigid = RigidSet(("x", "y", "z"), TRIAD - TRIAD.mean(0), 0.0005)
    assert label_warnings(names, np.array([0.9, 0.95, 0.9, 0.92]), trained_rigid=rigid, rigid=rigid, lost=10,
                          frames=1000, labelled=0.97) == []
    moved = RigidSet(rigid.names, rigid.canonical * 1.1, 0.0005)  # the longest side (65.2 mm) 6.5 mm longer
    lines = label_warnings(names, np.array([0.9, 0.01, 0.9, 0.92]), trained_rigid=rigid, rigid=moved, lost=60,
                           frames=1000, labelled=0.9, released=[Release(500, 300, ("a", "c"))], rate=100.0)
    assert len(lines) == 5 and all("\n" not in line for line in lines)
    assert "up to 6.5 mm" in lines[0] and "b labelled in 1 %" in lines[1] and "6.0 % of the frames" in lines[2]
    assert "a and c at frame 500" in lines[3] and "labels for 90.0 %" in lines[4]
    np.testing.assert_array_equal(missing_labels([0.9, 0.44, 0.9, 0.95, 0.46]), [False, True, False, False, False])


def test_reversed_pairs_are_the_labels_holding_each_others_markers():
    # Four knuckles 20 mm apart in a row (the model's means); another subject's 25 % wider and 3 mm off, moving
    # 5 mm about. Labels 1 and 2 holding each other's markers are the one pair reversed; labels given in too few
    # frames are not judged, and a row that is only shorter is not reversed.
    rng = np.random.default_rng(0)
    expected = np.array([[0.0, 0.0, 0.0], [0.02, 0.0, 0.0], [0.04, 0.0, 0.0], [0.06, 0.0, 0.0]])
    frames = REVERSED_LEAST + 20
    points = 1.25 * expected + [0.0, 0.003, 0.0] + rng.normal(0.0, 0.005, (frames, 4, 3))
    assert not reversed_pairs(expected, points).any()
    assert not reversed_pairs(expected, 0.2 * points).any()
    swapped = points[:, [0, 2, 1, 3]]
    want = np.zeros((4, 4), dtype=bool)
    want[1, 2] = want[2, 1] = True
    np.testing.assert_array_equal(reversed_pairs(expected, swapped), want)
    swapped[21:, 2] = np.nan  # label 2 given in 21 frames only
    assert not reversed_pairs(expected, swapped).any()


def test_a_tally_keeps_the_points_left_and_finds_a_rigid_body_among_them():
    # A stream whose four unlabelled points are a rigid body turning about, besides six labelled hand points.
    from scipy.spatial.transform import Rotation

    body = np.array([[0.0, 0.0, 0.0], [0.05, 0.0, 0.0], [0.0, 0.08, 0.0], [0.03, 0.02, 0.06]])
    rng = np.random.default_rng(0)
    tally, labelled = LabelTally(6), LabelTally(6)
    for t in range(2000):
        hand = rng.uniform(-0.5, 0.5, (6, 3))
        obj = body @ Rotation.random(random_state=t).as_matrix().T + rng.uniform(-0.5, 0.5, 3)
        tally.add(np.r_[np.arange(6), [-1] * 4], points=np.vstack([hand, obj]))
        labelled.add(np.arange(6), points=hand)
    assert len(tally.left) == 200 and len(tally.left[0]) == 4 and tally.labelled_share == 0.6
    found = tally.unnamed_body()
    assert found is not None and len(found.names) == 4 and found.names[0] == "object:0"
    line = unnamed_body_warning(found, False)
    assert "4 of the points no label was given" in line and "object:0-3" in line and "\n" not in line
    assert "labelled object:0-object:3" in unnamed_body_warning(found, True)
    assert labelled.unnamed_body() is None  # every point labelled: nothing searched
