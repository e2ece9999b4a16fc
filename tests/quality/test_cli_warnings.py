"""The writing verbs print, store and (with --strict) fail on the warnings of an implausible result.

Each test feeds a verb a deliberately implausible input and checks: the warning line on stderr, the
warning stored in the output (read back), exit code 0 without ``--strict`` and 2 with it, and the output
written either way (issue 14: never a silent wrong result).
"""

import hashlib
import json

import numpy as np
import pytest

from handcap.cli import main
from handcap.core.markers import MarkerSequence
from handcap.core.motion import HandMotion
from handcap.io import load_npz, read_hand_motion, read_markers, read_object_motion, write_hand_motion, write_markers
from handcap.synth.scene import SynthConfig, synthesize


@pytest.fixture(scope="module")
def capture():
    return synthesize(SynthConfig(layout="glove-13", motion="open-close", frames=120, rate=60, seed=5,
                                  noise_mm=0.5, object="none", swap_rate=0.0))


def _digest(path):
    return hashlib.sha256(path.read_bytes()).hexdigest()


def _warning_lines(capsys, verb):
    err = capsys.readouterr().err
    lines = [line for line in err.splitlines() if line]
    assert all(line.startswith(f"handcap {verb}: ") for line in lines), err
    return [line.removeprefix(f"handcap {verb}: warning: ") for line in lines if ": warning: " in line], err


def _run_both(argv, out, capsys, verb):
    """Run without and with --strict (same output path); return the warning lines of the first run."""
    assert main(argv) == 0
    lines, _ = _warning_lines(capsys, verb)
    assert out.exists()
    first = out.stat().st_mtime_ns
    out.unlink()
    assert main(["--strict", *argv]) == 2
    strict_lines, err = _warning_lines(capsys, verb)
    assert strict_lines == lines and f"handcap {verb}: error: {len(lines)} warning(s) and --strict given" in err
    assert out.exists() and first
    return lines


def test_convert_reports_a_marker_jumping_half_a_metre(capture, tmp_path, capsys):
    m = capture.markers
    positions = m.positions.copy()
    i = m.index("index_tip")
    seen = np.flatnonzero(~np.isnan(positions[:, i, 0]))
    frame = seen[(seen > 0) & np.isin(seen - 1, seen) & np.isin(seen + 1, seen)][20]
    positions[frame, i] += [0.5, 0.0, 0.0]  # a label swap with a ghost half a metre away, for one frame
    source = tmp_path / "take.npz"
    write_markers(MarkerSequence(positions, m.names, m.rate), source)
    before = _digest(source)
    out = tmp_path / "converted.npz"
    lines = _run_both(["convert", str(source), str(out)], out, capsys, "convert")
    assert len(lines) == 1 and "move faster than 10 m/s" in lines[0] and "index_tip" in lines[0]
    assert read_markers(out).warnings == tuple(lines)
    assert _digest(source) == before
    # A plausible take: no warning, exit 0 even with --strict.
    write_markers(m, tmp_path / "plain.npz")
    assert main(["--strict", "convert", str(tmp_path / "plain.npz"), str(tmp_path / "plain.c3d")]) == 0
    lines, _ = _warning_lines(capsys, "convert")
    assert lines == [] and read_markers(tmp_path / "plain.c3d").warnings == ()


def test_metrics_shows_the_stored_warnings_and_its_own(capture, tmp_path, capsys):
    truth = capture.hand_motion
    joints = truth.joints.copy()
    joints[60, 17] += [0.0, 0.03, 0.0]  # the index tip jumps 3 cm for one frame
    betas = truth.betas.copy()
    betas[3] = 3.0
    stored = "solve MRE 13.00 mm is above 5 mm (plausible: <= 5 mm); a line stored by the solve"
    motion = HandMotion(betas, truth.global_orient, truth.hand_pose, truth.transl, truth.rate, truth.side,
                        truth.phi, joints=joints, warnings=(stored,))
    path = tmp_path / "motion.npz"
    write_hand_motion(motion, path)
    before = _digest(path)
    out = tmp_path / "metrics.json"
    lines = _run_both(["metrics", str(path), "--out", str(out)], out, capsys, "metrics")
    assert lines[0] == stored
    assert any(line.startswith("shape value(s)") and "betas[3] = 3.00" in line for line in lines)
    assert any(line.startswith("joint jerk spikes") for line in lines)
    assert json.loads(out.read_text())["warnings"] == lines
    assert _digest(path) == before


def test_shape_from_a_giant_hand_stores_its_warning(tmp_path, capsys):
    out = tmp_path / "betas.npz"
    lines = _run_both(["shape", "--lengths", "hand_length=400", "--out", str(out)], out, capsys, "shape")
    assert len(lines) == 1 and lines[0].startswith("shape value(s) at or beyond")
    assert [str(w) for w in load_npz(out)["warnings"]] == lines


def test_track_object_reports_a_deformed_object(tmp_path, capsys):
    from scipy.spatial.transform import Rotation
    rng = np.random.default_rng(0)
    canonical = np.array([[0.0, 0, 0], [0.08, 0, 0], [0, 0.06, 0], [0, 0, 0.05]])
    rot = Rotation.from_rotvec(np.linspace(0, 1, 80)[:, None] * [0.3, 1.0, -0.2]).as_matrix()
    positions = np.einsum("tij,mj->tmi", rot, 1.06 * canonical) + np.linspace([0, 0, 1], [0.2, 0.1, 1.1], 80)[:, None]
    source = tmp_path / "box.npz"
    write_markers(MarkerSequence(positions + rng.normal(0, 3e-4, positions.shape), [f"box:{i}" for i in range(4)],
                                 100.0), source)
    from handcap.io import save_npz
    save_npz(tmp_path / "canonical.npz", {"canonical": canonical})  # the object as designed, 6 % smaller
    out = tmp_path / "box_motion.npz"
    lines = _run_both(["track-object", str(source), "--markers", "box:*",
                       "--canonical", str(tmp_path / "canonical.npz"), "--name", "box", "--out", str(out)],
                      out, capsys, "track-object")
    assert len(lines) == 1 and "object 'box': mean residual" in lines[0]
    assert read_object_motion(out).warnings == tuple(lines)


def test_synth_with_an_outsized_subject_stores_the_warning_in_its_files(tmp_path, capsys):
    folder = tmp_path / "capture"
    argv = ["synth", "--motion", "open-close", "--frames", "40", "--rate", "30", "--cameras", "6",
            "--betas", "0,0,4,0,0,0,0,0,0,0", "--out", str(folder)]
    assert main(argv) == 0
    lines, _ = _warning_lines(capsys, "synth")
    assert len(lines) == 1 and "betas[2] = 4.00" in lines[0]
    assert read_markers(folder / "markers.npz").warnings == tuple(lines)
    assert read_markers(folder / "markers.c3d").warnings == tuple(lines)
    assert read_hand_motion(folder / "truth.npz").warnings == tuple(lines)
    assert main(["--strict", *argv[:-1], str(tmp_path / "again")]) == 2
    assert (tmp_path / "again" / "markers.npz").exists()


def test_triangulate_with_moved_cameras_stores_the_warning(capture, tmp_path, capsys):
    from handcap.core.cameras import Camera, CameraRig
    from handcap.io import save_npz
    save_npz(tmp_path / "detections.npz", capture.detections)
    moved = CameraRig([Camera(c.name, c.size, c.matrix, c.distortions, c.rotation,
                              c.translation + [0.03 * (i % 2), 0, 0]) for i, c in enumerate(capture.rig)])
    moved.save(tmp_path / "cameras.toml")
    out = tmp_path / "markers.npz"
    lines = _run_both(["triangulate", str(tmp_path / "detections.npz"), "--cameras", str(tmp_path / "cameras.toml"),
                       "--workers", "1", "--out", str(out)], out, capsys, "triangulate")
    assert any("of the detections were rejected" in line for line in lines)
    assert read_markers(out).warnings == tuple(lines)


def test_camera_files_keep_their_warnings(capture, tmp_path):
    from handcap.io.cameras import read_cameras_toml, read_cameras_warnings, write_cameras_toml
    write_cameras_toml(capture.rig, tmp_path / "rig.toml", warnings=["reprojection RMS above 1 px"])
    assert read_cameras_warnings(tmp_path / "rig.toml") == ("reprojection RMS above 1 px",)
    assert read_cameras_toml(tmp_path / "rig.toml") == capture.rig
    capture.rig.save(tmp_path / "plain.toml")
    assert read_cameras_warnings(tmp_path / "plain.toml") == ()


def test_a_rig_keeps_its_warnings_through_its_file(capture, tmp_path):
    from handcap.io.cameras import read_cameras_toml, read_cameras_warnings
    rig = capture.rig.with_warnings("reprojection RMS above 1 px (plausible: <= 1 px) for cam_2 (1.8 px)")
    rig.save(tmp_path / "rig.toml")
    assert read_cameras_toml(tmp_path / "rig.toml").warnings == rig.warnings
    assert read_cameras_warnings(tmp_path / "rig.toml") == rig.warnings
