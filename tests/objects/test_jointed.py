"""Objects with revolute joints tracked from their description alone: a two-part hinge and a three-part
chain, against synthetic takes with known pose and angles."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from handcap import HandcapError
from handcap.core.transforms import homogeneous
from handcap.objects import articulated_from_table
from handcap.objects.jointed import joint_order, part_markers, pose_parts, track_jointed

HINGE_TOML = """
name = "hinge"
units = "mm"

[[parts]]
name = "base"
markers = { b1 = [0, 0, 0], b2 = [60, 0, 0], b3 = [0, 40, 5], b4 = [55, 35, 0] }

[[parts]]
name = "lid"
markers = { l1 = [5, 0, 30], l2 = [60, -5, 30], l3 = [0, -40, 35] }

[[joints]]
type = "revolute"
parent = "base"
child = "lid"
axis = [1, 0, 0]
origin = [0, 0, 15]
limits_deg = [-5, 185]
"""


def _take(obj, n, rng, angles, noise=0.0005, hide=0.1):
    t = np.arange(n) / 100.0
    turn = Rotation.from_rotvec(0.4 * np.sin(2 * np.pi * np.outer(t, [0.3, 0.2, 0.25]))) * Rotation.random(
        random_state=int(rng.integers(1 << 30)))
    pose = homogeneous(turn.as_matrix(), np.array([0.0, 0.0, 1.0]) + 0.05 * np.sin(np.outer(t, [1.0, 0.7, 0.5])))
    markers = part_markers(obj, pose_parts(obj, pose, angles)) + rng.normal(0, noise, (n, len(obj.marker_names), 3))
    markers[rng.random(markers.shape[:2]) < hide] = np.nan
    return markers, pose


@pytest.fixture(scope="module")
def hinge(tmp_path_factory):
    import tomllib
    return articulated_from_table(tomllib.loads(HINGE_TOML), "hinge.toml")


def test_hinge_angle_and_pose_from_its_toml_alone(hinge):
    rng = np.random.default_rng(0)
    n = 400
    truth = np.deg2rad(90 + 85 * np.sin(np.linspace(0, 3 * np.pi, n)))[:, None]  # 5 to 175 degrees
    markers, pose = _take(hinge, n, rng, truth)
    track = track_jointed(markers, hinge)
    ok = np.isfinite(track.angles[:, 0])
    assert ok.mean() > 0.97 and track.joint_names == ("lid",)
    error = np.rad2deg(np.abs(track.angles[ok, 0] - truth[ok, 0]))
    # the lid's three markers sit 30-40 mm from the axis: 0.5 mm of noise is about a degree
    assert np.median(error) < 1.0 and np.percentile(error, 99) < 3.5
    found = np.isfinite(track.translation[:, 0])
    assert np.linalg.norm(track.translation[found] - pose[found, :3, 3], axis=1).max() < 0.002
    rot = Rotation.from_rotvec(track.rotation[found]).inv() * Rotation.from_matrix(pose[found, :3, :3])
    assert np.median(np.rad2deg(rot.magnitude())) < 1.0
    assert np.nanmedian(track.rms) < 0.0012
    assert [w.split(":")[1].split(" (")[0] for w in track.warnings] == [f" no pose in {(~ok).sum()} of 400 frames"]


def test_one_marker_of_the_lid_still_gives_its_angle(hinge):
    rng = np.random.default_rng(1)
    truth = np.full((50, 1), np.deg2rad(40.0))
    markers, _ = _take(hinge, 50, rng, truth, noise=0.0, hide=0.0)
    markers[:, 5:] = np.nan  # only l1 left
    assert np.allclose(track_jointed(markers, hinge).angles[:, 0], truth[:, 0], atol=1e-6)


def test_limits_and_a_missing_joint_are_warned(hinge):
    rng = np.random.default_rng(2)
    truth = np.full((60, 1), np.deg2rad(230.0))  # past the 185-degree limit
    markers, _ = _take(hinge, 60, rng, truth, hide=0.0)
    warnings = " ".join(track_jointed(markers, hinge).warnings)
    assert "leaves its limits" in warnings
    bent = markers.copy()
    bent[:, 6] += 0.02  # a lid marker that does not move with the lid
    assert "from the fitted object" in " ".join(track_jointed(bent, hinge).warnings)


def test_a_chain_of_three_parts_and_bad_descriptions():
    table = {"name": "arm", "parts": [
        {"name": "a", "markers": {"a1": [0, 0, 0], "a2": [0.05, 0, 0], "a3": [0, 0.03, 0.01]}},
        {"name": "b", "markers": {"b1": [0.1, 0, 0], "b2": [0.15, 0.01, 0], "b3": [0.12, 0.03, 0]}},
        {"name": "c", "markers": {"c1": [0.2, 0, 0], "c2": [0.25, 0, 0.01], "c3": [0.22, -0.03, 0]}}],
        "joints": [{"type": "revolute", "parent": "b", "child": "c", "axis": [0, 0, 1], "origin": [0.18, 0, 0]},
                   {"type": "revolute", "parent": "a", "child": "b", "axis": [0, 1, 0], "origin": [0.08, 0, 0]}]}
    arm = articulated_from_table(table)
    assert joint_order(arm)[0] == "a" and [j.child for j in joint_order(arm)[1]] == ["b", "c"]
    rng = np.random.default_rng(3)
    truth = np.stack([np.linspace(-0.5, 0.5, 200), np.linspace(1.0, -1.0, 200)], axis=1)
    markers, _ = _take(arm, 200, rng, truth, noise=0.0003, hide=0.05)
    track = track_jointed(markers, arm)
    assert track.joint_names == ("c", "b")
    ok = np.isfinite(track.angles).all(axis=1)
    assert np.rad2deg(np.abs(track.angles[ok] - truth[ok])).max() < 3.0
    loop = dict(table, joints=table["joints"] + [{"type": "revolute", "parent": "c", "child": "a", "axis": [1, 0, 0]}])
    with pytest.raises(HandcapError, match="one root part"):
        joint_order(articulated_from_table(loop))
    with pytest.raises(HandcapError, match="never shows 3 markers"):
        track_jointed(np.full((5, 9, 3), np.nan), arm)
    with pytest.raises(HandcapError, match="must be"):
        track_jointed(np.zeros((5, 4, 3)), arm)


def test_track_object_verb_with_a_users_hinge(tmp_path, hinge, capsys):
    from handcap.cli import main
    from handcap.core.markers import MarkerSequence
    from handcap.io import read_object_motion, write_markers

    (tmp_path / "hinge.toml").write_text(HINGE_TOML)
    rng = np.random.default_rng(5)
    truth = np.deg2rad(np.linspace(10, 120, 150))[:, None]
    markers, pose = _take(hinge, 150, rng, truth, hide=0.05)
    write_markers(MarkerSequence(markers, hinge.marker_names, 100.0), tmp_path / "take.c3d")
    before = (tmp_path / "hinge.toml").read_bytes()
    assert main(["track-object", str(tmp_path / "take.c3d"), "--articulated", str(tmp_path / "hinge.toml"),
                 "--out", str(tmp_path / "hinge.npz")]) == 0
    assert "joints lid" in capsys.readouterr().out
    assert (tmp_path / "hinge.toml").read_bytes() == before
    with np.load(tmp_path / "hinge.npz") as data:
        angles = data["state_joint_angles"][:, 0]
        assert [str(j) for j in data["joints"]] == ["lid"] and data["fit_rms"].shape == (150,)
    ok = np.isfinite(angles)
    error = np.rad2deg(np.abs(angles[ok] - truth[ok, 0]))
    assert ok.mean() > 0.95 and np.median(error) < 1.0 and error.max() < 6.0
    motion = read_object_motion(tmp_path / "hinge.npz")
    assert np.nanmax(np.linalg.norm(motion.translation - pose[:, :3, 3], axis=1)) < 0.003
    # the description given as the output, or a take without its markers: one line, exit 2
    assert main(["track-object", str(tmp_path / "take.c3d"), "--articulated", str(tmp_path / "hinge.toml"),
                 "--out", str(tmp_path / "hinge.toml")]) == 2
    write_markers(MarkerSequence(markers[:, :4], hinge.marker_names[:4], 100.0), tmp_path / "base.c3d")
    assert main(["track-object", str(tmp_path / "base.c3d"), "--articulated", str(tmp_path / "hinge.toml"),
                 "--out", str(tmp_path / "x.npz")]) == 2
    assert "lacks 3 of the hinge markers" in capsys.readouterr().err
    assert (tmp_path / "hinge.toml").read_bytes() == before
