"""Synthetic captures: files, ground truth consistency, occlusion, determinism."""

import numpy as np
import pytest
import trimesh
from scipy.spatial.transform import Rotation

from handcap import HandcapError
from handcap.cli import main
from handcap.core.geometry import closest_points_on_mesh
from handcap.hand import OpenHand
from handcap.hand.anatomy import PHI_LIMITS
from handcap.io import read_hand_motion, read_markers, read_points
from handcap.synth.objects import make_object
from handcap.layouts import MARKER_GAP, load_layout
from handcap.synth.scene import SynthConfig, misplaced, synthesize, write_capture

FILES = ("markers.c3d", "markers.npz", "points.npz", "detections.npz", "cameras.toml", "truth.npz", "scene.toml")


@pytest.fixture(scope="module")
def grasp(tmp_path_factory):
    config = SynthConfig(layout="glove-13", motion="grasp", frames=300, seed=3)
    folder = tmp_path_factory.mktemp("grasp")
    capture = synthesize(config)
    write_capture(capture, folder)
    return config, capture, folder


def _truth(folder):
    with np.load(folder / "truth.npz") as data:
        return {k: data[k] for k in data.files}


def test_folder_has_every_file_and_they_read_back(grasp):
    config, capture, folder = grasp
    for name in FILES:
        assert (folder / name).is_file(), name
    markers = read_markers(folder / "markers.c3d")
    assert markers.n_frames == 300 and markers.rate == 100.0
    np.testing.assert_allclose(markers.positions, read_markers(folder / "markers.npz").positions, atol=2e-6,
                               equal_nan=True)
    motion = read_hand_motion(folder / "truth.npz")
    assert motion.joints.shape == (300, 21, 3) and motion.marker_fit.shape == (300, 13, 3)
    points = read_points(folder / "points.npz")
    np.testing.assert_array_equal(points.counts, (~markers.missing).sum(axis=1))


def _surface_markers(truth, hand):
    """Marker positions rebuilt from truth.npz alone: barycentric point plus offset along the face normal."""
    out = hand.forward(truth["betas"], truth["global_orient"], truth["hand_pose"], truth["transl"])
    tri = out.vertices[:, hand.faces[truth["attachment_triangles"]]]  # (T, M, 3, 3)
    on_skin = np.einsum("mk,tmki->tmi", truth["attachment_barycentric"], tri)
    normal = np.cross(tri[:, :, 1] - tri[:, :, 0], tri[:, :, 2] - tri[:, :, 0])
    normal /= np.linalg.norm(normal, axis=2, keepdims=True)
    return on_skin + truth["attachment_offset"][:, None] * normal, on_skin, out.vertices


def test_markers_lie_on_the_hand_surface_within_the_noise(grasp):
    config, capture, folder = grasp
    truth = _truth(folder)
    hand = OpenHand(str(truth["side"]))
    names = list(truth["names"][:13])
    markers = read_markers(folder / "markers.c3d").select(names)
    expected, on_skin, vertices = _surface_markers(truth, hand)
    observed = markers.positions.copy()
    for start, stop, a, b in truth["swaps"]:  # a swapped label is a known fault, not noise
        if a < 13 and b < 13:
            observed[start:stop, [a, b]] = np.nan
    err = np.linalg.norm(observed - expected, axis=2)
    err = err[~np.isnan(err)]
    sigma = config.noise_mm / 1000
    # 3D Gaussian jitter: RMS distance is sqrt(3) sigma; C3D stores float32 millimetres.
    assert np.sqrt(np.mean(err**2)) == pytest.approx(np.sqrt(3) * sigma, rel=0.15)
    assert err.max() < 6 * sigma
    # And the noise-free markers sit one marker radius off the skin.
    t = 150
    closest, _, _ = closest_points_on_mesh(expected[t], vertices[t], hand.faces, candidates=64)
    dist = np.linalg.norm(expected[t] - closest, axis=1)
    assert np.all(np.abs(dist - 0.007) < 0.0015), dist


def test_fingers_behind_the_object_are_hidden(grasp):
    """Independent ray test against the object alone: every blocked line must be unseen."""
    config, capture, folder = grasp
    truth = _truth(folder)
    obj = make_object("cylinder", seed=config.seed)
    blocked_total = 0
    for t in range(0, 300, 12):
        rot = Rotation.from_rotvec(truth["object_rotation"][t]).as_matrix()
        mesh = trimesh.Trimesh(obj.vertices @ rot.T + truth["object_translation"][t], obj.faces, process=False)
        for c, camera in enumerate(capture.rig):
            targets = truth["positions"][t, :13]
            direction = targets - camera.center
            dist = np.linalg.norm(direction, axis=1)
            hits, ray, _ = mesh.ray.intersects_location(np.repeat(camera.center[None], 13, 0),
                                                        direction / dist[:, None])
            blocked = np.zeros(13, bool)
            for r, h in zip(ray, hits):
                if np.linalg.norm(h - camera.center) < dist[r] - 1e-3:
                    blocked[r] = True
            assert not (blocked & truth["camera_visible"][t, c, :13]).any()
            blocked_total += blocked.sum()
    assert blocked_total > 20  # the object does hide fingers in a grasp
    # Some cameras lose the finger markers while the hand holds the object.
    holding = truth["object_holding"].astype(bool)
    assert (~truth["camera_visible"][holding, :, :13]).mean() > 0.1


def test_same_seed_same_bytes_other_seed_other_bytes(grasp, tmp_path):
    config, _, folder = grasp
    write_capture(synthesize(config), tmp_path / "again")
    for name in FILES:
        assert (folder / name).read_bytes() == (tmp_path / "again" / name).read_bytes(), name
    from dataclasses import replace
    small = SynthConfig(layout="tips-5", motion="open-close", frames=30, seed=3)
    assert not np.array_equal(synthesize(replace(small, seed=4)).hand_motion.phi, synthesize(small).hand_motion.phi)


@pytest.mark.parametrize("layout, motion", [
    ("dense-patches", "rotate-cube"), ("joints-19", "pinch"), ("tips-5", "tapping"), ("active-9", "wrist"),
    ("glove-13", "open-close"), ("glove-13", "precision"), ("joints-19", "random"),
])
def test_every_layout_and_motion_make_a_capture(tmp_path, layout, motion):
    rate = 20.0 if motion in ("rotate-cube", "precision") else 100.0  # object motions need 2.5 s or more
    config = SynthConfig(layout=layout, motion=motion, frames=60 if rate == 20 else 40, rate=rate, seed=1,
                         side="left" if motion == "wrist" else "right")
    capture = synthesize(config)
    paths = write_capture(capture, tmp_path)
    assert all(p.is_file() for p in paths.values())
    phi = capture.hand_motion.phi
    assert (phi >= PHI_LIMITS[:, 0] - 1e-9).all() and (phi <= PHI_LIMITS[:, 1] + 1e-9).all()
    # Smooth: no joint turns faster than 20 rad/s, the wrist moves slower than 3 m/s.
    assert np.abs(np.diff(phi, axis=0)).max() * config.rate < 20
    assert np.linalg.norm(np.diff(capture.hand_motion.transl, axis=0), axis=1).max() * config.rate < 3
    assert 0.2 < capture.truth["visible"].mean() <= 1.0


@pytest.mark.parametrize("name", ["joints-19", "glove-13"])
def test_misplaced_spheres_never_touch(name):
    """Placement moves each sphere on its own (3 mm sd here, 8 mm: far more than a lab's); none comes nearer
    another than their two radii plus MARKER_GAP, or than the layout's own distance where that is less."""
    layout, hand = load_layout(name), OpenHand()
    nominal = layout.positions()
    floor = np.minimum(2 * layout.marker_radius + MARKER_GAP,
                       np.linalg.norm(nominal[:, None] - nominal[None], axis=-1))
    moved_most, skin = 0.0, hand.forward().vertices
    for seed in range(12):
        placed = misplaced(layout, hand, 0.008, np.random.default_rng(seed)).positions()
        dist = np.linalg.norm(placed[:, None] - placed[None], axis=-1)
        np.fill_diagonal(dist, np.inf)
        assert (dist >= floor - 1e-9).all()
        moved_most = max(moved_most, np.linalg.norm(placed - nominal, axis=1).max())
        on_skin = np.linalg.norm(closest_points_on_mesh(placed, skin, hand.faces)[0] - placed, axis=1)
        assert on_skin.max() < 1e-6
    assert moved_most > 0.01  # the markers did move


def test_clean_capture_equals_truth_where_seen():
    config = SynthConfig(layout="tips-5", motion="open-close", frames=50, noise_mm=0, dropout=0, ghost_rate=0,
                         swap_rate=0, pixel_noise=0)
    capture = synthesize(config)
    seen = capture.truth["visible"]
    np.testing.assert_array_equal(~capture.markers.missing, seen)
    np.testing.assert_allclose(capture.markers.positions[seen], capture.truth["positions"][seen])
    det = capture.detections
    for c, camera in enumerate(capture.rig):
        rows = det["camera"] == c
        pixels, _ = camera.project(capture.truth["positions"][det["frame"][rows], det["marker"][rows]])
        np.testing.assert_allclose(det["xy"][rows], pixels, atol=1e-9)


def test_faults_happen_at_their_rates():
    config = SynthConfig(layout="glove-13", motion="random", frames=1000, rate=100, ghost_rate=5, swap_rate=1,
                         dropout=0.05, outlier_rate=0.1, seed=2, cameras=3)
    capture = synthesize(config)
    truth = capture.truth
    assert len(truth["ghosts"]) == pytest.approx(50, abs=22)  # Poisson, 5 per second for 10 s
    assert 3 <= len(truth["swaps"]) <= 20
    assert truth["dropped"].mean() == pytest.approx(0.05, abs=0.02)
    assert capture.detections["wrong_id"].mean() == pytest.approx(0.1, abs=0.01)
    ghosts = capture.markers.positions[:, len(truth["names"]):]
    # Ghosts appear near real markers (5-25 mm away).
    g_t, g_m = np.nonzero(~np.isnan(ghosts[..., 0]))
    d = np.nanmin(np.linalg.norm(truth["positions"][g_t] - ghosts[g_t, g_m][:, None], axis=2), axis=1)
    assert np.median(d) < 0.03


@pytest.mark.parametrize("kwargs, message", [
    ({"motion": "juggle"}, "unknown motion"),
    ({"frames": 1}, "frames must be"),
    ({"min_views": 13, "cameras": 12}, "min_views"),
    ({"object": "banana"}, "unknown object"),
    ({"motion": "grasp", "object": "none"}, "needs an object"),
    ({"dropout": 1.5}, "dropout"),
    ({"betas": (0.0,) * 9}, "betas must be 10"),
    ({"side": "both"}, "side must be"),
])
def test_bad_settings(kwargs, message):
    with pytest.raises(HandcapError, match=message):
        SynthConfig(**kwargs)


def test_object_motions_need_time():
    with pytest.raises(HandcapError, match="needs at least 2.5 s"):
        synthesize(SynthConfig(motion="grasp", frames=100, rate=100))


def test_cli_synth_and_bad_input(tmp_path, capsys):
    out = tmp_path / "cap"
    assert main(["synth", "--layout", "tips-5", "--motion", "tapping", "--frames", "30", "--seed", "5",
                 "--out", str(out)]) == 0
    assert (out / "markers.c3d").is_file()
    assert main(["synth", "--scene", str(out / "scene.toml"), "--out", str(tmp_path / "again")]) == 0
    assert (out / "markers.c3d").read_bytes() == (tmp_path / "again" / "markers.c3d").read_bytes()
    capsys.readouterr()
    assert main(["synth", "--layout", "glove-14", "--out", str(tmp_path / "x")]) == 2
    err = capsys.readouterr().err
    assert "unknown layout" in err and len(err.strip().splitlines()) == 1
    assert main(["synth", "--frames", "5", "--min-views", "20", "--out", str(tmp_path / "y")]) == 2
