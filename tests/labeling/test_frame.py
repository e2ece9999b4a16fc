"""Finding rigid marker sets (a hand's back markers, an object) among unlabeled points, against known poses."""

import numpy as np
from scipy.spatial.transform import Rotation

from handcap.labeling.frame import HandFrameFinder, RigidSet, triangles_within
from handcap.labeling.relearn import search_frames

TRIAD = np.array([[0.0, 0.03, 0.0], [-0.03, -0.02, 0.0], [0.035, -0.015, 0.0]])


def place(canonical, rotvec, shift):
    rot = Rotation.from_rotvec(rotvec).as_matrix()
    return canonical @ rot.T + shift, rot


def test_triad_found_among_clutter_with_its_pose():
    rng = np.random.default_rng(0)
    finder = HandFrameFinder(RigidSet(("a", "b", "c"), TRIAD - TRIAD.mean(0), 0.003))
    world, rot = place(finder.rigid.canonical, [0.3, -0.5, 1.0], [0.2, 0.1, 1.0])
    clutter = rng.uniform(-0.15, 0.15, (12, 3)) + [0.2, 0.1, 1.0]
    order = rng.permutation(15)
    points = np.concatenate([world, clutter])[order]
    pose = finder.find(points)
    assert pose.found
    np.testing.assert_array_equal(order[pose.points], [0, 1, 2])
    np.testing.assert_allclose(pose.rotation, rot, atol=1e-9)


def test_a_dropped_back_marker_is_not_replaced_by_a_look_alike_triangle():
    # Three other points form the triad's shape 6 cm away; when one back marker drops out, the two left
    # keep the hand where it is rather than jumping to the look-alike.
    canonical = TRIAD - TRIAD.mean(0)
    finder = HandFrameFinder(RigidSet(("a", "b", "c"), canonical, 0.003))
    hand, _ = place(canonical, [0, 0, 0], [0, 0, 1.0])
    look_alike, _ = place(canonical, [0, 0.4, 0], [0.06, 0.0, 1.0])
    assert (finder.find(np.concatenate([hand, look_alike])).points == [0, 1, 2]).all()
    pose = finder.find(np.concatenate([hand[1:], look_alike]))
    np.testing.assert_array_equal(pose.points, [-1, 0, 1])
    np.testing.assert_allclose(pose.translation, [0, 0, 1.0], atol=1e-3)
    # A stray point near the hidden marker's place does not pass for it: it breaks the rigid distances.
    stray = hand[0] + [0.008, 0, 0]
    pose = finder.find(np.concatenate([hand[1:], [stray], look_alike]))
    np.testing.assert_array_equal(pose.points, [-1, 0, 1])


def test_object_found_with_its_best_triangle_hidden_and_not_from_a_chance_triangle():
    rng = np.random.default_rng(3)
    canonical = rng.normal(scale=0.04, size=(8, 3))
    canonical -= canonical.mean(0)
    rigid = RigidSet.for_object([f"o{i}" for i in range(8)], canonical)
    world, rot = place(canonical, [1.0, 0.2, -0.4], [0.0, 0.3, 0.9])
    for hidden in range(8):  # whichever marker is hidden, the object is found afresh from the others
        finder = HandFrameFinder(rigid, max_hold=0)
        pose = finder.find(np.delete(world, hidden, axis=0))
        assert pose.found and (pose.points >= 0).sum() == 7
        np.testing.assert_allclose(pose.rotation, rot, atol=1e-6)
    # Three points that happen to match one triangle of the object, and nothing else: not the object.
    fresh = HandFrameFinder(rigid, max_hold=0)
    a, b, c = finder._anchors[0]
    chance, _ = place(canonical[[a, b, c]], [0.2, 0.2, 0.2], [0.5, 0.0, 1.0])
    assert fresh.find(np.concatenate([chance, rng.uniform(-0.3, 0.3, (5, 3))])) is None


def test_a_suspect_frame_is_searched_afresh_and_leaves_a_look_alike():
    # Locked onto a look-alike (the real triad was hidden when the hand was first found), the finder keeps
    # tracking it while its markers stay put; flagged as suspect, it searches and the fit picks the hand.
    canonical = TRIAD - TRIAD.mean(0)
    finder = HandFrameFinder(RigidSet(("a", "b", "c"), canonical, 0.003))
    hand, _ = place(canonical, [0, 0, 0], [0, 0, 1.0])
    look_alike, _ = place(canonical, [0, 0.4, 0], [0.06, 0.0, 1.0])
    finder.find(look_alike)
    both = np.concatenate([look_alike, hand])

    def fit(rot, trans, used):  # the other points fit well only in the hand's true frame
        return -4e3 * np.linalg.norm(trans - [0, 0, 1.0])  # 240 at the look-alike, as measured in a grasp

    assert (finder.find(both, fit).points == [0, 1, 2]).all()
    finder.suspect = True
    assert (finder.find(both, fit).points == [3, 4, 5]).all()


def test_triangles_within_lists_what_the_whole_cube_of_tests_lists():
    # The pair-then-third search against the brute (K, K, K) test, in its order, for one frame and for a batch.
    rng = np.random.default_rng(5)
    points = rng.uniform(-0.05, 0.05, (4, 30, 3))
    points[2, 25:] = np.nan  # a shorter frame, padded
    dist = np.linalg.norm(points[:, :, None] - points[:, None], axis=-1)
    sides, tol = np.array([0.04, 0.05, 0.045]), 0.004
    e = [np.abs(dist - s) < tol for s in sides]
    brute = np.argwhere(e[0][..., :, :, None] & e[1][..., :, None, :] & e[2][..., None, :, :])
    assert len(brute) > 50
    np.testing.assert_array_equal(triangles_within(dist, sides, tol), brute)
    np.testing.assert_array_equal(triangles_within(dist[1], sides, tol), brute[brute[:, 0] == 1, 1:])
    assert not (triangles_within(dist, sides, tol)[:, 1:] >= 25)[brute[:, 0] == 2].any()


def test_search_frames_gives_what_find_gives_after_reset():
    # Frames of a triad among clutter (some without it, some with a look-alike, one of two points), searched for
    # three sets at once (the triad, one a little larger, one of other sides): each set's poses are those its
    # finder finds frame by frame.
    rng = np.random.default_rng(8)
    canonical = TRIAD - TRIAD.mean(0)
    sets = [RigidSet(("a", "b", "c"), c, 0.003) for c in (canonical, canonical * 1.08, canonical[[0, 2, 1]] * 0.9)]
    frames = []
    for t in range(40):
        hand, _ = place(canonical, rng.normal(size=3), rng.normal(scale=0.1, size=3) + [0, 0, 1])
        clutter = rng.uniform(-0.1, 0.1, (rng.integers(0, 25), 3)) + hand.mean(0)
        parts = [hand + rng.normal(scale=0.0007, size=hand.shape)] if t % 5 else []
        if t % 7 == 0:
            parts.append(place(canonical * 1.08, rng.normal(size=3), hand.mean(0) + [0.05, 0, 0])[0])
        pts = np.concatenate(parts + [clutter])
        frames.append(pts[rng.permutation(len(pts))])
    frames.append(frames[1][:2])
    batched = search_frames(sets, frames)
    counts = []
    for rigid, poses in zip(sets, batched):
        finder = HandFrameFinder(rigid, max_hold=0)
        for pts, pose in zip(frames, poses):
            finder.reset()
            alone = finder.find(pts)
            assert (alone is None) == (pose is None)
            if pose is not None:
                np.testing.assert_array_equal(pose.points, alone.points)
                np.testing.assert_allclose(pose.rotation, alone.rotation, atol=1e-12)
                np.testing.assert_allclose(pose.translation, alone.translation, atol=1e-12)
        counts.append(sum(p is not None for p in poses))
    assert 30 <= counts[0] < len(frames) and counts[1] >= 5
    assert search_frames(sets, []) == [[], [], []] and search_frames(sets[:1], [frames[1][:2]]) == [[None]]
