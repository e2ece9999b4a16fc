"""Warnings of implausible results: issued, stored on every container, kept in files, printed by the CLI."""

import warnings

import numpy as np
import pytest

from handcap import cli
from handcap.cli import convert as cli_convert
from handcap.steps import Step
from handcap.core.errors import HandcapError, HandcapWarning, merge_warnings, warn
from handcap.core.markers import MarkerSequence
from handcap.core.motion import HandMotion, ObjectMotion
from handcap.hand.attachment import MarkerAttachment
from handcap.io import (
    read_hand_motion,
    read_markers,
    read_object_motion,
    write_hand_motion,
    write_markers,
    write_object_motion,
)


def test_warn_issues_a_handcap_warning_and_returns_one_line():
    with pytest.warns(HandcapWarning, match="MRE 7.1 mm"):
        line = warn("MRE 7.1 mm\n above   5 mm")
    assert line == "MRE 7.1 mm above 5 mm"


def test_a_bad_input_error_is_a_value_error():
    # Issue 15: a library user may catch the built-in type; the message stays one line.
    with pytest.raises(ValueError, match="no such file") as caught:
        read_markers("no/such/take.c3d")
    assert isinstance(caught.value, HandcapError) and "\n" not in str(caught.value)


def test_merge_keeps_order_and_drops_repeats():
    assert merge_warnings(("a", "b"), None, "a", ["c", ""]) == ("a", "b", "c")


def _markers():
    rng = np.random.default_rng(3)
    return MarkerSequence(rng.normal(size=(5, 2, 3)), ["a", "b"], 100.0)


def test_marker_warnings_survive_derivation_and_files(tmp_path):
    markers = _markers().with_warnings("units guessed: millimetres")
    assert markers.select(["b"]).warnings == ("units guessed: millimetres",)
    assert markers.frames(1, 4).warnings == markers.warnings
    assert markers.renamed(["x", "y"]).warnings == markers.warnings
    assert markers.with_warnings("units guessed: millimetres", "second").warnings == (
        "units guessed: millimetres", "second")
    for name in ("m.npz", "m.c3d"):
        write_markers(markers, tmp_path / name)
        assert read_markers(tmp_path / name).warnings == markers.warnings
    write_markers(_markers(), tmp_path / "clean.npz")
    assert read_markers(tmp_path / "clean.npz").warnings == ()
    assert "warnings" not in np.load(tmp_path / "clean.npz").files


def test_motion_and_attachment_warnings_round_trip(tmp_path):
    motion = HandMotion(np.zeros(10), np.zeros((4, 3)), np.zeros((4, 45)), np.zeros((4, 3)), 50.0)
    motion = motion.with_warnings("shape value 3 at its bound")
    assert motion.frames(1, 3).warnings == motion.warnings
    write_hand_motion(motion, tmp_path / "h.npz")
    assert read_hand_motion(tmp_path / "h.npz").warnings == motion.warnings
    obj = ObjectMotion(np.zeros((4, 3)), np.zeros((4, 3)), 50.0).with_warnings("residual 9 mm")
    write_object_motion(obj, tmp_path / "o.npz")
    assert read_object_motion(tmp_path / "o.npz").warnings == ("residual 9 mm",)
    att = MarkerAttachment(("a",), [0], [[1.0, 0, 0]], [0.005], np.zeros(10)).with_warnings("MRE 6 mm")
    att.save(tmp_path / "a.npz")
    assert MarkerAttachment.load(tmp_path / "a.npz").warnings == ("MRE 6 mm",)
    assert MarkerAttachment.load(tmp_path / "a.npz").subset(["a"]).warnings == ("MRE 6 mm",)


def _verb_with_warnings(args):
    warn("implausible figure")  # what library code does; the CLI must not print it twice
    return Step((), ("implausible figure", "second figure"))


@pytest.mark.parametrize("strict, code", [(False, 0), (True, 2)])
def test_cli_prints_each_warning_once_and_strict_exits_2(monkeypatch, capsys, tmp_path, strict, code):
    monkeypatch.setattr(cli_convert, "_cmd_convert", _verb_with_warnings)
    argv = (["--strict"] if strict else []) + ["convert", str(tmp_path / "a.c3d"), str(tmp_path / "b.npz")]
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # a HandcapWarning escaping main() would fail here
        assert cli.main(argv) == code
    err = capsys.readouterr().err
    assert err.count("handcap convert: warning: implausible figure") == 1
    assert err.count("handcap convert: warning: second figure") == 1
    assert ("--strict" in err) == strict
