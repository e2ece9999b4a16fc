"""OpenHand: anthropometry, mesh quality, numpy/torch agreement, mirroring, shape."""

import numpy as np
import pytest
import torch
import trimesh

from handcap import HandcapError
from handcap.core.geometry import self_intersections
from handcap.hand import PHI_LIMITS, PHI_NAMES, OpenHand

# Buchholz et al. (1992) segment lengths / hand length, typed here independently
# of handcap.hand.anthropometry: proximal, middle, distal (thumb: metacarpal,
# proximal, distal). Average adult hand length: mean of 190 and 175 mm.
BUCHHOLZ = {
    "index": (0.265, 0.143, 0.097),
    "middle": (0.277, 0.170, 0.108),
    "ring": (0.259, 0.165, 0.107),
    "pinky": (0.206, 0.117, 0.093),
    "thumb": (0.251, 0.196, 0.158),
}
HAND_LENGTH_MM = 182.5
# Joint chains in the 21-joint output: MANO joints then tips (thumb, index, middle, ring, pinky).
CHAINS = {"index": (1, 2, 3, 17), "middle": (4, 5, 6, 18), "pinky": (7, 8, 9, 20),
          "ring": (10, 11, 12, 19), "thumb": (13, 14, 15, 16)}


@pytest.fixture(scope="module", params=["right", "left"])
def hand(request):
    return OpenHand(request.param)


def random_phi(rng, n):
    return rng.uniform(PHI_LIMITS[:, 0], PHI_LIMITS[:, 1], size=(n, 27))


def test_bone_lengths_match_buchholz_table(hand):
    joints = hand.forward().joints * 1000
    for finger, ratios in BUCHHOLZ.items():
        chain = joints[list(CHAINS[finger])]
        lengths = np.linalg.norm(np.diff(chain, axis=0), axis=1)
        np.testing.assert_allclose(lengths, np.array(ratios) * HAND_LENGTH_MM, atol=1.0)


def test_hand_length_and_breadth_are_the_average_adult(hand):
    joints = hand.forward().joints
    assert np.linalg.norm(joints[18] - joints[0]) * 1000 == pytest.approx(HAND_LENGTH_MM, abs=1.0)
    assert hand.measurements()["hand_breadth"] == pytest.approx(0.0815)


def test_mesh_is_watertight_consistent_and_encloses_the_joints(hand):
    out = hand.forward()
    mesh = trimesh.Trimesh(out.vertices, hand.faces, process=False)
    assert mesh.is_watertight
    assert mesh.is_winding_consistent
    assert 250e-6 < mesh.volume < 500e-6  # cubic metres: an adult hand and a little wrist
    inside = mesh.contains(out.joints[:16])
    assert inside.all(), np.flatnonzero(~inside)


def test_flat_hand_has_no_self_intersection(hand):
    out = hand.forward()
    assert len(self_intersections(out.vertices, hand.faces)) == 0


def test_every_segment_has_its_own_vertices(hand):
    counts = np.bincount(hand.segment_of_vertex, minlength=16)
    assert (counts > 10).all(), dict(zip(hand.segment_names, counts))
    assert hand.segment_names[0] == "palm" and hand.segment_names[2] == "index_middle"
    faces = hand.segment_faces("index_distal")
    assert len(faces) > 10 and (hand.segment_of_vertex[hand.faces[faces]] == 3).all()
    with pytest.raises(HandcapError, match="unknown hand segment"):
        hand.segment_id("index_tip")


def test_numpy_and_torch_forward_agree(hand):
    rng = np.random.default_rng(1)
    betas = rng.normal(size=10)
    phi = random_phi(rng, 8)
    orient, transl = rng.normal(size=(8, 3)), rng.normal(scale=0.3, size=(8, 3))
    ref = hand.forward(betas, orient, hand.hand_pose_from_phi(phi), transl)
    t = lambda a: torch.tensor(a, dtype=torch.float64)  # noqa: E731
    out = hand.forward(t(betas), t(orient), phi=t(phi), transl=t(transl))
    np.testing.assert_allclose(out.vertices.numpy(), ref.vertices, atol=1e-6)
    np.testing.assert_allclose(out.joints.numpy(), ref.joints, atol=1e-6)


def test_torch_forward_is_differentiable(hand):
    rng = np.random.default_rng(2)
    phi = torch.tensor(random_phi(rng, 1) * 0.5, requires_grad=True)
    betas = torch.tensor(rng.normal(size=10) * 0.5, requires_grad=True)
    orient = torch.tensor(rng.normal(size=(1, 3)), requires_grad=True)

    def f(phi, betas, orient):
        return hand.forward(betas, orient, phi=phi).vertices[:, ::97].sum(dim=-1)

    assert torch.autograd.gradcheck(f, (phi, betas, orient), eps=1e-6, atol=1e-5)


def test_pip_bend_of_90_degrees_turns_the_middle_phalanx_90_degrees_about_the_pip_axis(hand):
    phi = np.zeros(27)
    phi[PHI_NAMES.index("index_pip_bend")] = np.pi / 2
    rest, bent = hand.forward().joints, hand.forward(phi=phi).joints
    before, after = rest[3] - rest[2], bent[3] - bent[2]
    np.testing.assert_allclose(bent[:3], rest[:3], atol=1e-12)  # proximal part unmoved
    cos = before @ after / (np.linalg.norm(before) * np.linalg.norm(after))
    assert np.degrees(np.arccos(cos)) == pytest.approx(90.0, abs=1e-9)
    axis = np.cross(before, after)
    axis /= np.linalg.norm(axis)
    # Frame of MANO joint 2 (index PIP): z is the flexion axis; the left hand's
    # frames are mirror images (det -1), which turns the world axis around.
    pip_axis = hand.frames[1][:, 2] * np.sign(np.linalg.det(hand.frames[1]))
    np.testing.assert_allclose(axis, pip_axis, atol=1e-9)
    # Flexion moves the finger towards the palm.
    _, palmar, _ = __import__("handcap.hand.anatomy", fromlist=["hand_axes"]).hand_axes(rest[:16], hand.is_right)
    assert after @ palmar > 0.9 * np.linalg.norm(after)


def test_left_hand_is_the_mirror_of_the_right():
    right, left = OpenHand("right"), OpenHand("left")
    rng = np.random.default_rng(3)
    phi, betas = random_phi(rng, 4), rng.normal(size=10)
    orient, transl = rng.normal(size=(4, 3)), rng.normal(size=(4, 3))
    mirror = np.array([1.0, 1.0, -1.0])
    # Mirroring in z maps a rotation vector (a, b, c) to (-a, -b, c).
    r = right.forward(betas, orient, phi=phi, transl=transl)
    lh = left.forward(betas, orient * np.array([-1.0, -1.0, 1.0]), phi=phi, transl=transl * mirror)
    np.testing.assert_allclose(lh.joints, r.joints * mirror, atol=1e-12)
    np.testing.assert_allclose(lh.vertices, r.vertices * mirror, atol=1e-12)
    np.testing.assert_array_equal(left.faces, right.faces[:, ::-1])


def test_batch_equals_single_frames(hand):
    rng = np.random.default_rng(4)
    phi, orient = random_phi(rng, 5), rng.normal(size=(5, 3))
    batch = hand.forward(phi=phi, global_orient=orient)
    for i in range(5):
        single = hand.forward(phi=phi[i], global_orient=orient[i])
        np.testing.assert_allclose(single.vertices, batch.vertices[i], atol=1e-12)


def test_global_orient_and_transl_move_the_hand_rigidly(hand):
    from scipy.spatial.transform import Rotation
    rng = np.random.default_rng(5)
    phi = random_phi(rng, 1)[0]
    rotvec, transl = rng.normal(size=3), rng.normal(size=3)
    base = hand.forward(phi=phi)
    moved = hand.forward(phi=phi, global_orient=rotvec, transl=transl)
    expect = Rotation.from_rotvec(rotvec).apply(base.vertices) + transl  # wrist joint at the origin
    np.testing.assert_allclose(moved.vertices, expect, atol=1e-12)


def test_shape_values_are_smooth_and_documented():
    hand = OpenHand()
    base = hand.measurements()
    bigger = hand.measurements(np.eye(10)[0])
    assert bigger["hand_length"] / base["hand_length"] == pytest.approx(np.exp(0.052), rel=1e-9)
    broad = hand.measurements(np.eye(10)[1] * 2)
    assert broad["hand_breadth"] / base["hand_breadth"] == pytest.approx(np.exp(0.1), rel=1e-9)
    # Longer fingers (beta 2) leave the palm alone.
    rest0, rest2 = hand.rest_joints(), hand.rest_joints(np.eye(10)[2])
    np.testing.assert_allclose(rest2[[1, 4, 7, 10]], rest0[[1, 4, 7, 10]], atol=1e-12)
    assert np.linalg.norm(rest2[18] - rest2[4]) > np.linalg.norm(rest0[18] - rest0[4]) * 1.03
    # Thicker (beta 4): volume grows, lengths do not.
    v0 = trimesh.Trimesh(hand.forward().vertices, hand.faces).volume
    v4 = trimesh.Trimesh(hand.forward(np.eye(10)[4]).vertices, hand.faces).volume
    assert v4 / v0 == pytest.approx(np.exp(0.12), rel=0.05)
    np.testing.assert_allclose(hand.rest_joints(np.eye(10)[4])[:, 0], rest0[:, 0], atol=1e-12)


@pytest.mark.parametrize("seed", range(3))
def test_joints_stay_inside_the_mesh_for_other_shapes(seed):
    hand = OpenHand()
    betas = np.random.default_rng(seed).normal(size=10) * 1.5
    out = hand.forward(betas)
    mesh = trimesh.Trimesh(out.vertices, hand.faces, process=False)
    assert mesh.contains(out.joints[:16]).all()


def test_bad_inputs_are_refused():
    hand = OpenHand()
    with pytest.raises(HandcapError, match="hand_pose must have shape"):
        hand.forward(hand_pose=np.zeros((3, 44)))
    with pytest.raises(HandcapError, match="batch shape"):
        hand.forward(hand_pose=np.zeros((3, 45)), transl=np.zeros((4, 3)))
    with pytest.raises(HandcapError, match="betas must have 10"):
        hand.forward(betas=np.zeros(9))
    with pytest.raises(HandcapError, match="not both"):
        hand.forward(hand_pose=np.zeros(45), phi=np.zeros(27))
    with pytest.raises(HandcapError, match="side must be"):
        OpenHand("middle")
