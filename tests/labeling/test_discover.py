"""A rigid body nobody named, found among the points a labelling leaves (handcap.labeling.discover)."""

import numpy as np
from scipy.spatial.distance import pdist
from scipy.spatial.transform import Rotation

from handcap.labeling.discover import find_rigid_body


def _body_frames(body, frames=300, ghosts=3, hidden=0.1, seed=0):
    """Frames of a rigid ``body`` (M, 3) turning and moving about, its markers hidden at random, among ghosts."""
    rng = np.random.default_rng(seed)
    turns = Rotation.random(frames, random_state=seed).as_matrix()
    out = []
    for t in range(frames):
        pts = body @ turns[t].T + rng.uniform(-0.5, 0.5, 3) + rng.normal(0.0, 0.0002, body.shape)
        pts = pts[rng.random(len(body)) > hidden]
        out.append(rng.permutation(np.vstack([pts, rng.uniform(-0.6, 0.6, (rng.poisson(ghosts), 3))])))
    return out


def test_a_rigid_body_among_ghosts_is_found_with_its_shape():
    # Six markers of a tool 2-12 cm apart, each hidden in 10 % of the frames, 3 ghosts a frame anywhere.
    body = np.array([[0.0, 0.0, 0.0], [0.05, 0.0, 0.0], [0.0, 0.08, 0.0], [0.03, 0.02, 0.06], [0.11, 0.05, 0.01],
                     [-0.02, 0.04, 0.03]])
    found = find_rigid_body(_body_frames(body), name="tool")
    assert found is not None and len(found.names) == len(body) and found.names[0] == "tool:0"
    np.testing.assert_allclose(found.canonical.mean(axis=0), 0.0, atol=1e-12)
    # Its shape: the same distances (independent of how its markers are numbered).
    np.testing.assert_allclose(np.sort(pdist(found.canonical)), np.sort(pdist(body)), atol=0.0005)


def test_ghosts_alone_or_a_body_seen_too_rarely_are_no_body():
    assert find_rigid_body(_body_frames(np.zeros((0, 3)), ghosts=8)) is None
    body = np.array([[0.0, 0.0, 0.0], [0.05, 0.0, 0.0], [0.0, 0.08, 0.0], [0.03, 0.02, 0.06]])
    rare = [f if t % 5 == 0 else f[:0] for t, f in enumerate(_body_frames(body, ghosts=0))]  # in 20 % of frames
    assert find_rigid_body(rare) is None and find_rigid_body(rare, min_share=0.15) is not None
    assert find_rigid_body([]) is None and find_rigid_body([np.zeros((0, 3))] * 5) is None


def test_markers_in_a_line_do_not_anchor_the_body_but_are_found_in_its_frame():
    # Three markers on a straight stick (a flat triangle has no frame) and one off it: the one triangle off the
    # line anchors the body, and the fourth marker is found in its frame.
    body = np.array([[0.0, 0.0, 0.0], [0.04, 0.0, 0.0], [0.11, 0.0, 0.0], [0.03, 0.05, 0.0]])
    found = find_rigid_body(_body_frames(body, ghosts=1))
    assert found is not None and np.isfinite(found.canonical).all() and len(found.names) == 4
    np.testing.assert_allclose(np.sort(pdist(found.canonical)), np.sort(pdist(body)), atol=0.0005)
    assert find_rigid_body(_body_frames(body[:3], ghosts=0)) is None  # the stick alone: no frame, no body


def test_a_symmetric_body_anchors_on_a_triangle_seen_once_a_frame():
    # A parallelogram's triangles come in congruent pairs (ABC and CDA): symmetric as a whole, it is found as it
    # is (its other marker falls on the same spot either way). With a fifth marker off its plane, a triangle
    # through that one anchors it (the parallelogram's own triangles would put the fifth marker at two spots),
    # and all five are found. (A cylinder's markers in a ring gave 13 spots for 10 markers before.)
    square = np.array([[0.0, 0.0, 0.0], [0.06, 0.0, 0.0], [0.08, 0.05, 0.0], [0.02, 0.05, 0.0]])
    alone = find_rigid_body(_body_frames(square, ghosts=0, hidden=0.0))
    np.testing.assert_allclose(np.sort(pdist(alone.canonical)), np.sort(pdist(square)), atol=0.0005)
    body = np.vstack([square, [0.01, 0.02, 0.04]])
    found = find_rigid_body(_body_frames(body, ghosts=1, hidden=0.0))
    assert found is not None and len(found.names) == 5
    np.testing.assert_allclose(np.sort(pdist(found.canonical)), np.sort(pdist(body)), atol=0.0005)


def test_a_cylinders_markers_are_found_once_each():
    # The synthetic cylinder's 10 markers sit round it, and many of their triangles are congruent. Anchored on a
    # shape that two triangles match in a frame, the other markers came out at 16 spots on two of three seeds.
    from handcap.synth.scene import SynthConfig, synthesize

    config = SynthConfig(layout="joints-19", motion="grasp", frames=260, seed=12, subject_seed=5)
    cylinder = synthesize(config, progress=False).object_motion.canonical
    for seed in (0, 1, 2):
        found = find_rigid_body(_body_frames(cylinder, ghosts=2, seed=seed))
        assert found is not None and len(found.names) == len(cylinder)
        np.testing.assert_allclose(np.sort(pdist(found.canonical)), np.sort(pdist(cylinder)), atol=0.0005)
