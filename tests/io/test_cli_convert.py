"""``handcap convert`` end to end, and every real marker file through the dispatcher."""

import hashlib
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from handcap import HandcapError, MarkerSequence
from handcap.cli import main
from handcap.io import read_markers, write_markers

RECORDING = "markers/hand_embodiment_glove/recording.tsv"


def _digest(path):
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


def _one_error_line(capsys):
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("handcap convert: error: ")
    return err


def test_tsv_to_c3d_to_npz_keeps_the_values(shared_data, tmp_path, capsys):
    source = shared_data / RECORDING
    assert main(["convert", str(source), str(tmp_path / "rec.c3d")]) == 0
    assert "6000 frames, 21 markers at 100 Hz" in capsys.readouterr().out
    assert main(["convert", str(tmp_path / "rec.c3d"), str(tmp_path / "rec.npz")]) == 0
    original, final = read_markers(source), read_markers(tmp_path / "rec.npz")
    assert final.names == original.names and final.rate == original.rate
    np.testing.assert_array_equal(final.missing, original.missing)
    # C3D stores float32 millimetres.
    np.testing.assert_allclose(final.positions, original.positions, atol=1e-6)


def test_c3d_to_trc_to_npz(shared_data, tmp_path):
    source = shared_data / "markers/ezc3d/Vicon.c3d"
    assert main(["convert", str(source), str(tmp_path / "v.trc")]) == 0
    assert main(["convert", str(tmp_path / "v.trc"), str(tmp_path / "v.npz")]) == 0
    np.testing.assert_allclose(read_markers(tmp_path / "v.npz").positions, read_markers(source).positions,
                               atol=1e-9)


def test_the_output_as_out_like_the_other_verbs_and_given_once(shared_data, tmp_path, capsys):
    source = shared_data / "markers/ezc3d/Vicon.c3d"
    assert main(["convert", str(source), "--out", str(tmp_path / "v.npz")]) == 0
    np.testing.assert_allclose(read_markers(tmp_path / "v.npz").positions, read_markers(source).positions,
                               atol=1e-9)
    capsys.readouterr()
    for twice in ([str(tmp_path / "a.npz"), "--out", str(tmp_path / "b.npz")], []):
        assert main(["convert", str(source), *twice]) == 2
        assert "give the output file once" in _one_error_line(capsys)
    assert not (tmp_path / "a.npz").exists() and not (tmp_path / "b.npz").exists()


def test_bad_input_exits_2_with_one_line(tmp_path, capsys):
    assert main(["convert", str(tmp_path / "absent.c3d"), str(tmp_path / "out.npz")]) == 2
    assert "no such file" in _one_error_line(capsys)
    (tmp_path / "cut.c3d").write_bytes(b"\x02\x50" + bytes(600))
    assert main(["convert", str(tmp_path / "cut.c3d"), str(tmp_path / "out.npz")]) == 2
    _one_error_line(capsys)
    assert not (tmp_path / "out.npz").exists()


def test_unknown_output_format_exits_2(shared_data, tmp_path, capsys):
    assert main(["convert", str(shared_data / RECORDING), str(tmp_path / "out.tsv")]) == 2
    assert "cannot write '.tsv' marker files" in _one_error_line(capsys)
    assert list(tmp_path.iterdir()) == []


def test_failed_conversion_keeps_an_existing_output(tmp_path, capsys):
    (tmp_path / "bad.trc").write_text("PathFileType\t4\n")
    (tmp_path / "out.npz").write_bytes(b"old")
    assert main(["convert", str(tmp_path / "bad.trc"), str(tmp_path / "out.npz")]) == 2
    _one_error_line(capsys)
    assert (tmp_path / "out.npz").read_bytes() == b"old"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bad.trc", "out.npz"]


@pytest.mark.parametrize("spelling", ["same", "dotted", "hardlink"])
def test_output_over_the_input_is_refused(tmp_path, capsys, spelling):
    source = tmp_path / "in.npz"
    write_markers(MarkerSequence(np.ones((3, 2, 3)), ["a", "b"], 10.0), source)
    before = _digest(source)
    target = {"same": source, "dotted": tmp_path / "." / "sub" / ".." / "in.npz",
              "hardlink": tmp_path / "link.npz"}[spelling]
    (tmp_path / "sub").mkdir()
    if spelling == "hardlink":
        os.link(source, target)
    assert main(["convert", str(source), str(target)]) == 2
    assert "would overwrite the input" in _one_error_line(capsys)
    assert _digest(source) == before


def test_installed_command(shared_data, tmp_path):
    command = Path(sys.executable).with_name("handcap")
    if not command.exists():
        pytest.skip("the handcap command is not installed beside this Python")
    done = subprocess.run([str(command), "convert", str(shared_data / "markers/ezc3d/Optotrak.c3d"),
                           str(tmp_path / "o.npz")], capture_output=True, text=True, timeout=60)
    assert done.returncode == 2
    assert done.stderr.count("\n") == 1 and "truncated C3D file" in done.stderr
    assert "Traceback" not in done.stderr


def _real_marker_files():
    # As tests/conftest.py's SHARED_DATA (parametrize runs before fixtures).
    root = Path(os.environ.get("HANDCAP_SHARED_DATA") or Path(__file__).resolve().parents[2].parent / "shared"
                / "data") / "markers"
    found = sorted(p.relative_to(root.parent).as_posix() for p in root.rglob("*")
                   if p.suffix.lower() in (".c3d", ".tsv", ".csv", ".trc"))
    # Without the data folder: one test, skipped by the shared_data fixture with its reason.
    return found or ["markers (absent)"]


# What each real file gives: (frames, markers) or the start of the error message.
EXPECTED = {
    "markers/ezc3d/Optotrak.c3d": "truncated C3D file",
    "markers/uci_hand_postures/Postures.csv": "this is the UCI hand-postures table",
}


@pytest.mark.parametrize("name", _real_marker_files())
def test_every_real_marker_file_loads_or_fails_clearly(shared_data, name):
    path = shared_data / name
    if name in EXPECTED:
        with pytest.raises(HandcapError, match=EXPECTED[name]):
            read_markers(path)
        return
    markers = read_markers(path)
    assert markers.n_frames > 0 and markers.n_markers > 0
    assert 0.1 < np.nanmax(np.abs(markers.positions)) < 5.0


def test_convert_partial_keeps_the_complete_frames_of_a_short_c3d(shared_data, tmp_path, capsys):
    from handcap.cli import main
    from handcap.io import read_markers
    source = shared_data / "markers" / "ezc3d" / "Optotrak.c3d"
    assert main(["convert", str(source), str(tmp_path / "o.npz")]) == 2
    assert "--partial" in capsys.readouterr().err
    assert main(["convert", "--partial", str(source), str(tmp_path / "o.npz")]) == 0
    markers = read_markers(tmp_path / "o.npz")
    assert markers.n_frames == 29 and markers.rate == 30.0 and markers.n_markers == 54
    with pytest.raises(HandcapError, match="C3D files only"):
        read_markers(shared_data / "markers" / "hand_embodiment_glove" / "recording.tsv", partial=True)
