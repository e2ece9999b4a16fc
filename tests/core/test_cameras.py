import cv2
import numpy as np
import pytest

from handcap.core.cameras import Camera, CameraRig
from handcap.core.errors import HandcapError

K = np.array([[2200.0, 0.0, 1230.5], [0.0, 2203.0, 1010.25], [0.0, 0.0, 1.0]])
# Of the size calibrateCamera gives for industrial 8-12 mm lenses.
REALISTIC = np.array([-0.12, 0.08, 0.0011, -0.0007, -0.02])


def look_at(name, eye, target=(0.0, 0.0, 0.0), distortions=REALISTIC, size=(2448, 2048)):
    """A camera at ``eye`` looking at ``target`` with image up along +z, built by hand."""
    eye, target = np.asarray(eye, float), np.asarray(target, float)
    forward = (target - eye) / np.linalg.norm(target - eye)
    right = np.cross(forward, [0.0, 0.0, 1.0])
    right /= np.linalg.norm(right)
    rotation = np.stack([right, np.cross(forward, right), forward])
    rvec, _ = cv2.Rodrigues(rotation)
    return Camera(name, size, K, distortions, rvec, -rotation @ eye)


@pytest.fixture
def ring():
    """Four cameras 1.5 m around the origin, alternately above and below it."""
    angles = np.deg2rad([20, 110, 200, 290])
    eyes = np.stack([1.5 * np.cos(angles), 1.5 * np.sin(angles), [0.6, -0.4, 0.5, -0.3]], axis=1)
    return CameraRig([look_at(f"cam_{i}", eye) for i, eye in enumerate(eyes)])


def random_camera(rng, distortion_scale):
    rotation = rng.normal(size=3)
    matrix = np.array([[rng.uniform(800, 4000), 0, rng.uniform(500, 1500)],
                       [0, rng.uniform(800, 4000), rng.uniform(400, 1100)], [0, 0, 1]])
    distortions = distortion_scale * rng.uniform(-1, 1, 5) * [0.3, 0.1, 0.01, 0.01, 0.05]
    return Camera("random", (2448, 2048), matrix, distortions, rotation, rng.normal(scale=0.5, size=3))


# -- projection ------------------------------------------------------------------------
@pytest.mark.parametrize("seed", range(5))
def test_project_matches_opencv(seed):
    rng = np.random.default_rng(seed)
    camera = random_camera(rng, distortion_scale=1.0)
    # Points in front of the camera within about 40 degrees of the optical axis.
    depth = rng.uniform(0.3, 3, (500, 1))
    local = np.concatenate([rng.uniform(-0.8, 0.8, (500, 2)), np.ones((500, 1))], axis=1) * depth
    points = (local - camera.translation) @ camera.rotation_matrix  # R.T (x - t)
    pixels, depth = camera.project(points)
    expected, _ = cv2.projectPoints(points, camera.rotation, camera.translation, camera.matrix, camera.distortions)
    np.testing.assert_allclose(pixels, expected.reshape(-1, 2), rtol=0, atol=1e-9)
    np.testing.assert_allclose(depth, local[:, 2], rtol=0, atol=1e-12)


def test_project_random_points_both_sides_matches_opencv_in_front_and_nan_behind():
    rng = np.random.default_rng(11)
    camera = random_camera(rng, distortion_scale=1.0)
    points = camera.center + rng.normal(size=(400, 3))
    pixels, depth = camera.project(points)
    front = depth > 0
    assert 50 < front.sum() < 350
    expected, _ = cv2.projectPoints(points[front], camera.rotation, camera.translation, camera.matrix,
                                    camera.distortions)
    # Far off the axis pixels reach millions; there the two agree to rounding (relative 1e-12).
    np.testing.assert_allclose(pixels[front], expected.reshape(-1, 2), rtol=1e-11, atol=1e-9)
    assert np.isnan(pixels[~front]).all()
    np.testing.assert_allclose(depth, (points - camera.center) @ camera.rotation_matrix[2], atol=1e-12)


def test_project_keeps_batch_shape_and_propagates_nan():
    rng = np.random.default_rng(2)
    camera = look_at("a", [0.2, -2.0, 0.5])
    points = rng.uniform(-0.3, 0.3, (4, 6, 3))
    points[1, 2] = np.nan
    pixels, depth = camera.project(points)
    assert pixels.shape == (4, 6, 2) and depth.shape == (4, 6)
    flat_pixels, flat_depth = camera.project(points.reshape(-1, 3))
    np.testing.assert_array_equal(pixels.reshape(-1, 2), flat_pixels)
    np.testing.assert_array_equal(depth.ravel(), flat_depth)
    assert np.isnan(pixels[1, 2]).all() and np.isnan(depth[1, 2])
    assert np.isfinite(np.delete(pixels.reshape(-1, 2), 8, axis=0)).all()
    single_pixels, single_depth = camera.project(points[0, 0])
    assert single_pixels.shape == (2,) and single_depth.shape == ()


def test_frames_and_projection_agree():
    camera = look_at("a", [1.0, -2.0, 0.7], target=[0.1, 0.0, 0.2])
    rotation, _ = cv2.Rodrigues(camera.rotation)
    np.testing.assert_allclose(camera.rotation_matrix, rotation, atol=1e-15)
    np.testing.assert_allclose(camera.center, [1.0, -2.0, 0.7], atol=1e-12)
    np.testing.assert_allclose(camera.camera2world @ camera.world2camera, np.eye(4), atol=1e-12)
    # The optical axis (camera z) points at the target.
    axis = camera.camera2world[:3, :3] @ [0.0, 0.0, 1.0]
    np.testing.assert_allclose(axis, np.array([-0.9, 2.0, -0.5]) / np.linalg.norm([-0.9, 2.0, -0.5]), atol=1e-12)
    np.testing.assert_allclose(camera.projection @ [*camera.center, 1.0], 0.0, atol=1e-9)
    # Without distortion, project is the projection matrix.
    pinhole = Camera("p", camera.size, camera.matrix, np.zeros(5), camera.rotation, camera.translation)
    points = np.random.default_rng(3).uniform(-0.3, 0.3, (50, 3))
    homogeneous = np.concatenate([points, np.ones((50, 1))], axis=1) @ camera.projection.T
    np.testing.assert_allclose(pinhole.project(points)[0], homogeneous[:, :2] / homogeneous[:, 2:], atol=1e-9)


# -- undistortion and rays -------------------------------------------------------------
def test_undistort_inverts_project():
    rng = np.random.default_rng(4)
    camera = look_at("a", [0.3, -1.8, 0.4])
    points = rng.uniform(-0.4, 0.4, (1000, 3))
    pixels, _ = camera.project(points)
    inside = camera.in_image(pixels)
    assert inside.sum() > 900
    pinhole = Camera("p", camera.size, camera.matrix, np.zeros(5), camera.rotation, camera.translation)
    ideal, _ = pinhole.project(points[inside])
    undistorted = camera.undistort_pixels(pixels[inside])
    assert np.abs(undistorted - ideal).max() < 1e-6
    local = points[inside] @ camera.rotation_matrix.T + camera.translation
    np.testing.assert_allclose(camera.undistort_pixels(pixels[inside], normalised=True),
                               local[:, :2] / local[:, 2:], rtol=0, atol=1e-9)


def test_undistort_keeps_shape_and_nan():
    camera = look_at("a", [0.0, -2.0, 0.0])
    pixels = np.array([[[100.0, 200.0], [np.nan, 5.0]], [[2400.0, 2000.0], [1224.0, 1024.0]]])
    out = camera.undistort_pixels(pixels)
    assert out.shape == (2, 2, 2)
    assert np.isnan(out[0, 1]).all() and np.isfinite(np.delete(out.reshape(-1, 2), 1, axis=0)).all()
    assert camera.undistort_pixels(np.zeros((0, 2))).shape == (0, 2)
    assert np.isnan(camera.undistort_pixels(np.full((3, 2), np.nan))).all()


def test_rays_pass_through_the_points():
    rng = np.random.default_rng(5)
    camera = look_at("a", [-1.0, -1.5, 0.8])
    points = rng.uniform(-0.3, 0.3, (200, 3))
    pixels, depth = camera.project(points)
    origins, directions = camera.rays(pixels)
    np.testing.assert_allclose(origins, np.broadcast_to(camera.center, (200, 3)))
    np.testing.assert_allclose(np.linalg.norm(directions, axis=1), 1.0, atol=1e-12)
    offsets = points - origins
    along = (offsets * directions).sum(axis=1)
    assert (along > 0).all()
    np.testing.assert_allclose(origins + along[:, None] * directions, points, atol=1e-9)
    # Distance along the ray and depth along the optical axis agree through the axis direction.
    np.testing.assert_allclose(along * (directions @ camera.rotation_matrix[2]), depth, atol=1e-9)


def test_in_image_follows_the_sensor_edges():
    camera = look_at("a", [0.0, -2.0, 0.0], size=(640, 480))
    pixels = np.array([[-0.5, -0.5], [639.49, 479.49], [639.5, 10], [10, 479.5], [-0.51, 10], [np.nan, 10]])
    np.testing.assert_array_equal(camera.in_image(pixels), [True, True, False, False, False, False])


# -- validation ------------------------------------------------------------------------
def test_camera_copies_and_freezes_its_arrays():
    matrix, rvec = K.copy(), np.array([[0.1], [0.2], [0.3]])  # OpenCV's (3, 1) vectors
    camera = Camera("a", (2448, 2048), matrix, REALISTIC.reshape(1, 5), rvec, [0.0, 0.0, 1.0])
    matrix[0, 0] = 1.0
    rvec[0] = 5.0
    assert camera.matrix[0, 0] == 2200.0 and camera.rotation[0] == 0.1
    assert camera.rotation.shape == (3,) and camera.distortions.shape == (5,)
    with pytest.raises(ValueError):
        camera.matrix[0, 0] = 3.0
    with pytest.raises(AttributeError):
        camera.name = "b"


def test_distortion_lengths_four_and_eight():
    four = Camera("a", (10, 10), K, [0.1, 0.2, 0.003, 0.004])
    np.testing.assert_array_equal(four.distortions, [0.1, 0.2, 0.003, 0.004, 0.0])
    eight = Camera("a", (10, 10), K, [0.1, 0.2, 0.003, 0.004, 0.05, 0.0, 0.0, 0.0])
    np.testing.assert_array_equal(eight.distortions, [0.1, 0.2, 0.003, 0.004, 0.05])
    assert Camera("a", (10, 10), K) == Camera("a", (10, 10), K, np.zeros(5), np.zeros(3), np.zeros(3))


def with_matrix(**entries):
    matrix = K.copy()
    for key, value in entries.items():
        matrix[int(key[1]), int(key[2])] = value
    return matrix


@pytest.mark.parametrize("changes, match", [
    ({"name": ""}, "name must be a non-empty string"),
    ({"name": 3}, "name must be a non-empty string"),
    ({"size": (2448,)}, r"size must be \[width, height\]"),
    ({"size": (2448, 0)}, "size must be two positive whole numbers"),
    ({"size": (2448.5, 2048)}, "size must be two positive whole numbers"),
    ({"size": (True, 2048)}, "size must be two positive whole numbers"),
    ({"matrix": np.eye(4)}, r"matrix must be 3x3 .* got shape \(4, 4\)"),
    ({"matrix": with_matrix(m00=-5.0)}, "focal lengths fx, fy must be positive"),
    ({"matrix": with_matrix(m01=0.5)}, "skew 0.5"),
    ({"matrix": with_matrix(m22=2.0)}, r"matrix must be \[\[fx, 0, cx\]"),
    ({"matrix": with_matrix(m02=np.nan)}, "matrix must be finite"),
    ({"matrix": "K"}, "matrix must be numbers"),
    ({"distortions": np.zeros(6)}, r"distortions must be 5 values .* got shape \(6,\)"),
    ({"distortions": [0, 0, 0, 0, 0, 0.1, 0, 0]}, "rational terms k4 k5 k6"),
    ({"distortions": [0, 0, np.inf, 0, 0]}, "distortions must be finite"),
    ({"rotation": [0.1, 0.2]}, r"rotation must have 3 values, got shape \(2,\)"),
    ({"rotation": [0.1, np.nan, 0.0]}, "rotation must be finite"),
    ({"translation": np.zeros((3, 3))}, "translation must have 3 values"),
    ({"translation": [[0.0, 1.0], [2.0]]}, "translation must be numbers"),
])
def test_camera_rejects_bad_values(changes, match):
    args = {"name": "a", "size": (2448, 2048), "matrix": K, "distortions": REALISTIC,
            "rotation": [0.1, 0.2, 0.3], "translation": [0.0, 0.0, 1.0]} | changes
    with pytest.raises(HandcapError, match=match):
        Camera(**args)


@pytest.mark.parametrize("method, value, match", [
    ("project", np.zeros((5, 2)), r"points must have shape \(\.\.\., 3\)"),
    ("undistort_pixels", np.zeros((5, 3)), r"pixels must have shape \(\.\.\., 2\)"),
    ("rays", np.zeros(3), r"pixels must have shape \(\.\.\., 2\)"),
    ("in_image", [["a", "b"]], "pixels must be numbers"),
])
def test_camera_methods_reject_bad_shapes(method, value, match):
    with pytest.raises(HandcapError, match=match):
        getattr(look_at("a", [0.0, -2.0, 0.0]), method)(value)


# -- rig -------------------------------------------------------------------------------
def test_rig_project_stacks_the_cameras(ring):
    points = np.random.default_rng(6).uniform(-0.2, 0.2, (30, 3))
    pixels, depths = ring.project(points)
    assert pixels.shape == (4, 30, 2) and depths.shape == (4, 30)
    for c, camera in enumerate(ring):
        single_pixels, single_depth = camera.project(points)
        np.testing.assert_array_equal(pixels[c], single_pixels)
        np.testing.assert_array_equal(depths[c], single_depth)
    assert ring.in_image(pixels).all()
    assert ring.projections.shape == (4, 3, 4) and ring.centers.shape == (4, 3)
    np.testing.assert_allclose(np.linalg.norm(ring.centers[:, :2], axis=1), 1.5, atol=1e-12)
    np.testing.assert_array_equal(ring.sizes, [[2448, 2048]] * 4)


def test_undistorted_pixels_and_projections_triangulate(ring):
    """An independent check: linear DLT on undistorted pixels recovers the points."""
    points = np.random.default_rng(7).uniform(-0.2, 0.2, (20, 3))
    pixels, _ = ring.project(points)
    undistorted = ring.undistort_pixels(pixels)
    projections = ring.projections
    for n, point in enumerate(points):
        rows = [undistorted[c, n, i] * projections[c, 2] - projections[c, i] for c in range(4) for i in (0, 1)]
        solution = np.linalg.svd(np.array(rows))[2][-1]
        np.testing.assert_allclose(solution[:3] / solution[3], point, atol=1e-9)
    normalised = ring.undistort_pixels(pixels, normalised=True)
    local = points @ ring[2].rotation_matrix.T + ring[2].translation
    np.testing.assert_allclose(normalised[2], local[:, :2] / local[:, 2:], atol=1e-12)


def test_rig_lookup(ring):
    assert len(ring) == 4 and ring.names == ("cam_0", "cam_1", "cam_2", "cam_3")
    assert ring["cam_2"] is ring[2] is ring[-2] is ring[np.int64(2)]
    assert ring.index("cam_3") == 3
    assert [camera.name for camera in ring] == list(ring.names)
    assert repr(ring) == "CameraRig(4 cameras: cam_0, cam_1, cam_2, cam_3)"
    assert ring == CameraRig(list(ring)) and ring != CameraRig(list(ring)[:3])


@pytest.mark.parametrize("key, match", [
    ("cam_9", "no camera named 'cam_9'; the rig has cam_0, cam_1, cam_2, cam_3"),
    (4, "camera index 4 is out of range for a rig of 4 cameras"),
    (-5, "camera index -5 is out of range"),
    (1.0, "cameras are looked up by index or name, got 1.0"),
])
def test_rig_lookup_rejects_unknown_keys(ring, key, match):
    with pytest.raises(HandcapError, match=match):
        ring[key]


def test_rig_rejects_bad_cameras(ring):
    with pytest.raises(HandcapError, match="at least one camera"):
        CameraRig([])
    with pytest.raises(HandcapError, match="camera names must be unique, repeated: cam_1"):
        CameraRig([ring[0], ring[1], ring[1]])
    with pytest.raises(HandcapError, match="cameras must be Camera objects, got dict"):
        CameraRig([ring[0], {"name": "b"}])
    with pytest.raises(HandcapError, match="cameras must be a sequence of Camera"):
        CameraRig(3)
    with pytest.raises(HandcapError, match=r"pixels must have shape \(C, N, 2\) with C = 4"):
        ring.in_image(np.zeros((3, 10, 2)))
    with pytest.raises(HandcapError, match=r"camera files are anipose-style \.toml, got '\.yaml'"):
        ring.save("rig.yaml")
    with pytest.raises(HandcapError, match="got 'no extension'"):
        CameraRig.load("rig")
