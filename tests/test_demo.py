"""handcap demo: its picture shows the solve beside the truth, and it lists every file it wrote."""

import dataclasses
import json
import re

import numpy as np
import pytest

import handcap.demo as demo
from handcap.cli import main
from handcap.core.files import atomic_output, file_stamps, written_since
from handcap.synth.scene import SynthConfig, synthesize


@pytest.fixture
def small_demo(monkeypatch):
    """The demo's path on a small glove session (the full one takes minutes)."""
    monkeypatch.setattr(demo, "DEMO_CONFIG", SynthConfig(layout="glove-13", motion="grasp", frames=60, rate=20.0,
                                                         seed=7, subject_seed=21, cameras=8, min_views=3,
                                                         outlier_rate=0.02))
    monkeypatch.setattr(demo, "CALIBRATION_CONFIG", SynthConfig(layout="glove-13", motion="calibration", frames=30,
                                                                rate=20.0, seed=8, subject_seed=21, cameras=8,
                                                                min_views=3))


def test_demo_counts_and_lists_every_file_it_wrote(small_demo, tmp_path, capsys):
    out = tmp_path / "demo"
    out.mkdir()
    (out / "notes.txt").write_text("the user's own file, not written by the demo")
    assert main(["demo", "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    count = int(re.search(r"wrote (\d+) files to", printed).group(1))
    listed = printed.split("wrote ")[1].splitlines()[1:]
    on_disk = sorted(str(p.relative_to(out)) for p in out.rglob("*") if p.is_file() and p.name != "notes.txt")
    assert count == len(listed) == len(on_disk) > 20
    assert [line.strip() for line in listed] == on_disk
    for name in ("hand.png", "session.toml", "summary.json", "results/take/motion.npz",
                 "results/calibration/attachment.npz",
                 "results/take/report.html", "results/calibration/cleaned.c3d", "results/take/solve.manifest.json"):
        assert name in on_disk
    summary = json.loads((out / "summary.json").read_text())
    assert summary["stages_run"] == 11 and summary["stages_up_to_date"] == 0  # the take is not calibrated again
    assert summary["triangulation_median_mm"] < 1.0 and summary["wrong_ids_rejected"] > 0.9
    assert "the session's stages" in printed
    # run again: the same inputs, every stage up to date
    assert main(["demo", "--out", str(out)]) == 0
    again = json.loads((out / "summary.json").read_text())
    assert again["stages_run"] == 0 and again["stages_up_to_date"] == 11


def test_written_since_sees_new_and_rewritten_files_only(tmp_path):
    (tmp_path / "old.txt").write_text("kept")
    (tmp_path / "again.txt").write_text("first")
    before = file_stamps(tmp_path)
    with atomic_output(tmp_path / "again.txt", "w") as fh:
        fh.write("second")
    (tmp_path / "sub").mkdir()
    (tmp_path / "sub" / "new.txt").write_text("new")
    assert written_since(tmp_path, before) == [str(tmp_path / "again.txt"), str(tmp_path / "sub" / "new.txt")]
    assert file_stamps(tmp_path / "missing") == {}


@pytest.fixture(scope="module")
def capture():
    return synthesize(SynthConfig(layout="glove-13", motion="calibration", frames=10, seed=2), progress=False)


def hand_pixels(panel):
    """Pixels of the picture that are neither background nor grey-blue-ish markers: the hand's silhouette."""
    return (np.abs(panel.astype(int) - 255).sum(axis=2) > 30)


def test_picture_puts_the_solve_beside_the_truth(capture):
    alone = demo.picture(capture, frame=5)
    assert alone.shape == (720, 960, 3)
    truth = capture.hand_motion
    same = demo.picture(capture, truth, frame=5)
    assert same.shape == (720, 1920, 3)
    np.testing.assert_array_equal(same[:, :960], alone)
    left, right = hand_pixels(same[60:, :960]), hand_pixels(same[60:, 960:])
    # The solve equal to the truth covers the same pixels (markers and colours aside) ...
    assert (left != right).mean() < 0.01 and left.mean() > 0.05
    # ... and a solve 3 cm off is drawn where it is.
    moved = dataclasses.replace(truth, transl=truth.transl + [0.03, 0.0, 0.0])
    right_moved = hand_pixels(demo.picture(capture, moved, frame=5)[60:, 960:])
    assert (left != right_moved).mean() > 0.03
