"""The command line of the solve stage: a small session end to end, and bad input exits 2."""

import json

import numpy as np
import pytest

from handcap.cli import main
from handcap.io import read_hand_motion, read_object_motion


@pytest.fixture(scope="module")
def session(tmp_path_factory):
    root = tmp_path_factory.mktemp("session")
    assert main(["synth", "--layout", "tips-5", "--motion", "calibration", "--frames", "60", "--seed", "1",
                 "--subject-seed", "3", "--out", str(root / "cal")]) == 0
    assert main(["synth", "--layout", "tips-5", "--motion", "precision", "--frames", "60", "--rate", "20",
                 "--seed", "2", "--subject-seed", "3", "--out", str(root / "take")]) == 0
    return root


def test_calibrate_solve_metrics(session, capsys):
    att, motion, metrics = session / "att.npz", session / "motion.npz", session / "metrics.json"
    assert main(["calibrate-markers", str(session / "cal" / "markers.c3d"), "--layout", "tips-5",
                 "--fit-shape", "--out", str(att)]) == 0
    assert main(["solve", str(session / "take" / "markers.c3d"), "--attachment", str(att),
                 "--filter-cutoff", "5", "--out", str(motion)]) == 0
    solved = read_hand_motion(motion)
    assert solved.n_frames == 60 and solved.marker_residuals.shape == (60, 8)
    assert main(["metrics", str(motion), "--truth", str(session / "take" / "truth.npz"),
                 "--markers", str(session / "take" / "markers.c3d"), "--out", str(metrics)]) == 0
    out = capsys.readouterr().out
    assert "joint error (mm)" in out and "MSNR" in out
    values = json.loads(metrics.read_text())
    assert values["joint_error_mm"][0] < 15 and values["mre_mm"][0] < 5


def test_a_take_of_left_prefixed_markers_is_calibrated_on_the_left_hand(tmp_path, capsys):
    """detect names a left hand's corners ``left:PATCH_rRcC``: calibrate-markers takes that hand without --side (it
    took the layout's, the right, and fitted the left hand's markers to the mirror-image hand)."""
    from dataclasses import replace

    from handcap.hand.attachment import MarkerAttachment
    from handcap.io import read_markers, write_markers

    assert main(["synth", "--layout", "tips-5", "--side", "left", "--motion", "calibration", "--frames", "60",
                 "--seed", "1", "--out", str(tmp_path / "cal")]) == 0
    markers = read_markers(tmp_path / "cal" / "markers.c3d")
    left = replace(markers, names=tuple(f"left:{n}" for n in markers.names))
    write_markers(left, tmp_path / "left.npz")
    mre = {}
    for name, extra in (("named", []), ("right", ["--side", "right"])):
        out = tmp_path / f"{name}.npz"
        capsys.readouterr()
        assert main(["calibrate-markers", str(tmp_path / "left.npz"), "--layout", "tips-5", "--out", str(out),
                     *extra]) == 0
        said = capsys.readouterr()
        mre[name] = float(said.out.split("calibration MRE ")[1].split(" mm")[0])
        assert MarkerAttachment.load(out).side == ("left" if name == "named" else "right")
        assert ("but the markers are named left" in said.err) == (name == "right")
    assert mre["named"] < 1.0 < mre["right"], mre  # the mirror-image hand fits the left hand's markers badly
    both = replace(markers, names=tuple(f"{'left' if k % 2 else 'right'}:{n}" for k, n in enumerate(markers.names)))
    write_markers(both, tmp_path / "both.npz")
    capsys.readouterr()
    assert main(["calibrate-markers", str(tmp_path / "both.npz"), "--layout", "tips-5", "--out",
                 str(tmp_path / "both_att.npz")]) == 2
    assert "both hands" in capsys.readouterr().err and not (tmp_path / "both_att.npz").exists()


def test_metrics_of_a_take_too_short_for_smoothness(session, tmp_path):
    # 3 frames: joint error against the truth, but no MSNR or jerk (a third difference needs 4 frames).
    from dataclasses import replace

    from handcap.io import write_hand_motion
    from handcap.report.metrics import motion_metrics

    truth = read_hand_motion(session / "take" / "truth.npz")
    short = truth.frames(0, 3)
    write_hand_motion(short, tmp_path / "short.npz")
    offset = np.array([0.003, 0.0, 0.004])
    moved = replace(short, transl=short.transl + offset, joints=short.joints + offset)
    write_hand_motion(moved, tmp_path / "moved.npz")
    figures = motion_metrics(tmp_path / "moved.npz", truth=tmp_path / "short.npz")
    assert figures["frames"] == 3 and abs(figures["joint_error_mm"][0] - 5.0) < 1e-6
    assert "msnr_db" not in figures and "jerk_m_s3" not in figures


def test_track_object_from_the_synthetic_object_markers(session, capsys):
    out = session / "object.npz"
    assert main(["track-object", str(session / "take" / "markers.npz"), "--markers", "sphere_*",
                 "--name", "ball", "--out", str(out)]) == 0
    motion = read_object_motion(out)
    truth = np.load(session / "take" / "truth.npz")
    seen = np.isfinite(motion.translation[:, 0])
    # The estimated body frame is centred on the markers' mean; the sphere's markers surround its centre.
    err = np.linalg.norm(motion.translation[seen] - truth["object_translation"][seen], axis=1)
    assert np.median(err) < 0.01
    assert "mean residual" in capsys.readouterr().out


def test_shape_from_lengths(tmp_path, capsys):
    assert main(["shape", "--lengths", "hand_length=195,hand_breadth=88", "--out", str(tmp_path / "b.npz")]) == 0
    assert np.load(tmp_path / "b.npz")["betas"][0] > 0.5


@pytest.mark.parametrize("argv, message", [
    (["solve", "MISSING.c3d", "--attachment", "a.npz", "--out", "m.npz"], "no such file"),
    (["calibrate-markers", "{take}/markers.c3d", "--layout", "nope", "--out", "a.npz"], "unknown layout"),
    (["calibrate-markers", "{take}/markers.c3d", "--layout", "glove-13", "--out", "a.npz"], "absent from"),
    (["calibrate-markers", "{take}/markers.c3d", "--layout", "tips-5", "--frames", "x", "--out", "a.npz"], "--frames"),
    (["track-object", "{take}/markers.c3d", "--markers", "thumb_tip,index_tip", "--out", "o.npz"], "at least 3"),
    (["track-object", "{take}/markers.c3d", "--markers", "cube_*", "--out", "o.npz"], "no marker matches"),
    (["solve", "{take}/markers.c3d", "--attachment", "{take}/truth.npz", "--out", "m.npz"], "attachment"),
    (["solve", "{take}/markers.c3d", "--attachment", "{take}/truth.npz", "--out", "{take}/markers.c3d"],
     "overwrite the input"),
    (["shape", "--lengths", "hand_length=big", "--out", "b.npz"], "--lengths"),
    (["metrics", "{take}/markers.npz"], "not a hand-motion"),
])
def test_bad_input_exits_2_with_one_line(session, tmp_path, capsys, monkeypatch, argv, message):
    monkeypatch.chdir(tmp_path)
    before = (session / "take" / "markers.c3d").read_bytes()
    assert main([a.format(take=session / "take") for a in argv]) == 2
    err = capsys.readouterr().err.strip()
    assert message in err and len(err.splitlines()) == 1
    assert (session / "take" / "markers.c3d").read_bytes() == before


def test_shape_default_nan_attachment_and_strict_warnings(session, tmp_path, capsys):
    att = tmp_path / "att.npz"
    assert main(["calibrate-markers", str(session / "cal" / "markers.c3d"), "--layout", "tips-5",
                 "--out", str(att)]) == 0
    assert "shape not fitted" in capsys.readouterr().out  # tips-5: one marker per digit (shape_is_constrained)
    # A NaN in the attachment is one line and exit 2 (it was a LinAlgError from the solver).
    with np.load(att) as data:
        arrays = {k: data[k] for k in data.files}
    arrays["barycentric"][2, 0] = np.nan
    bad = tmp_path / "bad.npz"
    np.savez(bad, **arrays)
    assert main(["solve", str(session / "take" / "markers.c3d"), "--attachment", str(bad),
                 "--out", str(tmp_path / "m.npz")]) == 2
    err = capsys.readouterr().err.strip()
    assert "NaN" in err and len(err.splitlines()) == 1
    # Two labels swapped in every frame: solved exchanged with a warning that names them, stored, and exit 2 with
    # --strict; solved as labelled (--keep-swaps), markers the attachment does not fit: the MRE's warning.
    from handcap import MarkerSequence
    from handcap.io import read_markers, write_markers_npz
    take = read_markers(session / "take" / "markers.c3d")
    names = list(take.names)
    i, j = names.index("thumb_tip"), names.index("pinky_tip")
    names[i], names[j] = names[j], names[i]
    swapped = tmp_path / "swapped.npz"
    write_markers_npz(MarkerSequence(take.positions, names, take.rate), swapped)
    out = tmp_path / "motion.npz"
    assert main(["--strict", "solve", str(swapped), "--attachment", str(att), "--out", str(out)]) == 2
    assert "warning: solve: 1 label swap(s)" in capsys.readouterr().err
    assert any("thumb_tip and pinky_tip in frames 0-" in w for w in read_hand_motion(out).warnings)
    assert main(["--strict", "solve", str(swapped), "--attachment", str(att), "--out", str(out), "--keep-swaps"]) == 2
    assert "warning: solve MRE" in capsys.readouterr().err
    assert any("solve MRE" in w for w in read_hand_motion(out).warnings)
