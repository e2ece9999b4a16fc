"""Rigid bodies: Kabsch against hand-built transforms, RANSAC, shape estimation, the real Vicon box."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from handcap import HandcapError, MarkerSequence
from handcap.objects import canonical_from_markers, kabsch, ransac_kabsch, track_rigid


def test_kabsch_recovers_a_transform_built_by_hand_batched_and_single():
    rng = np.random.default_rng(0)
    pts = rng.normal(size=(5, 6, 3))
    rot = Rotation.random(5, random_state=1).as_matrix()
    trans = rng.normal(size=(5, 3))
    moved = np.einsum("bij,bnj->bni", rot, pts) + trans[:, None]
    r, t = kabsch(pts, moved)
    np.testing.assert_allclose(r, rot, atol=1e-12)
    np.testing.assert_allclose(t, trans, atol=1e-12)
    r0, t0 = kabsch(pts[0], moved[0])
    np.testing.assert_allclose(r0, r[0], atol=1e-12)
    # Weight 0 drops a point; a mirrored target still yields a proper rotation.
    bad = moved[0].copy()
    bad[2] += 10.0
    w = np.ones(6)
    w[2] = 0
    np.testing.assert_allclose(kabsch(pts[0], bad, w)[0], rot[0], atol=1e-12)
    assert np.linalg.det(kabsch(pts[0], pts[0] * [-1, 1, 1])[0]) == pytest.approx(1.0)


def test_ransac_rejects_a_mislabelled_marker():
    rng = np.random.default_rng(2)
    canonical = rng.uniform(-0.05, 0.05, size=(8, 3))
    rot = Rotation.random(random_state=3).as_matrix()
    observed = canonical @ rot.T + [0.1, 0.2, 0.3]
    observed[4] += [0.03, 0.0, 0.0]
    r, t, inliers = ransac_kabsch(canonical, observed, threshold=0.002)
    assert not inliers[4] and inliers.sum() == 7
    np.testing.assert_allclose(r, rot, atol=1e-9)


def test_refit_drops_a_far_label_among_few_points_one_at_a_time():
    # Five points of a 20 mm cubie, one label 28 mm off: the first fit is pulled about 5 mm, so every point lay
    # beyond 3 mm of it; dropping them all at once left none, and the spoilt fit was returned.
    from handcap.objects.rigid import kabsch_refit

    rng = np.random.default_rng(4)
    source = rng.uniform(-0.01, 0.01, size=(5, 3))
    rot = Rotation.random(2, random_state=5).as_matrix()
    target = np.einsum("tij,mj->tmi", rot, source) + [0.1, 0.2, 0.3]
    target[0, 2] += [0.028, 0.0, 0.0]
    fit_rot, fit_trans = kabsch_refit(source, target, np.ones((2, 5)), 0.003)
    np.testing.assert_allclose(fit_rot, rot, atol=1e-9)
    np.testing.assert_allclose(fit_trans, [[0.1, 0.2, 0.3]] * 2, atol=1e-9)
    # three points left and one still off: no pose fits them
    assert np.isnan(kabsch_refit(source[:3], target[:1, :3], np.ones((1, 3)), 0.003)[0]).all()
    # with at most one drop allowed, two far labels leave the fit spoilt but not NaN (the caller measures it)
    target[1, 3] += [0.0, 0.028, 0.0]
    target[1, 2] += [0.028, 0.0, 0.0]
    assert np.isfinite(kabsch_refit(source, target[1:], np.ones((1, 5)), 0.003, 1)[0]).all()


def test_canonical_shape_from_a_take_matches_the_body_up_to_a_rigid_motion():
    rng = np.random.default_rng(4)
    body = rng.uniform(-0.05, 0.05, size=(6, 3))
    rots = Rotation.random(50, random_state=5).as_matrix()
    positions = np.einsum("tij,nj->tni", rots, body) + rng.normal(size=(50, 1, 3))
    positions[rng.random((50, 6)) < 0.2] = np.nan
    shape = canonical_from_markers(positions)
    r, t = kabsch(shape, body - body.mean(axis=0))
    np.testing.assert_allclose(shape @ r.T + t, body - body.mean(axis=0), atol=1e-9)


def test_a_shape_seen_a_part_at_a_time_is_learnt_whole():
    # A held object's patches: each frame of a moving object shows another part of it, a few markers shared with
    # the frames before. The first shape took each marker the first frame lacks at its mean place over the take
    # (where the moving object never was), and settled 1-3 mm off (1.3 mm median on a rendered cylinder).
    rng = np.random.default_rng(6)
    angle = np.linspace(0.0, 2 * np.pi, 40, endpoint=False)
    body = np.column_stack([0.035 * np.cos(angle), 0.035 * np.sin(angle), rng.uniform(-0.05, 0.05, 40)])
    n = 12
    rots = Rotation.from_rotvec(np.outer(np.linspace(0, 1.5, n), [0.3, 1.0, 0.2])).as_matrix()
    positions = np.einsum("tij,nj->tni", rots, body) + np.linspace(0, 0.3, n)[:, None, None] * [1.0, 0.5, 0.0]
    positions += rng.normal(0.0, 2e-5, positions.shape)
    for t in range(n):  # frame t shows a band of 10 markers round the cylinder, 7 of them seen in frame t - 1
        band = (3 * t + np.arange(10)) % 40
        hidden = np.ones(40, bool)
        hidden[band] = False
        positions[t, hidden] = np.nan
    shape = canonical_from_markers(positions)
    r, t = kabsch(shape, body - body.mean(axis=0))
    error = np.linalg.norm(shape @ r.T + t - (body - body.mean(axis=0)), axis=1)
    assert error.max() < 1e-4, error.max()


def test_real_vicon_box(shared_data):
    from handcap.io import read_markers
    markers = read_markers(shared_data / "markers" / "ezc3d" / "Vicon.c3d")
    names = [n for n in markers.names if n.startswith("boite:")]
    track = track_rigid(markers, names, name="boite")
    assert len(names) == 8
    assert track.mean_residual < 0.001  # issue 3: within 1 mm
    assert len(track.unsolved) == 0
    span = np.ptp(track.motion.translation, axis=0).max()
    assert span > 0.3  # the box moves about 45 cm


def test_frames_with_fewer_than_three_markers_are_reported_not_guessed(shared_data):
    from handcap.io import read_markers
    markers = read_markers(shared_data / "markers" / "ezc3d" / "Vicon.c3d")
    box = markers.select([n for n in markers.names if n.startswith("boite:")])
    positions = box.positions.copy()
    positions[100:110, 2:] = np.nan  # only two markers left
    track = track_rigid(MarkerSequence(positions, box.names, box.rate))
    np.testing.assert_array_equal(track.unsolved, np.arange(100, 110))
    assert np.isnan(track.motion.rotation[100:110]).all()
    assert np.isfinite(track.motion.rotation[:100]).all()


def test_markers_the_take_never_shows_are_left_out_and_said(shared_data):
    # A patch's corners that no camera pair saw: asked for by 'NAME:*', never in the take. The track is the one of
    # the markers seen, and the warning names the others.
    from handcap.io import read_markers
    from handcap.quality.plausibility import object_warnings

    markers = read_markers(shared_data / "markers" / "ezc3d" / "Vicon.c3d")
    box = markers.select([n for n in markers.names if n.startswith("boite:")])
    unseen = np.full((box.n_frames, 2, 3), np.nan)
    wider = MarkerSequence(np.concatenate([box.positions[:, :3], unseen, box.positions[:, 3:]], axis=1),
                           [*box.names[:3], "boite:x_r0c0", "boite:x_r0c1", *box.names[3:]], box.rate)
    alone, track = track_rigid(box, name="boite"), track_rigid(wider, name="boite")
    assert track.left_out == ("boite:x_r0c0", "boite:x_r0c1") and track.motion.marker_names == box.names
    np.testing.assert_array_equal(track.motion.translation, alone.motion.translation)
    said = object_warnings(track, threshold=0.005)
    assert said[0] == ("object 'boite': 2 of its 10 markers are never seen in the take and are left out of it "
                       "(boite:x_r0c0, boite:x_r0c1)")
    assert not object_warnings(alone, threshold=0.005)


def test_bad_inputs():
    m = MarkerSequence(np.zeros((4, 2, 3)), ["a", "b"], 100)
    with pytest.raises(HandcapError, match="at least 3 markers"):
        track_rigid(m)
    nan = MarkerSequence(np.full((4, 3, 3), np.nan), ["a", "b", "c"], 100)
    with pytest.raises(HandcapError, match="shows 0 of the object's 3 markers"):
        track_rigid(nan)
    two = MarkerSequence(np.where(np.arange(3)[None, :, None] < 2, 1.0, np.nan) * np.ones((4, 3, 3)), ["a", "b", "c"],
                         100)
    with pytest.raises(HandcapError, match="shows 2 of the object's 3 markers"):
        track_rigid(two)
    ok = MarkerSequence(np.random.default_rng(0).normal(size=(4, 3, 3)), ["a", "b", "c"], 100)
    with pytest.raises(HandcapError, match="canonical positions must have shape"):
        track_rigid(ok, canonical=np.zeros((2, 3)))


def test_canonical_shapes_estimated_side_by_side_as_each_alone():
    rng = np.random.default_rng(2)
    takes = []
    for _ in range(6):
        body = rng.normal(scale=0.03, size=(5, 3))
        rot = Rotation.random(25, random_state=rng).as_matrix()
        take = np.einsum("tij,mj->tmi", rot, body) + rng.normal(size=(25, 1, 3))
        take += rng.normal(scale=5e-4, size=take.shape)
        take[rng.random((25, 5)) < 0.3] = np.nan
        takes.append(take)
    together = canonical_from_markers(np.stack(takes).reshape(2, 3, 25, 5, 3))
    assert together.shape == (2, 3, 5, 3)
    for take, shape in zip(takes, together.reshape(6, 5, 3)):
        np.testing.assert_allclose(shape, canonical_from_markers(take), atol=1e-12)
