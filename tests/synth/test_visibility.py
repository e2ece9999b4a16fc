from dataclasses import replace

import numpy as np
import pytest
import trimesh

from handcap.core.cameras import Camera, CameraRig
from handcap.core.compiled import AVAILABLE as NUMBA
from handcap.synth import visibility
from handcap.synth.visibility import PAIRS_AT_ONCE, camera_visibility, occluded, take_visibility

K = np.array([[800.0, 0, 320], [0, 800, 240], [0, 0, 1]])


def looking_down_z(z=2.0):
    # Camera at (0, 0, z) looking towards -z: world->camera flips y and z.
    from scipy.spatial.transform import Rotation
    rot = Rotation.from_matrix(np.diag([1.0, -1.0, -1.0])).as_rotvec()
    return Camera("top", (640, 480), K, np.zeros(5), rot, np.array([0.0, 0.0, z]))


def test_a_box_hides_what_is_under_it():
    camera = looking_down_z()
    box = trimesh.creation.box(extents=[0.2, 0.2, 0.1])
    points = np.array([[0.0, 0.0, -0.2], [0.5, 0.0, -0.2], [0.0, 0.0, 0.2], [0.0, 0.0, 0.0501]])
    hidden = occluded(camera, points, box.vertices, box.faces)
    np.testing.assert_array_equal(hidden, [True, False, False, False])


def brute_force_hidden(camera, points, mesh):
    """trimesh's own ray casting: hidden where the first hit is more than 0.1 mm before the point."""
    direction = points - camera.center
    length = np.linalg.norm(direction, axis=1)
    hits, ray, _ = mesh.ray.intersects_location(np.repeat(camera.center[None], len(points), 0),
                                               direction / length[:, None])
    expect = np.zeros(len(points), bool)
    for r, h in zip(ray, hits):
        if np.linalg.norm(h - camera.center) < length[r] - 1e-4:
            expect[r] = True
    return expect


# Both ways of testing: compiled (numba's grid of image boxes) and numpy (every point against every box at once).
WAYS = [False, pytest.param(True, marks=pytest.mark.skipif(not NUMBA, reason="numba is not installed"))]


@pytest.fixture(params=WAYS, ids=["numpy", "compiled"])
def compiled(request, monkeypatch):
    monkeypatch.setattr(visibility, "COMPILED", request.param)
    return request.param


def test_culled_test_agrees_with_brute_force_rays(compiled):
    rng = np.random.default_rng(0)
    mesh = trimesh.creation.icosphere(subdivisions=3, radius=0.1)
    mesh.vertices *= [1.0, 0.5, 0.7]
    points = rng.uniform(-0.2, 0.2, size=(400, 3))
    points = points[~mesh.contains(points)]
    camera = looking_down_z()
    hidden = occluded(camera, points, mesh.vertices, mesh.faces)
    expect = brute_force_hidden(camera, points, mesh)
    np.testing.assert_array_equal(hidden, expect)
    assert 10 < expect.sum() < len(points) - 10


def test_frames_tested_together_agree_with_brute_force_rays_in_each(monkeypatch, compiled):
    # Each frame its own mesh (moved and turned) and points; a small pair budget splits the frames in chunks.
    monkeypatch.setattr("handcap.synth.visibility.PAIRS_AT_ONCE", 3 * 60 * 1280)
    assert PAIRS_AT_ONCE > 3 * 60 * 1280
    rng = np.random.default_rng(1)
    base = trimesh.creation.icosphere(subdivisions=3, radius=0.1)
    rig = CameraRig((looking_down_z(), replace(looking_down_z(2.5), name="high")))
    meshes, points = [], []
    for t in range(7):
        mesh = base.copy()
        mesh.vertices *= [1.0, 0.5 + 0.05 * t, 0.7]
        mesh.apply_transform(trimesh.transformations.rotation_matrix(0.3 * t, [0, 1, 0]))
        mesh.vertices += [0.02 * t, 0.0, 0.0]
        p = rng.uniform(-0.2, 0.2, size=(120, 3))
        points.append(p[~mesh.contains(p)][:60])
        meshes.append(mesh)
    points = np.stack(points)
    points[2, 5] = np.nan
    seen = take_visibility(points, rig, np.stack([m.vertices for m in meshes]), base.faces)
    assert seen.shape == (7, 2, 60) and not seen[2, :, 5].any()
    for t, mesh in enumerate(meshes):
        for c, camera in enumerate(rig):
            finite = np.isfinite(points[t]).all(axis=1)
            pixels, depth = camera.project(points[t])
            expect = finite & camera.in_image(pixels) & (depth > 0)
            expect[finite] &= ~brute_force_hidden(camera, points[t, finite], mesh)
            np.testing.assert_array_equal(seen[t, c], expect)
    assert 20 < (~seen).sum() < seen.size - 20


def test_view_angle_and_image_bounds():
    camera = looking_down_z()
    rig = CameraRig((camera,))
    flat = trimesh.creation.box(extents=[0.01, 0.01, 0.01])
    flat.vertices += [5.0, 5.0, -5.0]  # far away, hides nothing
    points = np.array([[0.0, 0.0, 0.0], [0.0, 0.0, 0.0], [3.0, 0.0, 0.0], [np.nan, 0, 0]])
    normals = np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, 0.0, 1.0]])
    seen = camera_visibility(points, rig, flat.vertices, flat.faces, normals=normals, max_view_angle=np.deg2rad(75))
    np.testing.assert_array_equal(seen[0], [True, False, False, False])


@pytest.mark.skipif(not NUMBA, reason="numba is not installed")
def test_compiled_and_numpy_agree_on_a_patched_hand_holding_a_box(monkeypatch):
    # Hundreds of printed corners on the hand (each camera's grid then has many cells), the box's markers apart,
    # the hand's own skin and the box hiding them: the two ways give the same answer for every marker and camera.
    from handcap.synth.scene import SynthConfig, synthesize

    def seen(way):
        monkeypatch.setattr(visibility, "COMPILED", way)
        config = SynthConfig(layout="dense-patches", motion="grasp", object="cuboid", frames=30, seed=4, cameras=4,
                             rate=10.0)
        return synthesize(config, progress=False).truth["camera_visible"]

    compiled, numpy_way = seen(True), seen(False)
    np.testing.assert_array_equal(compiled, numpy_way)
    assert 0.1 < compiled.mean() < 0.9 and compiled.shape[2] > 400
