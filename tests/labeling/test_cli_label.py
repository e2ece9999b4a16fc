"""corrupt -> label -> score-labels from the command line, on the real glove recording; bad input exits 2."""

import json

import numpy as np
import pytest

from handcap.cli import main
from handcap.io import read_markers, write_markers


@pytest.fixture(scope="module")
def takes(shared_data, tmp_path_factory):
    root = tmp_path_factory.mktemp("label")
    take = read_markers(shared_data / "markers" / "hand_embodiment_glove" / "recording.tsv")
    write_markers(take[:2000], root / "rom.c3d")
    write_markers(take[2000:2600], root / "test.c3d")
    write_markers(take[:2000], root / "rom_all.c3d")
    return root


def test_corrupt_label_score(takes, capsys):
    r = takes
    assert main(["corrupt", str(r / "test.c3d"), "--layout", "glove-13", "--ghost-rate", "2", "--dropout", "0.05",
                 "--seed", "0", "--out", str(r / "unl.c3d")]) == 0
    assert (r / "unl.truth.c3d").exists()
    before = (r / "unl.c3d").read_bytes()
    assert main(["label", str(r / "unl.c3d"), "--train", str(r / "rom.c3d"), "--layout", "glove-13",
                 "--model", str(r / "model.npz"), "--out", str(r / "labeled.c3d")]) == 0
    assert (r / "unl.c3d").read_bytes() == before  # the input is never touched
    labeled = read_markers(r / "labeled.c3d")
    assert labeled.names[:3] == ("hand_top", "hand_left", "hand_right") and labeled.n_frames == 600
    capsys.readouterr()
    assert main(["score-labels", str(r / "labeled.c3d"), "--truth", str(r / "unl.truth.c3d"),
                 "--json", str(r / "score.json")]) == 0
    assert "false occlusion" in capsys.readouterr().out
    score = json.loads((r / "score.json").read_text())
    assert score["instances"] == 600 * 13 and score["correct_percent"] > 99.5
    # The saved model labels the same way without training again.
    assert main(["label", str(r / "unl.c3d"), "--train", str(r / "model.npz"), "--model", str(r / "model.npz"),
                 "--layout", "glove-13", "--out", str(r / "again.npz")]) == 0
    np.testing.assert_allclose(read_markers(r / "again.npz").positions, labeled.positions, atol=1e-6)


@pytest.mark.parametrize("argv, message", [
    (["label", "{r}/test.c3d", "--train", "{r}/rom.c3d", "--layout", "nope", "--out", "{r}/x.c3d"], "unknown layout"),
    (["label", "{r}/test.c3d", "--train", "{r}/rom.c3d", "--layout", "joints-19", "--out", "{r}/x.c3d"],
     "not in the training take"),
    (["label", "{r}/test.c3d", "--train", "{r}/rom.c3d", "--layout", "glove-13", "--out", "{r}/test.c3d"],
     "input"),
    (["label", "{r}/test.c3d", "--train", "{r}/rom.c3d", "--layout", "glove-13", "--hypotheses", "0",
      "--out", "{r}/x.c3d"], "hypotheses"),
    (["score-labels", "{r}/test.c3d", "--truth", "{r}/rom.c3d"], "frames"),
    (["corrupt", "{r}/test.c3d", "--dropout", "1.5", "--out", "{r}/c.c3d"], "dropout"),
    (["corrupt", "{r}/missing.c3d", "--out", "{r}/c.c3d"], "missing.c3d"),
])
def test_bad_input_exits_2_with_one_line(takes, capsys, argv, message):
    assert main([a.format(r=takes) for a in argv]) == 2
    err = capsys.readouterr().err.strip()
    assert message in err and len(err.splitlines()) == 1


def test_a_held_object_from_the_training_take(takes, capsys):
    # Every marker of the recording in the stream (arm, back and the pillow's triad too); the pillow's
    # shape comes from the training take, and its markers get their own labels.
    r = takes
    assert main(["corrupt", str(r / "test.c3d"), "--ghost-rate", "2", "--dropout", "0.05", "--seed", "3",
                 "--out", str(r / "all.c3d")]) == 0
    assert main(["label", str(r / "all.c3d"), "--train", str(r / "rom_all.c3d"), "--layout", "glove-13",
                 "--object", "pillow_*", "--out", str(r / "all_labeled.c3d")]) == 0
    labeled, truth = read_markers(r / "all_labeled.c3d"), read_markers(r / "all.truth.c3d")
    assert labeled.names[-3:] == ("pillow_top", "pillow_left", "pillow_right")
    got = labeled.positions[:, -3:]
    true = np.stack([truth.positions[:, truth.index(n)] for n in labeled.names[-3:]], axis=1)
    same = np.isclose(got, true).all(axis=-1) | (np.isnan(got[..., 0]) & np.isnan(true[..., 0]))
    # Measured: 98 % of the pillow's label-frames right, the rest gaps (it cannot be found with two of its three
    # markers before it was ever seen, and a soft pillow strays from its shape); never another point.
    assert same.mean() > 0.97
    assert (np.isnan(got[..., 0]) | same).all()
    capsys.readouterr()
    assert main(["label", str(r / "all.c3d"), "--train", str(r / "rom_all.c3d"), "--layout", "glove-13",
                 "--object", "nothing_*", "--out", str(r / "x.c3d")]) == 2
    assert "no marker matches 'nothing_*'" in capsys.readouterr().err
    assert main(["label", str(r / "all.c3d"), "--train", str(r / "rom_all.c3d"), "--layout", "glove-13",
                 "--object", "pillow_top,pillow_left", "--out", str(r / "x.c3d")]) == 2
    assert "3 or more markers, got 2" in capsys.readouterr().err


def test_two_hands_from_the_command_line(takes, shared_data, tmp_path, capsys):
    # Issue 14: --layout once per hand (each with its own names and rigid markers), --train takes holding both.
    from dataclasses import replace

    from scipy.spatial.transform import Rotation

    from handcap import MarkerSequence
    from handcap.layouts import load_layout
    glove = load_layout("glove-13")
    paths = []
    for prefix in ("R_", "L_"):
        layout = replace(glove, name=prefix + "glove", rigid=tuple(prefix + n for n in glove.rigid),
                         markers=tuple(replace(m, name=prefix + m.name) for m in glove.markers))
        layout.save(tmp_path / f"{prefix}layout.toml")
        paths.append(str(tmp_path / f"{prefix}layout.toml"))
    take = read_markers(shared_data / "markers" / "hand_embodiment_glove" / "recording.tsv").select(glove.names)
    mirrored = take.positions * [-1.0, 1.0, 1.0]
    centre = np.nanmean(mirrored.reshape(-1, 3), axis=0)
    left = (mirrored - centre) @ Rotation.from_euler("z", 180, degrees=True).as_matrix().T + centre + [0.4, 0, 0]
    names = tuple("R_" + n for n in glove.names) + tuple("L_" + n for n in glove.names)
    both = MarkerSequence(np.concatenate([take.positions, np.roll(left, -1500, axis=0)], axis=1), names, take.rate)
    write_markers(both[:2000], tmp_path / "rom.c3d")
    write_markers(both[2000:2600], tmp_path / "test.c3d")
    assert main(["corrupt", str(tmp_path / "test.c3d"), "--ghost-rate", "2", "--seed", "0",
                 "--out", str(tmp_path / "unl.c3d")]) == 0
    assert main(["label", str(tmp_path / "unl.c3d"), "--train", str(tmp_path / "rom.c3d"), "--layout", paths[0],
                 "--layout", paths[1], "--out", str(tmp_path / "labeled.c3d")]) == 0
    from handcap.labeling import score_labels
    labeled, truth = read_markers(tmp_path / "labeled.c3d"), read_markers(tmp_path / "unl.truth.c3d")
    assert set(labeled.names) == set(names)
    score = score_labels(labeled, truth)
    assert score.fraction("correct") > 0.995 and score.fraction("erroneous") < 0.001
    capsys.readouterr()
    assert main(["label", str(tmp_path / "unl.c3d"), "--train", str(tmp_path / "rom.c3d"), "--layout", paths[0],
                 "--layout", paths[1], "--method", "nearest", "--out", str(tmp_path / "x.c3d")]) == 2
    assert "several --layout" in capsys.readouterr().err


def test_several_training_takes_and_strict_warnings(takes, capsys):
    # --train repeated; a take whose hand frame cannot be found warns, and --strict makes that exit 2.
    r = takes
    assert main(["label", str(r / "test.c3d"), "--train", str(r / "rom.c3d"), "--train", str(r / "rom_all.c3d"),
                 "--layout", "glove-13", "--out", str(r / "two_takes.c3d")]) == 0
    take = read_markers(r / "test.c3d")
    positions = take.positions.copy()
    positions[:, [take.index(n) for n in ("hand_top", "hand_left", "hand_right")]] = np.nan
    from handcap import MarkerSequence
    write_markers(MarkerSequence(positions, take.names, take.rate), r / "no_back.c3d")
    capsys.readouterr()
    assert main(["--strict", "label", str(r / "no_back.c3d"), "--train", str(r / "rom.c3d"), "--layout", "glove-13",
                 "--out", str(r / "no_back_labeled.c3d")]) == 2
    err = capsys.readouterr().err
    assert "warning: hand frame lost in" in err
    assert (r / "no_back_labeled.c3d").exists()  # written all the same


def test_offline_labels_are_checked_against_the_solved_hand(takes, capsys):
    # --offline runs the check (a line says what it did) and stays as right as without it on the real glove;
    # --no-hand-check leaves the labeler's labels.
    r = takes
    assert main(["corrupt", str(r / "test.c3d"), "--layout", "glove-13", "--ghost-rate", "2", "--dropout", "0.05",
                 "--seed", "1", "--out", str(r / "off.c3d")]) == 0
    scores = {}
    for flags in ((), ("--no-hand-check",)):
        capsys.readouterr()
        assert main(["label", str(r / "off.c3d"), "--train", str(r / "rom.c3d"), "--layout", "glove-13", "--offline",
                     *flags, "--out", str(r / "off-labeled.c3d")]) == 0
        out = capsys.readouterr().out
        assert ("checked against the solved hand" in out) == (not flags), out
        assert main(["score-labels", str(r / "off-labeled.c3d"), "--truth", str(r / "off.truth.c3d"),
                     "--json", str(r / "off.json")]) == 0
        scores[flags] = json.loads((r / "off.json").read_text())
    checked, plain = scores[()], scores[("--no-hand-check",)]
    assert checked["correct_percent"] > 99.5 and checked["erroneous_percent"] <= plain["erroneous_percent"]
    assert abs(checked["correct_percent"] - plain["correct_percent"]) < 0.2
