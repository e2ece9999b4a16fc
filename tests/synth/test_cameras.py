import numpy as np
import pytest

from handcap.core.errors import HandcapError
from handcap.synth.cameras import MAX_CAMERAS, WORK_VOLUME_M, cage_rig

TARGET = np.array([0.0, 0.0, 1.0])


def sphere(radius, n=2000, seed=0):
    directions = np.random.default_rng(seed).normal(size=(n, 3))
    return TARGET + radius * directions / np.linalg.norm(directions, axis=1, keepdims=True)


@pytest.mark.parametrize("seed", range(4))
@pytest.mark.parametrize("n_cameras", [1, 4, 12, 13, MAX_CAMERAS])
def test_every_camera_sees_the_work_volume(n_cameras, seed):
    rig = cage_rig(n_cameras, seed=seed)
    assert len(rig) == n_cameras
    pixels, depths = rig.project(TARGET[None])
    assert (depths > 0).all() and rig.in_image(pixels).all()
    # The 0.5 m volume around the target is framed: all of it in view, and it
    # spans most of the short side of the image.
    pixels, depths = rig.project(sphere(WORK_VOLUME_M / 2))
    assert (depths > 0).all() and rig.in_image(pixels).all()
    spans = np.ptp(pixels, axis=1).min(axis=1)
    assert (spans > 0.8 * 2048).all()


def test_rig_surrounds_the_target():
    rig = cage_rig()
    offsets = rig.centers - TARGET
    quadrants = np.floor(np.arctan2(offsets[:, 1], offsets[:, 0]) / (np.pi / 2)) % 4
    assert set(quadrants) == {0, 1, 2, 3}
    assert (offsets[:, 2] > 0.2).sum() >= 4 and (offsets[:, 2] < -0.2).sum() >= 4
    # Four cameras are already spread out.
    offsets = cage_rig(4).centers - TARGET
    assert set(np.floor(np.arctan2(offsets[:, 1], offsets[:, 0]) / (np.pi / 2)) % 4) == {0, 1, 2, 3}
    assert (offsets[:, 2] > 0).any() and (offsets[:, 2] < 0).any()


@pytest.mark.parametrize("seed", range(3))
def test_cameras_sit_on_the_cage_frame(seed):
    centers = cage_rig(MAX_CAMERAS, seed=seed, cage_size=(2.4, 1.2, 2.1), target=(0.1, -0.1, 0.9)).centers
    x, y, z = np.abs(centers[:, 0]), np.abs(centers[:, 1]), centers[:, 2]
    assert (x <= 1.2 + 1e-12).all() and (y <= 0.6 + 1e-12).all() and ((z >= 0) & (z <= 2.1 + 1e-12)).all()
    on_side = np.isclose(x, 1.2, atol=1e-12) | np.isclose(y, 0.6, atol=1e-12)
    assert on_side.all()
    assert len(np.unique(centers.round(6), axis=0)) == MAX_CAMERAS


def test_cameras_are_upright_and_look_at_the_target():
    rig = cage_rig(distortion_scale=0.0)
    above, _ = rig.project(TARGET + [0.0, 0.0, 0.1])
    below, _ = rig.project(TARGET - [0.0, 0.0, 0.1])
    assert (above[:, 1] < below[:, 1]).all()  # image v grows downwards, world z upwards
    for camera in rig:
        axis = camera.camera2world[:3, 2]
        to_target = (TARGET - camera.center) / np.linalg.norm(TARGET - camera.center)
        assert np.degrees(np.arccos(np.clip(axis @ to_target, -1, 1))) <= 1.0 + 1e-9
        np.testing.assert_allclose(camera.matrix[:2, 2], [1223.5, 1023.5], atol=0.01 * 2448)
        assert abs(camera.matrix[1, 1] / camera.matrix[0, 0] - 1) <= 1e-3
        np.testing.assert_array_equal(camera.distortions, 0.0)


def test_options_are_honoured():
    rig = cage_rig(3, focal_px=3000.0, resolution=(1280, 1024), distortion_scale=0.1, seed=5)
    assert [camera.matrix[0, 0] for camera in rig] == [3000.0] * 3
    assert all(camera.size == (1280, 1024) for camera in rig)
    distortions = np.stack([camera.distortions for camera in rig])
    assert (np.abs(distortions) <= 0.1 * np.array([1.0, 0.5, 0.05, 0.05, 0.1])).all()
    assert np.abs(distortions[:, 0]).max() > 0.01
    assert rig.names == ("cam_0", "cam_1", "cam_2")


def test_same_seed_same_bytes_and_smaller_rigs_are_prefixes(tmp_path):
    cage_rig(seed=3).save(tmp_path / "a.toml")
    cage_rig(seed=3).save(tmp_path / "b.toml")
    cage_rig(seed=4).save(tmp_path / "c.toml")
    assert (tmp_path / "a.toml").read_bytes() == (tmp_path / "b.toml").read_bytes()
    assert (tmp_path / "a.toml").read_bytes() != (tmp_path / "c.toml").read_bytes()
    assert list(cage_rig(5, seed=3)) == list(cage_rig(seed=3))[:5]


@pytest.mark.parametrize("kwargs, match", [
    ({"n_cameras": 0}, f"n_cameras must be between 1 and {MAX_CAMERAS}, got 0"),
    ({"n_cameras": MAX_CAMERAS + 1}, "n_cameras must be between 1 and"),
    ({"n_cameras": 2.5}, "n_cameras must be a whole number"),
    ({"n_cameras": True}, "n_cameras must be a whole number"),
    ({"cage_size": (2.0, -1.0, 2.0)}, "cage_size must be positive"),
    ({"cage_size": (2.0, 1.0)}, "cage_size must be three finite numbers"),
    ({"target": (0.0, 0.7, 1.0)}, r"target \[0.0, 0.7, 1.0\] must lie inside the cage \[-1, 1\] x \[-0.5, 0.5\]"),
    ({"target": (0.0, 0.0, np.nan)}, "target must be three finite numbers"),
    ({"target": (0.95, 0.45, 1.6)}, "camera cam_0 is 0.0.. m from the target, too close"),
    ({"resolution": (2448,)}, "resolution must be two whole numbers"),
    ({"resolution": (2448.0, 2048)}, "resolution must be two whole numbers"),
    ({"resolution": (2448, -1)}, "resolution must be positive pixels"),
    ({"focal_px": 0.0}, "focal_px must be a positive finite number"),
    ({"focal_px": "long"}, "focal_px must be a number"),
    ({"distortion_scale": -0.1}, "distortion_scale must be a finite number >= 0"),
    ({"distortion_scale": np.inf}, "distortion_scale must be a finite number >= 0"),
    ({"distortion_scale": "small"}, "distortion_scale must be a finite number >= 0"),
])
def test_rejects_bad_arguments(kwargs, match):
    with pytest.raises(HandcapError, match=match):
        cage_rig(**kwargs)


def test_region_rig_sees_the_points_at_the_same_pixels_less_its_window():
    from handcap.synth.filming import region_rig

    rig = cage_rig(6, seed=2)
    points = np.random.default_rng(0).normal([0.0, 0.0, 1.0], 0.05, (50, 3))
    cut = region_rig(rig, points, margin=20)
    for full, window in zip(rig, cut):
        a, _ = full.project(points)
        b, _ = window.project(points)
        shift = a - b
        assert np.allclose(shift, shift[0], atol=1e-9) and np.allclose(shift[0], 2 * np.round(shift[0] / 2))
        assert (b >= 20 - 1e-6).all() and (b <= np.array(window.size) - 20 + 2).all()
        assert window.size[0] < full.size[0] and window.size[1] < full.size[1]
