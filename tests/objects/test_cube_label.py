"""Labeling a cube's markers in unlabelled points from one labelled frame, scored against the synthetic truth."""

import numpy as np
import pytest

from handcap import HandcapError
from handcap.cli import main
from handcap.core.markers import MarkerSequence
from handcap.io import read_markers, write_markers
from handcap.objects import load_articulated
from handcap.objects.cube_label import label_cube
from handcap.objects.cube_track import track_cube
from handcap.synth.scene import SynthConfig, synthesize, write_capture

CUBE = load_articulated("cube2x2")
NAMES = list(CUBE.marker_names)


@pytest.fixture(scope="module")
def capture():
    return synthesize(SynthConfig(motion="turn-cube", moves="R U' F2 D", seed=6, noise_mm=0.5, rate=100.0,
                                  cameras=8), progress=False)


def _first_whole(capture):
    given = capture.markers.select(NAMES).positions
    counts = np.isfinite(given).all(axis=2).reshape(len(given), 8, 3).sum(axis=2)
    start = int(np.argmax((counts >= 2).all(axis=1)))
    return given[start], start


def test_labels_follow_the_cubies_through_the_moves(capture):
    first, start = _first_whole(capture)
    labels = label_cube(capture.points.frames, CUBE, first, start)
    truth = capture.labeled_points(NAMES).positions[start:]
    got = labels.positions[start:]
    have, real = np.isfinite(got).all(axis=2), np.isfinite(truth).all(axis=2)
    same = have & real & (np.linalg.norm(np.nan_to_num(got - truth), axis=-1) < 1e-9)
    correct = same | (~have & ~real)
    assert correct.mean() > 0.99, correct.mean()
    assert (have & ~same).mean() < 0.005  # wrong labels (ghosts and hand markers taken) are rare
    assert track_cube(labels.positions, CUBE).moves == "R U' F2 D"


def test_a_shuffled_start_labels_the_wrong_cubies(capture):
    """The start decides identity: the same points labelled from a start with two cubies swapped keep them
    swapped (the labeler follows, it does not guess)."""
    first, start = _first_whole(capture)
    swapped = first.copy()
    swapped[[0, 1, 2, 21, 22, 23]] = first[[21, 22, 23, 0, 1, 2]]
    with pytest.raises(HandcapError):  # DBL's and UFR's markers are not where a cubie's fit puts them together
        track_cube(label_cube(capture.points.frames, CUBE, swapped, start).positions, CUBE)


def test_track_object_labels_from_start_and_bad_inputs(capture, tmp_path, capsys):
    write_capture(capture, tmp_path)
    first, start = _first_whole(capture)
    given = np.full((start + 1, 24, 3), np.nan)
    given[start] = first
    write_markers(MarkerSequence(given, NAMES, capture.markers.rate), tmp_path / "start.c3d")
    argv = ["track-object", str(tmp_path / "points.npz"), "--articulated", "cube2x2", "--out",
            str(tmp_path / "cube.npz")]
    assert main([*argv, "--start", str(tmp_path / "start.c3d"), "--labeled", str(tmp_path / "labels.c3d")]) == 0
    assert "R U' F2 D" in capsys.readouterr().out
    assert read_markers(tmp_path / "labels.c3d").names == tuple(NAMES)
    for extra, message in ((["--labeled", str(tmp_path / "x.c3d")], "give --start too"),
                           (["--start", str(tmp_path / "markers.c3d"), "--labeled", str(tmp_path / "points.npz")],
                            "input"),
                           ([], "not a marker .npz")):
        assert main([*argv, *extra]) == 2
        err = capsys.readouterr().err
        assert message in err and len(err.strip().splitlines()) == 1, err
    hidden = given.copy()
    hidden[:, :2] = np.nan
    write_markers(MarkerSequence(hidden, NAMES, capture.markers.rate), tmp_path / "poor.c3d")
    assert main([*argv, "--start", str(tmp_path / "poor.c3d")]) == 2
    assert "no frame shows 2 labelled markers of every cubie" in capsys.readouterr().err
    assert main(["track-object", str(tmp_path / "markers.c3d"), "--markers", "a,b,c", "--start",
                 str(tmp_path / "start.c3d"), "--out", str(tmp_path / "o.npz")]) == 2
