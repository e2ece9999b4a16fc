"""Augmentation of training data: time warps keep the motion, per-sample changes have the stated sizes."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from handcap import HandcapError
from handcap.occlusion.augment import Augmentation, augment_frames, time_warp, warped_copies
from handcap.occlusion.data import PosedTake

RATE = 100.0


def _ramp_take(frames=300):
    """Markers moving at constant velocity, phi growing linearly, a steady turn about one axis."""
    t = np.arange(frames, dtype=np.float64)
    velocity = np.array([0.001, -0.002, 0.0005])  # metres per frame
    positions = np.stack([t[:, None] * velocity + 0.01 * m for m in range(4)], axis=1)
    phi = np.outer(t, np.linspace(0.001, 0.002, 27))
    orient = Rotation.from_rotvec(np.outer(t * 0.004, [0.0, 0.6, 0.8])).as_rotvec()
    transl = np.outer(t, velocity)
    return PosedTake(positions, ("a", "b", "c", "d"), RATE, phi, orient, transl, subject="s1")


@pytest.mark.parametrize("speed", [0.5, 2.0])
def test_time_warp_at_constant_speed_resamples_the_motion(speed):
    take = _ramp_take()
    warped = time_warp(take, np.random.default_rng(0), (speed, speed))
    # Output frame k is input time k * speed: every quantity is linear in time, so exact.
    u = np.arange(len(warped.positions)) * speed
    assert len(warped.positions) == int(np.floor((len(take.positions) - 1) / speed)) + 1
    np.testing.assert_allclose(warped.positions, np.interp(u, np.arange(300), np.arange(300))[:, None, None]
                               * np.array([0.001, -0.002, 0.0005]) + take.positions[0], atol=1e-12)
    np.testing.assert_allclose(warped.phi, np.outer(u, np.linspace(0.001, 0.002, 27)), atol=1e-12)
    np.testing.assert_allclose(warped.global_orient, np.outer(u * 0.004, [0.0, 0.6, 0.8]), atol=1e-9)
    assert warped.subject == "s1" and warped.rate == RATE


def test_time_warp_speeds_stay_in_range_and_missing_stays_missing():
    take = _ramp_take()
    positions = take.positions.copy()
    positions[100:110, 2] = np.nan
    take = PosedTake(positions, take.names, RATE)
    warped = time_warp(take, np.random.default_rng(3), (0.6, 1.6))
    # The first marker moves 1 step per input frame along x: its steps are the speeds.
    steps = np.diff(warped.positions[:, 0, 0]) / 0.001
    assert steps.min() >= 0.6 - 1e-9 and steps.max() <= 1.6 + 1e-9 and steps.std() > 0.05
    gap = np.isnan(warped.positions[:, 2, 0])
    assert 4 <= gap.sum() <= 20  # the 10 missing frames, at 0.6-1.6x speed
    assert not np.isnan(warped.positions[:, [0, 1, 3]]).any()


def test_warped_copies_are_deterministic():
    takes = [_ramp_take(), _ramp_take(200)]
    a = warped_copies(takes, Augmentation(copies=2), seed=1)
    b = warped_copies(takes, Augmentation(copies=2), seed=1)
    c = warped_copies(takes, Augmentation(copies=2), seed=2)
    assert len(a) == 4 and all(np.array_equal(x.positions, y.positions) for x, y in zip(a, b))
    assert not np.array_equal(a[0].positions, c[0].positions)


def _hand(n=4000):
    rng = np.random.default_rng(0)
    base = rng.normal(0, 0.04, (7, 3))  # four rigid markers, not in a plane, and three others
    return np.broadcast_to(base, (n, 7, 3)).copy(), np.array([True, True, True, True, False, False, False])


def test_scale_alone_scales_each_axis_about_the_centre():
    local, rigid = _hand()
    centre = np.array([0.01, 0.0, -0.01])
    out = augment_frames(local, centre, rigid, Augmentation(scale=0.1, rigid_deg=0, rigid_mm=0, placement_mm=0),
                         np.random.default_rng(1))
    factor = (out - centre) / (local - centre)
    assert np.allclose(factor, factor[:, :1])  # one factor per frame and axis
    log = np.log(factor[:, 0])
    assert abs(log.mean()) < 0.01
    assert np.std(log, axis=0) == pytest.approx([0.1] * 3, rel=0.1)  # 10 % per axis


def test_rigid_set_moves_as_a_body_by_the_stated_angle():
    local, rigid = _hand()
    a = Augmentation(scale=0, rigid_deg=10.0, rigid_mm=4.0, placement_mm=0)
    out = augment_frames(local, np.zeros(3), rigid, a, np.random.default_rng(2))
    assert np.array_equal(out[:, ~rigid], local[:, ~rigid])  # the fingers stay
    d = lambda x: np.linalg.norm(x[:, :, None] - x[:, None], axis=-1)  # noqa: E731
    assert np.allclose(d(out[:, rigid]), d(local[:, rigid]))  # rigid distances kept
    # Recover each frame's rotation of the rigid set (Kabsch) and compare with the stated spread.
    p = local[:, rigid] - local[:, rigid].mean(1, keepdims=True)
    q = out[:, rigid] - out[:, rigid].mean(1, keepdims=True)
    u, _, vt = np.linalg.svd(np.swapaxes(p, 1, 2) @ q)
    angles = Rotation.from_matrix(u @ vt).magnitude()
    # A normal angle of 10 deg: its absolute value has mean 10 * sqrt(2 / pi) deg.
    assert np.degrees(angles.mean()) == pytest.approx(10 * np.sqrt(2 / np.pi), rel=0.08)
    shift = out[:, rigid].mean(1) - local[:, rigid].mean(1)
    assert np.std(shift, axis=0) == pytest.approx([0.004] * 3, rel=0.1)


def test_placement_jitter_has_the_stated_spread_and_keeps_missing():
    local, rigid = _hand()
    local[:10, 4] = np.nan
    out = augment_frames(local, np.zeros(3), rigid, Augmentation(scale=0, rigid_deg=0, rigid_mm=0, placement_mm=3.0),
                         np.random.default_rng(3))
    assert np.isnan(out[:10, 4]).all()
    assert np.nanstd(out - local) == pytest.approx(0.003, rel=0.05)


@pytest.mark.parametrize("bad", [dict(scale=-0.1), dict(scale=0.6), dict(placement_mm=np.nan), dict(copies=1.5),
                                 dict(copies=-1), dict(speed=(1.5, 1.0)), dict(speed=(0.0, 1.0))])
def test_bad_augmentation_is_refused(bad):
    with pytest.raises(HandcapError):
        Augmentation(**bad)


def test_a_motion_worn_by_other_subjects_keeps_the_pose_and_changes_the_hand():
    from handcap.occlusion.data import simulate_take, synthetic_hand_takes, worn_by_another_subject

    takes = synthetic_hand_takes("active-9", subjects=1, seconds_per_motion=0.5, motions=("random",), worn_by=2,
                                 placement_mm=8.0)
    assert len(takes) == 3 and len({t.subject for t in takes}) == 3 and all(t.synthetic for t in takes)
    first, other = takes[0], takes[1]
    assert np.array_equal(first.phi, other.phi) and np.array_equal(first.transl, other.transl)
    assert not np.allclose(first.betas, other.betas)
    # The markers follow the hand: the wrist triad is rigid in every take, but its size is the subject's.
    triad = lambda t: np.linalg.norm(t.positions[:, 0] - t.positions[:, 1], axis=-1)  # noqa: E731
    assert triad(other).std() < 0.002 and abs(triad(other).mean() - triad(first).mean()) > 0.0005
    same = worn_by_another_subject(first, "active-9", 0, placement_mm=8.0, betas_sd=1.0)
    assert np.array_equal(same.positions, other.positions)  # deterministic for its subject seed
    with pytest.raises(HandcapError, match="with poses"):
        worn_by_another_subject(PosedTake(first.positions, first.names, RATE), "active-9", 1)
    assert simulate_take("active-9", "random", 20, RATE, 4).subject == "synthetic subject 4"


def test_each_finger_turns_on_its_own_about_the_back_of_the_hand():
    from handcap.layouts import load_layout
    from handcap.occlusion.augment import finger_groups

    layout = load_layout("glove-13")
    fingers = finger_groups(layout, layout.names)
    # index, middle, pinky (little), ring, thumb: two markers each; the triad none.
    assert fingers.tolist() == [-1, -1, -1, 4, 4, 0, 0, 1, 1, 3, 3, 2, 2]
    rigid = np.array([n in layout.rigid for n in layout.names])
    local = np.broadcast_to(layout.positions(), (3000, 13, 3)).copy()
    a = Augmentation(scale=0, rigid_deg=0, rigid_mm=0, finger_deg=12.0, placement_mm=0)
    out = augment_frames(local, np.zeros(3), rigid, a, np.random.default_rng(4), fingers)
    pivot = local[0, rigid].mean(axis=0)
    assert np.array_equal(out[:, rigid], local[:, rigid])
    np.testing.assert_allclose(np.linalg.norm(out - pivot, axis=-1), np.linalg.norm(local - pivot, axis=-1))
    for f in range(5):
        pair = np.flatnonzero(fingers == f)
        np.testing.assert_allclose(np.linalg.norm(out[:, pair[0]] - out[:, pair[1]], axis=-1),
                                   np.linalg.norm(local[0, pair[0]] - local[0, pair[1]]))
    # Two fingers turn independently: their moves are uncorrelated.
    move = out - local
    assert abs(np.corrcoef(move[:, 4, 0], move[:, 6, 0])[0, 1]) < 0.1
    assert Augmentation().finger_deg == 20.0 and "fingers 20 deg" in Augmentation().describe()


def test_frames_of_one_sample_share_the_subject():
    # Two frames per sample (the frame before a gap and one in it): one subject and placement for both, so
    # the change between them is only the motion (here: a known shift of the fingers).
    local, rigid = _hand(2000)
    later = local.copy()
    later[:, ~rigid] += [0.002, -0.001, 0.0005]
    pair = np.stack([local, later], axis=1)  # (N, 2, M, 3)
    out = augment_frames(pair, np.zeros(3), rigid, Augmentation(), np.random.default_rng(5),
                         np.array([-1, -1, -1, -1, 0, 0, 1]))
    assert out.shape == pair.shape
    np.testing.assert_allclose(out[:, 0, rigid], out[:, 1, rigid], atol=1e-12)  # the rigid set did not move
    moved = np.linalg.norm(out[:, 1] - out[:, 0], axis=-1)[:, ~rigid]
    # The fingers moved 2.3 mm, scaled by the sample's subject (12 % spread): not by two placements.
    assert np.all(np.abs(moved - np.linalg.norm([0.002, -0.001, 0.0005])) < 0.0015)
    # Frames of different samples are different subjects.
    assert np.std(out[:, 0, 4] - local[:, 4], axis=0).min() > 0.005
