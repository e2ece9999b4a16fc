import numpy as np
import pytest

from handcap import HandcapError, HandMotion, MarkerSequence, ObjectMotion, PointCloudSequence
from handcap.core.markers import marker_gaps, runs


def seq(T=10, M=3, rate=100.0, names=None):
    rng = np.random.default_rng(0)
    return MarkerSequence(rng.normal(size=(T, M, 3)), names or [f"m{i}" for i in range(M)], rate)


def test_gap_statistics_of_a_known_pattern():
    missing = np.array([1, 1, 0, 0, 1, 0, 1, 1, 1, 0, 0, 1], bool)
    g = marker_gaps(missing, "a")
    assert g.leading == 2 and g.trailing == 1
    np.testing.assert_array_equal(g.gap_lengths, [1, 3])
    np.testing.assert_array_equal(g.segment_lengths, [2, 1, 2])
    assert g.n_gaps == 2 and g.max_gap == 3 and g.mean_gap == 2.0
    never = marker_gaps(np.ones(4, bool))
    assert never.n_gaps == 0 and never.leading == 4 and len(never.segment_lengths) == 0


def test_runs_against_a_loop():
    rng = np.random.default_rng(1)
    mask = rng.random(200) < 0.4
    starts, lengths = runs(mask)
    rebuilt = np.zeros_like(mask)
    for s, n in zip(starts, lengths):
        rebuilt[s:s + n] = True
    np.testing.assert_array_equal(rebuilt, mask)


def test_marker_sequence_gaps_and_summary():
    pos = np.zeros((8, 2, 3))
    pos[2:4, 0] = np.nan
    pos[5, 0, 1] = np.nan  # one NaN coordinate makes the whole sample missing
    m = MarkerSequence(pos, ["a", "b"], 50)
    assert np.isnan(m.positions[5, 0]).all()
    gaps = m.gaps()
    np.testing.assert_array_equal(gaps[0].gap_lengths, [2, 1])
    assert gaps[1].n_gaps == 0
    summary = m.gap_summary()
    assert summary["gaps"] == 2 and summary["max_gap_frames"] == 2
    assert summary["missing_fraction"] == pytest.approx(3 / 16)


def test_select_names_with_and_without_subject_prefix():
    m = seq(M=3, names=["Fingers2a:LIDX1", "Fingers2a:LIDX2", "other"])
    assert m.select(["LIDX2", "other"]).names == ("Fingers2a:LIDX2", "other")
    assert m["Fingers2a:LIDX1"].n_markers == 1
    np.testing.assert_array_equal(m.select("LIDX1").positions[:, 0], m.positions[:, 0])
    with pytest.raises(HandcapError, match="no marker named 'LIDX9'"):
        m.select("LIDX9")
    amb = seq(M=2, names=["A:x", "B:x"])
    with pytest.raises(HandcapError, match="ambiguous"):
        amb.index("x")


def test_frames_slices_and_rate():
    m = seq(T=100, rate=100)
    assert m[10:20].n_frames == 10
    half = m.frames(0, None, 2)
    assert half.rate == 50 and half.n_frames == 50
    np.testing.assert_array_equal(half.positions, m.positions[::2])
    assert m.time_range(0.2, 0.5).n_frames == 30
    assert m.duration == 1.0


def test_never_changes_the_callers_array():
    pos = np.zeros((4, 1, 3))
    pos[1, 0, 0] = np.nan
    m = MarkerSequence(pos, ["a"], 10)
    assert not np.isnan(pos[1, 0, 1])  # only the copy was completed to all-NaN
    pos[0] = 5.0
    assert m.positions[0, 0, 0] == 0.0


@pytest.mark.parametrize("kwargs, message", [
    (dict(positions=np.zeros((3, 2)), names=["a", "b"], rate=1), r"shape \(T, M, 3\)"),
    (dict(positions=np.zeros((3, 2, 3)), names=["a"], rate=1), "1 marker names for 2 markers"),
    (dict(positions=np.zeros((3, 2, 3)), names=["a", "a"], rate=1), "repeated: a"),
    (dict(positions=np.zeros((3, 1, 3)), names=["a"], rate=0), "positive"),
    (dict(positions=np.zeros((3, 1, 3)), names=["a"], rate="fast"), r"rate \(frames per second\) must be a number"),
    (dict(positions=np.full((3, 1, 3), np.inf), names=["a"], rate=1), "infinite"),
    (dict(positions=np.zeros((3, 1, 3)), names=["a"], rate=1, residuals=np.zeros(3)), "residuals"),
])
def test_bad_marker_sequences(kwargs, message):
    with pytest.raises(HandcapError, match=message):
        MarkerSequence(**kwargs)


def test_point_clouds_round_trip_padding():
    frames = [np.zeros((2, 3)), np.ones((0, 3)), np.arange(9.0).reshape(3, 3)]
    pc = PointCloudSequence(frames, 30)
    np.testing.assert_array_equal(pc.counts, [2, 0, 3])
    again = PointCloudSequence.from_padded(pc.padded(), 30)
    for a, b in zip(again.frames, pc.frames):
        np.testing.assert_array_equal(a, b)
    with pytest.raises(HandcapError, match="non-finite"):
        PointCloudSequence([np.full((1, 3), np.nan)], 30)


def test_hand_and_object_motion_validation_and_slicing():
    T = 5
    hm = HandMotion(np.zeros(10), np.zeros((T, 3)), np.zeros((T, 45)), np.zeros((T, 3)), 30, phi=np.zeros((T, 27)))
    assert hm.frames(1, 3).n_frames == 2 and hm.frames(1, 3).phi.shape == (2, 27)
    with pytest.raises(HandcapError, match="hand_pose has 4 frames"):
        HandMotion(np.zeros(10), np.zeros((T, 3)), np.zeros((4, 45)), np.zeros((T, 3)), 30)
    with pytest.raises(HandcapError, match="betas"):
        HandMotion(np.zeros(9), np.zeros((T, 3)), np.zeros((T, 45)), np.zeros((T, 3)), 30)
    om = ObjectMotion(np.tile([0, 0, np.pi / 2], (T, 1)), np.tile([1.0, 0, 0], (T, 1)), 30, "box", ("a",),
                      np.array([[1.0, 0, 0]]))
    np.testing.assert_allclose(om.transform_points(om.canonical)[0, 0], [1.0, 1.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(om.matrices()[0, :3, 3], [1, 0, 0])
    with pytest.raises(HandcapError, match="canonical"):
        ObjectMotion(np.zeros((T, 3)), np.zeros((T, 3)), 30, "box", ("a", "b"), np.zeros((1, 3)))


def test_positions_of_names_the_sequence_lacks_are_nan_throughout():
    rng = np.random.default_rng(0)
    m = MarkerSequence(rng.normal(size=(4, 3, 3)), ["a", "b", "c"], 100.0)
    got = m.positions_of(["c", "x", "a"])
    np.testing.assert_array_equal(got[:, [0, 2]], m.select(["c", "a"]).positions)
    assert got.shape == (4, 3, 3) and np.isnan(got[:, 1]).all()
