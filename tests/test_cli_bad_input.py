"""Bad input on the command line: one line, exit code 2, no traceback, and no input ever changed (issue 14).

Every writing verb is fed an output path equal to one of its inputs, a folder, a path in a missing folder
and a path in a folder that cannot be written; then the tracebacks of issue 14 (a binary file given as
TOML, NaN in an attachment, a missing object mesh, an object file of another length, wrong units, output
piped into ``head``). Each case checks the exit code, that stderr is the one line ``handcap VERB: error:
...``, and that the sha256 of every input file is what it was.
"""

from __future__ import annotations

import hashlib
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
import pytest

from handcap.cli import main
from handcap.io import load_npz, read_markers, read_rig, save_npz, write_markers
from handcap.io.cameras import write_cameras_toml

BOARD = "checkerboard:9x6:0.025"


@pytest.fixture(scope="module")
def take(tmp_path_factory):
    """A small synthetic take and everything the verbs read: markers, points, detections, cameras,
    attachment, hand motion, object motion (and one cut short), a scan, a layout, a labeling model."""
    root = tmp_path_factory.mktemp("take")
    s = root / "s"
    assert main(["synth", "--frames", "40", "--motion", "open-close", "--object", "none", "--seed", "3",
                 "--out", str(s)]) == 0
    assert main(["calibrate-markers", str(s / "markers.npz"), "--layout", "glove-13",
                 "--out", str(root / "att.npz")]) == 0
    assert main(["solve", str(s / "markers.npz"), "--attachment", str(root / "att.npz"),
                 "--out", str(root / "motion.npz")]) == 0
    assert main(["track-object", str(s / "markers.npz"), "--markers", "hand_top,hand_left,hand_right",
                 "--out", str(root / "obj.npz")]) == 0
    obj = load_npz(root / "obj.npz")
    save_npz(root / "obj_short.npz", {k: (v[:25] if k in ("rotation", "translation") else v) for k, v in obj.items()})
    markers = read_markers(s / "markers.npz")
    save_npz(root / "scan.npz", {"points": markers.positions[0][~markers.missing[0]]})
    assert main(["layout", "new", "--like", "glove-13", "--out", str(root / "layout.toml")]) == 0
    return root


def _sha(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def _inputs(take: Path) -> list[Path]:
    return sorted(p for p in take.rglob("*") if p.is_file())


def _run_bad(argv, take, capsys, verb, match=None):
    """Run ``argv``; check exit 2, one error line naming ``verb``, no traceback, inputs unchanged."""
    before = {p: _sha(p) for p in _inputs(take)}
    capsys.readouterr()
    code = main([str(a) for a in argv])
    captured = capsys.readouterr()
    err = captured.err
    assert code == 2, err
    assert "Traceback" not in err + captured.out
    assert err.count("\n") == 1 and err.startswith(f"handcap {verb}: error: "), err
    if match is not None:
        assert match in err, err
    after = {p: _sha(p) for p in _inputs(take) if p in before}
    assert after == before
    return err


def _writing_verbs(t: Path) -> dict:
    """verb -> (argv with OUT where the output goes, the input file OUT is set to, file suffix of OUT)."""
    s = t / "s"
    m, cams, det = s / "markers.npz", s / "cameras.toml", s / "detections.npz"
    return {
        "convert": (["convert", m, "OUT"], m, ".npz"),
        "calibrate-markers": (["calibrate-markers", m, "--layout", "glove-13", "--out", "OUT"], m, ".npz"),
        "solve": (["solve", m, "--attachment", t / "att.npz", "--out", "OUT"], t / "att.npz", ".npz"),
        "track-object": (["track-object", m, "--markers", "hand_top,hand_left,hand_right", "--out", "OUT"], m,
                         ".npz"),
        "metrics": (["metrics", t / "motion.npz", "--out", "OUT"], t / "motion.npz", ".json"),
        "shape": (["shape", "--scan", t / "scan.npz", "--out", "OUT"], t / "scan.npz", ".npz"),
        "label": (["label", s / "points.npz", "--train", m, "--layout", "glove-13", "--out", "OUT"], m, ".npz"),
        "label --model": (["label", s / "points.npz", "--train", m, "--layout", "glove-13", "--model", "OUT",
                           "--out", t / "never.npz"], s / "points.npz", ".npz"),
        "score-labels": (["score-labels", m, "--truth", m, "--json", "OUT"], m, ".json"),
        "corrupt": (["corrupt", m, "--out", "OUT"], m, ".npz"),
        "train-occlusion": (["train-occlusion", m, "--layout", "glove-13", "--epochs", "1", "--out", "OUT"], m,
                            ".npz"),
        "fill": (["fill", m, "--method", "linear", "--out", "OUT"], m, ".npz"),
        "clean": (["clean", m, "--out", "OUT"], m, ".npz"),
        "triangulate": (["triangulate", det, "--cameras", cams, "--out", "OUT"], det, ".npz"),
        "calibrate intrinsics": (["calibrate", "intrinsics", cams, "--board", BOARD, "--out", "OUT"], cams,
                                 ".toml"),
        "calibrate rig": (["calibrate", "rig", det, det, "--intrinsics", cams, "--board", BOARD, "--out", "OUT"],
                          cams, ".toml"),
        "layout new": (["layout", "new", "--like", t / "layout.toml", "--force", "--out", "OUT"],
                       t / "layout.toml", ".toml"),
    }


VERBS = ["convert", "calibrate-markers", "solve", "track-object", "metrics", "shape", "label", "label --model",
         "score-labels", "corrupt", "train-occlusion", "fill", "clean", "triangulate", "calibrate intrinsics",
         "calibrate rig", "layout new"]


def _argv(spec, out):
    return [out if a == "OUT" else a for a in spec]


@pytest.mark.parametrize("verb", VERBS)
def test_output_equal_to_an_input_is_refused(take, capsys, verb):
    argv, inp, _ = _writing_verbs(take)[verb]
    _run_bad(_argv(argv, inp), take, capsys, verb.split()[0], "overwrite the input")


@pytest.mark.parametrize("verb", VERBS)
def test_output_that_is_a_folder_is_refused(take, capsys, verb, tmp_path):
    argv, _, suffix = _writing_verbs(take)[verb]
    folder = tmp_path / f"out{suffix}"
    folder.mkdir()
    _run_bad(_argv(argv, folder), take, capsys, verb.split()[0], "is a folder")
    assert list(folder.iterdir()) == []


@pytest.mark.parametrize("verb", VERBS)
def test_output_in_a_missing_folder_is_refused(take, capsys, verb, tmp_path):
    argv, _, suffix = _writing_verbs(take)[verb]
    _run_bad(_argv(argv, tmp_path / "absent" / f"out{suffix}"), take, capsys, verb.split()[0], "does not exist")
    assert not (tmp_path / "absent").exists()


def _unwritable_folder(tmp_path) -> Path:
    """A folder no file can be created in: read-only permissions, or (as root, who ignores them) /sys."""
    if os.geteuid() != 0:
        folder = tmp_path / "locked"
        folder.mkdir(mode=0o500)
        return folder
    try:
        with tempfile.TemporaryFile(dir="/sys"):
            pass
    except OSError:
        return Path("/sys")
    pytest.skip("running as root with no read-only folder at hand")


@pytest.mark.parametrize("verb", VERBS)
def test_output_in_an_unwritable_folder_is_refused(take, capsys, verb, tmp_path):
    argv, _, suffix = _writing_verbs(take)[verb]
    folder = _unwritable_folder(tmp_path)
    _run_bad(_argv(argv, folder / f"handcap-test-out{suffix}"), take, capsys, verb.split()[0], "cannot write in")


def test_synth_refuses_a_folder_with_files_unless_forced(take, capsys, tmp_path):
    folder = tmp_path / "busy"
    folder.mkdir()
    (folder / "notes.txt").write_text("mine\n")
    argv = ["synth", "--frames", "40", "--motion", "open-close", "--object", "none", "--out", folder]
    _run_bad(argv, take, capsys, "synth", "--force")
    assert sorted(p.name for p in folder.iterdir()) == ["notes.txt"]
    assert main([str(a) for a in argv] + ["--force"]) == 0
    assert (folder / "notes.txt").read_text() == "mine\n" and (folder / "markers.npz").is_file()


def test_synth_refuses_to_write_over_its_own_scene(take, capsys):
    s = take / "s"
    _run_bad(["synth", "--scene", s / "scene.toml", "--force", "--out", s], take, capsys, "synth", "holds the input")


@pytest.mark.parametrize("verb", ["synth", "demo"])
def test_folder_writers_refuse_a_file_as_folder(take, capsys, verb):
    argv = ["synth", "--frames", "40"] if verb == "synth" else ["demo"]
    _run_bad(argv + ["--out", take / "att.npz"], take, capsys, verb, "not a folder")


@pytest.mark.parametrize("option", ["layout", "cameras"])
def test_binary_file_given_as_toml(take, capsys, tmp_path, option):
    binary = tmp_path / "binary.toml"
    binary.write_bytes(bytes(range(256)) * 4)
    s = take / "s"
    if option == "layout":
        argv = ["calibrate-markers", s / "markers.npz", "--layout", binary, "--out", tmp_path / "a.npz"]
        verb = "calibrate-markers"
    else:
        argv = ["triangulate", s / "detections.npz", "--cameras", binary, "--out", tmp_path / "m.npz"]
        verb = "triangulate"
    _run_bad(argv, take, capsys, verb, str(binary))
    assert [p.name for p in tmp_path.iterdir()] == ["binary.toml"]


def test_nan_in_an_attachment(take, capsys, tmp_path):
    arrays = load_npz(take / "att.npz")
    arrays["barycentric"] = np.where(np.arange(arrays["barycentric"].size).reshape(arrays["barycentric"].shape) == 4,
                                     np.nan, arrays["barycentric"])
    save_npz(tmp_path / "nan.npz", arrays)
    _run_bad(["solve", take / "s" / "markers.npz", "--attachment", tmp_path / "nan.npz", "--out",
              tmp_path / "m.npz"], take, capsys, "solve")
    assert not (tmp_path / "m.npz").exists()


def test_missing_object_mesh(take, capsys, tmp_path):
    _run_bad(["metrics", take / "motion.npz", "--object", take / "obj.npz", "--object-mesh", tmp_path / "absent.ply"],
             take, capsys, "metrics", "absent.ply")


def test_object_of_another_length(take, capsys, tmp_path):
    import trimesh
    trimesh.creation.box(extents=(0.05, 0.05, 0.05)).export(tmp_path / "box.ply")
    err = _run_bad(["metrics", take / "motion.npz", "--object", take / "obj_short.npz", "--object-mesh",
                    tmp_path / "box.ply"], take, capsys, "metrics")
    assert "25" in err and "40" in err


def test_object_of_another_length_without_mesh(take, capsys):
    _run_bad(["metrics", take / "motion.npz", "--object", take / "obj_short.npz"], take, capsys, "metrics", "25")


# -- units ------------------------------------------------------------------------------------------------

def test_coordinates_of_1e30_metres(take, capsys, tmp_path):
    markers = read_markers(take / "s" / "markers.npz")
    arrays = load_npz(take / "s" / "markers.npz")
    arrays["positions"] = np.where(np.isnan(markers.positions), np.nan, 1e30)
    save_npz(tmp_path / "huge.npz", arrays)
    _run_bad(["solve", tmp_path / "huge.npz", "--attachment", take / "att.npz", "--out", tmp_path / "m.npz"],
             take, capsys, "solve", "fit no length unit")
    assert not (tmp_path / "m.npz").exists()


def _mm_declared_as_m(markers, path):
    write_markers(markers, path)        # TRC is written in millimetres
    text = path.read_text()
    path.write_text(text.replace("\tmm\t", "\tm\t", 1))


def test_trc_in_millimetres_declared_as_metres(take, capsys, tmp_path):
    """The hand's size tells millimetres: solve runs, says so in a warning, and gives the honest file's motion."""
    markers = read_markers(take / "s" / "markers.npz")
    _mm_declared_as_m(markers, tmp_path / "m.trc")
    assert main(["solve", str(tmp_path / "m.trc"), "--attachment", str(take / "att.npz"),
                 "--out", str(tmp_path / "motion.npz")]) == 0
    err = capsys.readouterr().err
    assert "handcap solve: warning:" in err and "read as millimetres" in err
    from handcap.io import read_hand_motion
    solved, honest = read_hand_motion(tmp_path / "motion.npz"), read_hand_motion(take / "motion.npz")
    np.testing.assert_allclose(solved.joints, honest.joints, atol=1e-4)
    assert any("read as millimetres" in w for w in solved.warnings)     # stored with the result
    assert main(["--strict", "solve", str(tmp_path / "m.trc"), "--attachment", str(take / "att.npz"),
                 "--out", str(tmp_path / "motion2.npz")]) == 2


def test_trc_declared_wrong_without_a_hand_asks_for_units(take, capsys, tmp_path):
    markers = read_markers(take / "s" / "markers.npz")
    _mm_declared_as_m(markers, tmp_path / "m.trc")
    _run_bad(["convert", tmp_path / "m.trc", tmp_path / "m.npz"], take, capsys, "convert", "--units mm|cm")
    assert main(["convert", str(tmp_path / "m.trc"), str(tmp_path / "m.npz"), "--units", "mm"]) == 0
    np.testing.assert_allclose(read_markers(tmp_path / "m.npz").positions, markers.positions, atol=1e-9)


def test_rig_in_millimetres(take, capsys, tmp_path):
    """Cameras 2-3 km apart in "metres": only millimetres fit, triangulate warns and gives the honest markers."""
    s = take / "s"
    rig = read_rig(s / "cameras.toml")
    write_cameras_toml(rig.scaled(1000.0), tmp_path / "mm.toml")
    assert main(["triangulate", str(s / "detections.npz"), "--cameras", str(tmp_path / "mm.toml"),
                 "--workers", "1", "--out", str(tmp_path / "mm.npz")]) == 0
    assert "read as millimetres" in capsys.readouterr().err
    assert main(["triangulate", str(s / "detections.npz"), "--cameras", str(s / "cameras.toml"),
                 "--workers", "1", "--out", str(tmp_path / "m.npz")]) == 0
    np.testing.assert_allclose(read_markers(tmp_path / "mm.npz").positions, read_markers(tmp_path / "m.npz").positions,
                               atol=1e-9)


# -- pipes ------------------------------------------------------------------------------------------------

def test_output_piped_into_head(take):
    """``handcap metrics motion.npz | head``: the reader is gone before the table is printed (closed here before
    the command starts writing, so the pipe is surely broken); no BrokenPipeError, no traceback, exit 0."""
    before = _sha(take / "motion.npz")
    code = f"import sys; from handcap.cli import main; sys.exit(main(['metrics', {str(take / 'motion.npz')!r}]))"
    proc = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            env={**os.environ, "OMP_NUM_THREADS": "1"})
    proc.stdout.close()
    err = proc.stderr.read().decode()
    assert proc.wait(timeout=300) == 0, err
    assert "Traceback" not in err and "BrokenPipe" not in err, err
    assert _sha(take / "motion.npz") == before
