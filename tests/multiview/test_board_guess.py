"""A board never seen: the calibration's error names the spec that finds the board in the recording (the
peers' most common calibration question, "0 boards detected"), on boards drawn here and on real recordings."""

import cv2
import numpy as np
import pytest

from handcap.cli import main
from handcap.multiview.board_guess import board_hint
from handcap.multiview.boards import detect_in_files, parse_board


def _photos(folder, spec, count=4, inverted=False):
    """``count`` views of the board ``spec`` tilted a little differently, on a grey background; image files."""
    board = parse_board(spec)
    if board.kind == "charuco":
        picture = board.opencv_charuco().generateImage((60 * board.columns, 60 * board.rows), marginSize=0)
    else:  # inner corners: one square more each way
        squares = (np.add.outer(np.arange(board.rows + 1), np.arange(board.columns + 1)) % 2) * 255
        picture = np.kron(squares, np.ones((60, 60))).astype(np.uint8)
    if inverted:
        picture = 255 - picture
    h, w = picture.shape
    picture = cv2.copyMakeBorder(picture, 40, 40, 40, 40, cv2.BORDER_CONSTANT, value=255 if not inverted else 0)
    rng = np.random.default_rng(3)
    folder.mkdir()
    paths = []
    for k in range(count):
        corners = np.float32([[0, 0], [w + 79, 0], [w + 79, h + 79], [0, h + 79]])
        moved = corners + rng.uniform(-25, 25, corners.shape).astype(np.float32) + 60
        warp = cv2.getPerspectiveTransform(corners, moved)
        image = cv2.warpPerspective(picture, warp, (w + 200, h + 200), borderValue=110)
        paths.append(folder / f"view{k}.png")
        cv2.imwrite(str(paths[-1]), image)
    return paths


@pytest.mark.parametrize("printed, given, inverted", [
    ("charuco:5x7:0.04", "charuco:7x5:0.04", False),                      # columns and rows swapped
    ("charuco:5x7:0.04", "charuco:5x7:0.04:DICT_5X5_100", False),         # another dictionary
    ("charuco:5x7:0.04", "charuco:5x7:0.04", True),                       # white markers on black
    ("charuco:5x7:0.04", "charuco:8x9:0.04", False),                      # another size: found by the ids seen
    ("charuco:5x7:0.04", "checkerboard:6x8:0.04", False),                 # a ChArUco board as a checkerboard
    ("checkerboard:7x5:0.03", "checkerboard:8x6:0.03", False),            # squares counted, not inner corners
    ("checkerboard:7x5:0.03", "checkerboard:6x4:0.03", False),            # one too few each way
])
def test_the_hint_names_the_spec_that_finds_the_board(tmp_path, printed, given, inverted):
    paths = _photos(tmp_path / "views", printed, inverted=inverted)
    board = parse_board(given)
    assert not detect_in_files(paths, board).found.any()  # the mistake: never seen
    hint = board_hint(paths, board)
    spec = hint.split("(--board ")[1].rstrip(")?")
    assert detect_in_files(paths, parse_board(spec)).found.all(), hint  # the suggestion finds it in every view
    expected = parse_board(printed)
    found = parse_board(spec)
    assert (found.kind, found.columns, found.rows) == (expected.kind, expected.columns, expected.rows), hint
    if found.kind == "charuco":
        assert found.inverted == inverted and found.dictionary.startswith("DICT_4X4"), hint


def test_nothing_like_a_board(tmp_path):
    tmp_path.joinpath("grey").mkdir()
    rng = np.random.default_rng(0)
    for k in range(3):
        cv2.imwrite(str(tmp_path / "grey" / f"{k}.png"), rng.integers(90, 140, (240, 320), dtype=np.uint8))
    hint = board_hint(tmp_path / "grey", parse_board("charuco:5x7:0.04"))
    assert "no ArUco markers of any dictionary" in hint and "--board" not in hint


def test_calibrate_says_it_in_one_line(tmp_path, capsys):
    paths = _photos(tmp_path / "views", "charuco:5x7:0.04", inverted=True)
    assert main(["calibrate", "intrinsics", *map(str, paths), "--board", "charuco:5x7:0.04",
                 "--out", str(tmp_path / "cam.toml")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "is never seen in" in err
    assert "--board charuco:5x7:0.04:0.03:DICT_4X4_1000:inverted)" in err, err
    assert not (tmp_path / "cam.toml").exists()


def test_real_recordings(shared_data):
    videos = shared_data / "calibration/caliscope_4cam"
    hint = board_hint(videos / "cam_0.mp4", parse_board("charuco:5x4:0.054:0.0405"))  # printed 4x5, inverted
    assert "4X4 white on black" in hint and "--board charuco:4x5:0.054:0.0405:DICT_4X4_1000:inverted)" in hint
    left = sorted((shared_data / "calibration/opencv_stereo").glob("left*.jpg"))
    hint = board_hint(left, parse_board("checkerboard:10x7:0.025"))  # 10 x 7 squares: 9 x 6 inner corners
    assert "--board checkerboard:9x6:0.025)" in hint
