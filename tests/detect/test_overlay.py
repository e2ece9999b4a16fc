"""``handcap overlay``: detections drawn over their images, checked pixel by pixel where the marks must be."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from handcap.cli import main
from handcap.core.camera import Camera
from handcap.core.camera_rig import CameraRig
from handcap.core.files import save_npz
from handcap.core.markers import MarkerSequence
from handcap.detect.overlay import HAND_COLOURS, OBJECT_COLOURS, FrameMarks, draw_frame
from handcap.io import write_markers
from handcap.io.camera_formats import write_rig

SIZE = (320, 240)  # width, height
NAMES = np.array(["right:index_middle_r0c0", "right:index_middle_r0c1", "mug:side_r2c3", "ball"])
XY = np.array([[60.0, 50.0], [100.0, 52.0], [200.0, 150.0], [260.0, 200.0]])
BLOCK = np.array([[[120.0, 100.0], [160.0, 100.0], [160.0, 140.0], [120.0, 140.0]]])


def _near(picture, xy, colour, tol=40):
    """Whether the pixel at ``xy`` is within ``tol`` of ``colour`` in every channel."""
    x, y = np.round(xy).astype(int)
    return bool(np.all(np.abs(picture[y, x].astype(int) - np.array(colour)) <= tol))


def test_corners_are_dots_in_their_owners_colour_and_blocks_show_their_underline():
    image = np.full(SIZE[::-1], 200, np.uint8)
    before = image.copy()
    owners = {}
    picture = draw_frame(image, FrameMarks(XY, NAMES, BLOCK, np.array(["7K"])), "cam frame 0", owners)
    assert picture.shape == (*SIZE[::-1], 3) and picture.dtype == np.uint8
    assert np.array_equal(image, before)  # the frame itself is not drawn on
    assert _near(picture, XY[0], HAND_COLOURS["right"]) and _near(picture, XY[1], HAND_COLOURS["right"])
    assert _near(picture, XY[2], OBJECT_COLOURS[0]) and _near(picture, XY[3], OBJECT_COLOURS[1])
    assert owners == {"mug": OBJECT_COLOURS[0], "": OBJECT_COLOURS[1]}  # kept for the next frame
    dimmed = int(200 * 0.75)
    assert _near(picture, (300, 120), (dimmed,) * 3, tol=2)  # away from every mark: the image, dimmed
    # The underlined (bottom) side is drawn thick: white 2 px off it; the top side thin, so not there.
    assert _near(picture, (140, 142), (255, 255, 255), tol=10) and not _near(picture, (140, 98), (255, 255, 255), 30)
    # The tag's text lies on the square above the block (y 60-100), not over its printed glyphs.
    text = np.all(np.abs(picture.astype(int) - np.array([255, 255, 0])) < 30, axis=2)
    rows = np.flatnonzero(text.any(axis=1))
    assert len(rows) and 60 <= rows.min() and rows.max() < 100
    # A tag named from the other cameras, not read, is written in magenta instead.
    named = draw_frame(image, FrameMarks(XY, NAMES, BLOCK, np.array(["7K"]), from_views=np.array([True])))
    magenta = np.all(np.abs(named.astype(int) - np.array([255, 0, 255])) < 30, axis=2)
    assert np.array_equal(magenta, text) and magenta.any()


def _take(tmp_path):
    """Two cameras' folders of two frames, and a detections file of handcap detect's form for them."""
    for camera in ("cam_a", "cam_b"):
        (tmp_path / "images" / camera).mkdir(parents=True)
        for t in range(2):
            cv2.imwrite(str(tmp_path / "images" / camera / f"{t:04d}.png"), np.full(SIZE[::-1], 90, np.uint8))
    rows = [(t, c, m) for t in range(2) for c in range(2) for m in range(3)]
    frame, camera, marker = (np.array(v) for v in zip(*rows))
    xy = XY[marker] + 3.0 * camera[:, None]
    save_npz(tmp_path / "det.npz", {
        "camera_names": np.array(["cam_a", "cam_b"]), "marker_names": NAMES[:3], "frame": frame, "camera": camera,
        "marker": marker, "xy": xy, "score": np.ones(len(frame)), "rate": np.array(30.0), "n_frames": np.array(2),
        "block_text": np.array(["7K", "7K"]), "block_frame": np.array([0, 1]), "block_camera": np.array([1, 1]),
        "block_xy": np.concatenate([BLOCK, BLOCK]), "block_score": np.ones(2)})
    return xy, frame, camera


def test_the_overlay_command_draws_every_camera_and_frame(tmp_path, capsys):
    xy, frame, camera = _take(tmp_path)
    inputs = {p: p.read_bytes() for p in (tmp_path / "images").rglob("*.png")}
    out = tmp_path / "overlay"
    assert main(["overlay", str(tmp_path / "det.npz"), str(tmp_path / "images"), "--out", str(out)]) == 0
    assert "4 pictures of 2 camera(s)" in capsys.readouterr().out
    assert sorted(p.relative_to(out).as_posix() for p in out.rglob("*.jpg")) == [
        "cam_a/000000.jpg", "cam_a/000001.jpg", "cam_b/000000.jpg", "cam_b/000001.jpg"]
    for (t, c), where in zip(zip(frame, camera), xy):
        picture = cv2.imread(str(out / ("cam_a", "cam_b")[c] / f"{t:06d}.jpg"))
        colour = HAND_COLOURS["right"] if np.any(np.all(where - 3.0 * c == XY[:2], axis=1)) else OBJECT_COLOURS[0]
        assert _near(picture, where, colour, tol=50)
    assert all(p.read_bytes() == data for p, data in inputs.items())  # the images are untouched
    # Every other frame.
    assert main(["overlay", str(tmp_path / "det.npz"), str(tmp_path / "images"), "--out", str(tmp_path / "o2"),
                 "--every", "2"]) == 0
    assert len(list((tmp_path / "o2").rglob("*.jpg"))) == 2


def test_reprojected_markers_are_crosses(tmp_path, capsys):
    _take(tmp_path)
    camera = Camera("cam_a", SIZE, [[300.0, 0, 160], [0, 300.0, 120], [0, 0, 1]])
    write_rig(CameraRig([camera, Camera("cam_b", SIZE, camera.matrix, translation=(0.1, 0.0, 0.0))]),
              tmp_path / "cameras.toml")
    point = np.array([-0.3, 0.2, 1.0])  # cam_a sees it at (70, 180)
    hidden = np.array([0.3, -0.2, 1.0])  # at (250, 60), but no camera detected this marker: no cross
    write_markers(MarkerSequence(np.tile([point, hidden], (2, 1, 1)), ("mug:side_r2c3", "mug:lid_r0c0"), 30.0),
                  tmp_path / "m.npz")
    out = tmp_path / "overlay"
    assert main(["overlay", str(tmp_path / "det.npz"), str(tmp_path / "images"), "--out", str(out), "--markers",
                 str(tmp_path / "m.npz"), "--rig", str(tmp_path / "cameras.toml")]) == 0
    picture = cv2.imread(str(out / "cam_a" / "000000.jpg"))
    grey = int(90 * 0.75)
    assert _near(picture, (70, 180), OBJECT_COLOURS[0], tol=60) and _near(picture, (70, 198), (grey,) * 3, tol=10)
    assert _near(picture, (66, 176), OBJECT_COLOURS[0], tol=60)  # an arm of the cross
    assert _near(picture, (250, 60), (grey,) * 3, tol=8) and _near(picture, (246, 56), (grey,) * 3, tol=8)
    capsys.readouterr()


@pytest.mark.parametrize("args, match", [
    (["--every", "0"], "--every 0"),
    (["--markers", "m.npz"], "go together"),
    (["--out", "images/cam_a/o"], "lies in the input"),
    (["--out", ".", "--force"], "or holds it"),
    (["DET=missing.npz"], "missing.npz"),
    (["INPUTS=other"], "none of its cameras"),
])
def test_bad_overlay_arguments_exit_2_with_one_line(tmp_path, capsys, monkeypatch, args, match):
    _take(tmp_path)
    (tmp_path / "other" / "cam_z").mkdir(parents=True)
    cv2.imwrite(str(tmp_path / "other" / "cam_z" / "0.png"), np.zeros((8, 8), np.uint8))
    monkeypatch.chdir(tmp_path)
    det = next((a.split("=")[1] for a in args if a.startswith("DET=")), "det.npz")
    inputs = next((a.split("=")[1] for a in args if a.startswith("INPUTS=")), "images")
    rest = [a for a in args if "=" not in a]
    if "--out" not in rest:
        rest += ["--out", "o"]
    assert main(["overlay", det, inputs, *rest]) == 2
    err = capsys.readouterr().err
    assert match in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "o").exists() and not (tmp_path / "images" / "cam_a" / "o").exists()


def test_detections_of_other_images_are_said_not_to_fit(tmp_path, capsys):
    _take(tmp_path)
    for t in range(2):  # smaller images than the detections were made in
        cv2.imwrite(str(tmp_path / "images" / "cam_b" / f"{t:04d}.png"), np.zeros((40, 40), np.uint8))
    assert main(["overlay", "--out", str(tmp_path / "o"), str(tmp_path / "det.npz"), str(tmp_path / "images")]) == 0
    assert "lie outside their images: are these the images" in capsys.readouterr().err


def test_a_file_with_part_of_the_block_rows_is_one_clear_error(tmp_path, capsys):
    _take(tmp_path)
    data = dict(np.load(tmp_path / "det.npz"))
    del data["block_xy"]
    save_npz(tmp_path / "part.npz", data)
    assert main(["overlay", str(tmp_path / "part.npz"), str(tmp_path / "images"), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert "but not block_xy" in err and len(err.strip().splitlines()) == 1 and not (tmp_path / "o").exists()


def test_hand_keypoints_are_drawn_with_their_bones(tmp_path, capsys):
    from handcap.markerless.keypoints import KEYPOINT_NAMES

    (tmp_path / "images" / "cam_a").mkdir(parents=True)
    cv2.imwrite(str(tmp_path / "images" / "cam_a" / "0000.png"), np.full(SIZE[::-1], 90, np.uint8))
    # A left hand's 21 keypoints: the wrist at (40, 200), each finger a straight chain upwards; the index finger's
    # tip not detected in this frame.
    xy = {"wrist": (40.0, 200.0)}
    for f, finger in enumerate(("thumb", "index", "middle", "ring", "pinky")):
        joints = ("cmc", "mcp", "ip", "tip") if finger == "thumb" else ("mcp", "pip", "dip", "tip")
        for j, joint in enumerate(joints):
            xy[f"{finger}_{joint}"] = (80.0 + 45.0 * f, 160.0 - 35.0 * j)
    names = [f"left:{n}" for n in KEYPOINT_NAMES]
    seen = [k for k, n in enumerate(KEYPOINT_NAMES) if n != "index_tip"]
    save_npz(tmp_path / "kp.npz", {
        "camera_names": np.array(["cam_a"]), "marker_names": np.array(names), "frame": np.zeros(len(seen), int),
        "camera": np.zeros(len(seen), int), "marker": np.array(seen), "xy": np.array([xy[KEYPOINT_NAMES[k]]
                                                                                      for k in seen]),
        "score": np.ones(len(seen)), "rate": np.array(30.0)})
    out = tmp_path / "o"
    assert main(["overlay", str(tmp_path / "kp.npz"), str(tmp_path / "images"), "--out", str(out)]) == 0
    picture = cv2.imread(str(out / "cam_a" / "000000.jpg"))
    left = HAND_COLOURS["left"]
    assert _near(picture, (125.0, 142.5), left, tol=60)  # the middle of the index finger's first bone
    assert _near(picture, (60.0, 180.0), left, tol=60)  # wrist to the thumb's base
    grey = int(90 * 0.75)
    assert _near(picture, (125.0, 72.5), (grey,) * 3, tol=12)  # index dip to its tip: the tip was not detected
    capsys.readouterr()


def test_a_detections_file_whose_frame_selection_is_damaged_is_one_clear_error(tmp_path, capsys):
    """first_frame / frame_step (written by detect --frames / --every) that are no whole numbers: exit 2, one line."""
    (tmp_path / "cam").mkdir()
    cv2.imwrite(str(tmp_path / "cam" / "0.png"), np.zeros((20, 30), np.uint8))
    base = {"camera_names": np.array(["cam"]), "marker_names": np.array(["a"]), "frame": np.zeros(1, np.int64),
            "camera": np.zeros(1, np.int64), "marker": np.zeros(1, np.int64), "xy": np.ones((1, 2)),
            "score": np.ones(1), "rate": np.array(30.0), "n_frames": np.array(1)}
    for bad in ({"first_frame": np.array(["x"])}, {"first_frame": np.array(-3)},
                {"first_frame": np.array(0), "frame_step": np.array([1, 2])}):
        np.savez(tmp_path / "det.npz", **base, **bad)
        assert main(["overlay", str(tmp_path / "det.npz"), str(tmp_path / "cam"), "--out", str(tmp_path / "o")]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and "first_frame, frame_step and n_frames must be whole numbers" in err[0]
