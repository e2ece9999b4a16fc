"""Metrics against hand-computed values."""

import numpy as np
import pytest
import trimesh
from scipy.spatial.transform import Rotation

from handcap.quality import (
    diversity_coherence,
    jerk,
    joint_position_error,
    marker_reconstruction_error,
    msnr,
    penetration,
)


def test_jerk_of_a_cubic_trajectory_is_six_times_its_leading_coefficient():
    rate = 50.0
    t = np.arange(100) / rate
    x = 0.2 * t**3 - t**2 + 0.5  # m: third derivative 1.2 m/s^3
    joints = np.zeros((100, 2, 3))
    joints[:, 1, 0] = x
    joints[:, 0, 2] = -0.5 * x
    s = jerk(joints, rate)
    np.testing.assert_allclose(s.mean, (1.2 + 0.6) / 2, rtol=1e-6)
    assert s.count == 97 * 2


def test_msnr_matches_its_definition_on_a_small_example():
    rng = np.random.default_rng(0)
    joints = rng.normal(size=(8, 3, 3))
    local = joints[:, 1:] - joints[:, :1]
    v = np.diff(local, axis=0)
    v_hat = np.empty_like(v)
    for t in range(len(v)):  # centred moving average of 3, ends repeated
        v_hat[t] = (v[max(t - 1, 0)] + v[t] + v[min(t + 1, len(v) - 1)]) / 3
    expect = 10 * np.log10(np.mean(v_hat**2) / np.mean((v - v_hat) ** 2))
    assert msnr(joints) == pytest.approx(expect)


def test_msnr_falls_as_noise_grows():
    t = np.arange(400) / 100.0
    joints = np.zeros((400, 2, 3))
    joints[:, 1, 0] = 0.05 * np.sin(2 * np.pi * t)
    rng = np.random.default_rng(1)
    values = [msnr(joints + rng.normal(0, s, joints.shape)) for s in (1e-5, 1e-4, 1e-3)]
    assert values[0] > values[1] > values[2]


def test_penetration_of_two_overlapping_spheres():
    a = trimesh.creation.icosphere(subdivisions=4, radius=0.03)
    b = trimesh.creation.icosphere(subdivisions=4, radius=0.04)
    # Sphere a's vertex nearest b's centre lies on the x axis: depth r_a + r_b - d.
    distance = 0.05
    hand = np.asarray(a.vertices)[None]
    obj = np.asarray(b.vertices) + [-distance, 0.0, 0.0]
    closest = hand[0][np.argmin(hand[0][:, 0])]
    expect = 0.04 - np.linalg.norm(closest - [-distance, 0, 0])
    s = penetration(np.repeat(hand, 3, axis=0), obj, b.faces)
    assert s.count == 3
    assert s.mean == pytest.approx(expect, abs=2e-4)  # the mesh is a polyhedron, not a sphere
    assert s.mean == pytest.approx(0.03 + 0.04 - distance, abs=1e-3)
    apart = penetration(hand, obj + [-0.2, 0, 0], b.faces)
    assert apart.count == 0


def test_penetration_of_a_turning_box_the_same_in_its_frame_as_in_the_world():
    # A box turned and moved in every frame, into which a sphere reaches 3, 6 and 9 mm, and in a fourth frame the
    # object is lost (NaN); measured per frame in the world, and once in the box's frame with the sphere moved there.
    box = trimesh.creation.box(extents=(0.06, 0.04, 0.02))
    ball = np.asarray(trimesh.creation.icosphere(subdivisions=3, radius=0.01).vertices)
    turns = Rotation.from_rotvec([[0.3, -0.5, 0.9], [1.2, 0.1, -0.4], [-0.7, 0.8, 0.2], [0.0, 0.0, 0.0]]).as_matrix()
    moves = np.array([[0.1, 0.2, 0.3], [-0.2, 0.05, 0.4], [0.0, -0.1, 0.5], [0.0, 0.0, 0.0]])
    local = np.stack([ball + [0.03 + 0.01 - depth, 0.0, 0.0] for depth in (0.003, 0.006, 0.009, 0.005)])
    world_hand = np.einsum("tij,tvj->tvi", turns, local) + moves[:, None]
    world_box = np.einsum("tij,vj->tvi", turns, np.asarray(box.vertices)) + moves[:, None]
    world_box[3] = np.nan
    local[3] = np.nan
    in_world = penetration(world_hand, world_box, box.faces)
    in_frame = penetration(local, np.asarray(box.vertices), box.faces)
    assert in_world.count == in_frame.count == 3
    assert in_frame.mean == pytest.approx(in_world.mean, abs=1e-12) and in_frame.std == pytest.approx(in_world.std)
    assert in_frame.mean == pytest.approx(0.006, abs=2e-4)  # the sphere's mesh, a polyhedron, reaches a bit less


def test_mre_and_joint_error_on_known_arrays():
    fitted = np.zeros((2, 2, 3))
    observed = np.array([[[0.003, 0, 0], [0, 0.004, 0]], [[np.nan] * 3, [0, 0, 0.002]]])
    s = marker_reconstruction_error(fitted, observed)
    assert (s.mean, s.count) == (pytest.approx(0.003), 3)
    assert s.std == pytest.approx(np.std([0.003, 0.004, 0.002]))
    assert joint_position_error(fitted, fitted + [0.001, 0, 0]).mean == pytest.approx(0.001)


def test_diversity_and_coherence():
    rng = np.random.default_rng(3)
    centres = rng.normal(size=(5, 4)) * 10
    clustered = np.repeat(centres, 40, axis=0) + rng.normal(size=(200, 4)) * 0.1
    d, c = diversity_coherence(clustered)
    assert d == pytest.approx(1.0, abs=1e-9) and c > 0.95
    lopsided = np.vstack([np.repeat(centres[:1], 180, axis=0), np.repeat(centres[1:], 5, axis=0)])
    d2, _ = diversity_coherence(lopsided + rng.normal(size=lopsided.shape) * 0.1)
    assert d2 < 0.5
    blob = rng.normal(size=(200, 4))
    assert diversity_coherence(blob)[1] < 0.7
