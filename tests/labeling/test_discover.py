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
