"""Frames of a folder: in the order of the numbers in their names, indexed by those numbers where the cameras share
one frame counter (a dropped frame stays missing), by their order otherwise, and warnings where that may pair
frames of different instants."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from handcap import HandcapError

from handcap.detect.sources import frame_notes, frame_sources


def _folder(root, camera, names):
    """A camera folder of tiny images whose grey level is each file's place in ``names`` (10, 20, ...)."""
    folder = root / camera
    folder.mkdir()
    for k, name in enumerate(names):
        cv2.imwrite(str(folder / name), np.full((4, 5), 10 * (k + 1), np.uint8))
    return folder


def _frames(source):
    """(index, grey level) of each frame."""
    return [(t, int(image[0, 0])) for t, image in source.frames()]


def test_numbers_in_names_are_compared_as_numbers(tmp_path):
    names = [f"img{k}.png" for k in range(1, 13)]  # img1 ... img12, written in that order
    (source,) = frame_sources([_folder(tmp_path, "cam", names)])
    assert [f.name for f in source.files] == names  # not img1, img10, img11, img12, img2, ...
    assert _frames(source) == [(k, 10 * (k + 1)) for k in range(12)]
    assert source.span() == 12 and frame_notes([source]) == []


def test_a_dropped_frame_stays_missing_and_is_a_warning(tmp_path):
    every = [f"frame_{k:04d}.png" for k in range(100, 106)]
    cam_0 = _folder(tmp_path, "cam_0", every)
    cam_1 = _folder(tmp_path, "cam_1", every[:3] + every[4:])  # camera 1 dropped frame 103
    sources = frame_sources([cam_0, cam_1])
    assert [t for t, _ in _frames(sources[0])] == [0, 1, 2, 3, 4, 5]
    # Its frame after the drop is still frame 4, the other camera's frame of the same instant.
    assert _frames(sources[1]) == [(0, 10), (1, 20), (2, 30), (4, 40), (5, 50)]
    assert [s.span() for s in sources] == [6, 6]
    (note,) = frame_notes(sources)
    assert note.startswith("cam_1: 1 frame(s) missing") and "after frame 2" in note


def test_cameras_that_number_apart_are_matched_by_order(tmp_path):
    phone_a = _folder(tmp_path, "phone_a", [f"IMG_{k}.jpg" for k in (4521, 4522, 4523)])
    phone_b = _folder(tmp_path, "phone_b", [f"IMG_{k:04d}.jpg" for k in (32, 33, 34)])
    sources = frame_sources([phone_a, phone_b])
    assert [[t for t, _ in _frames(s)] for s in sources] == [[0, 1, 2], [0, 1, 2]]
    assert frame_notes(sources) == []


def test_cameras_matched_by_order_with_different_counts_are_a_warning(tmp_path):
    a = _folder(tmp_path, "left", ["a.png", "b.png", "c.png"])
    b = _folder(tmp_path, "right", ["a.png", "b.png"])
    sources = frame_sources([a, b])
    assert [s.numbers for s in sources] == [(), ()] and [s.span() for s in sources] == [3, 2]
    (note,) = frame_notes(sources)
    assert "left: 3, right: 2" in note and "matched by their order" in note


def test_a_name_without_a_number_orders_the_folder(tmp_path):
    (source,) = frame_sources([_folder(tmp_path, "cam", ["0003.png", "0007.png", "last.png"])])
    assert _frames(source) == [(0, 10), (1, 20), (2, 30)] and frame_notes([source]) == []


def test_clock_times_in_names_are_no_frame_counter(tmp_path):
    names = [f"IMG_20261128_1015{k:02d}.jpg" for k in (33, 41, 58)] + ["IMG_20261128_101602.jpg"]
    (source,) = frame_sources([_folder(tmp_path, "phone", names)])
    assert source.numbers == () and [t for t, _ in _frames(source)] == [0, 1, 2, 3] and frame_notes([source]) == []


@pytest.mark.parametrize("name, match", [("IMG_0001.HEIC", "HEIC/HEIF photograph"), ("shot.dng", "camera raw file"),
                                         ("notes.txt", "not an image")])
def test_photographs_opencv_cannot_read_say_what_to_do(tmp_path, name, match):
    (tmp_path / "cam").mkdir()
    (tmp_path / "cam" / name).write_bytes(b"\x00" * 64)
    with pytest.raises(HandcapError, match=match):
        frame_sources([tmp_path / "cam" / name])
    with pytest.raises(HandcapError, match="holds no images") as err:
        frame_sources([tmp_path / "cam"])
    assert (match in str(err.value)) == (match != "not an image")
    assert (tmp_path / "cam" / name).read_bytes() == b"\x00" * 64


def _video(path, levels):
    """A short MJPG video whose frames have the grey levels ``levels``."""
    out = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), 10.0, (32, 24), isColor=False)
    for level in levels:
        out.write(np.full((24, 32), level, np.uint8))
    out.release()


def test_a_take_folder_gives_a_camera_to_each_video_and_each_folder_of_images(tmp_path):
    take = tmp_path / "take"
    take.mkdir()
    _video(take / "cam10.avi", [40, 200])
    _video(take / "cam2.avi", [90, 90, 160])
    (take / "notes.txt").write_text("not a camera")
    sources = frame_sources([take])
    assert [(s.camera, s.kind) for s in sources] == [("cam2", "video"), ("cam10", "video")]  # natural order
    assert [[level // 10 for _, level in _frames(s)] for s in sources] == [[9, 9, 16], [4, 20]]  # MJPG: +-a few

    # Pose2Sim's layout: a folder of camera folders, one frame counter; an empty folder beside them is no camera.
    frames = tmp_path / "intrinsics"
    frames.mkdir()
    _folder(frames, "int_cam02_img", [f"cam02_{k:02d}.png" for k in range(1, 7)])
    _folder(frames, "int_cam01_img", [f"cam01_{k:02d}.png" for k in (1, 2, 3, 5, 6)])  # frame 4 dropped
    (frames / "empty").mkdir()
    sources = frame_sources([frames])
    assert [s.camera for s in sources] == ["int_cam01_img", "int_cam02_img"]
    assert [[t for t, _ in _frames(s)] for s in sources] == [[0, 1, 2, 4, 5], [0, 1, 2, 3, 4, 5]]
    assert frame_notes(sources) == ["int_cam01_img: 1 frame(s) missing by its files' numbers (first after frame 2); "
                                    "its other frames keep their numbers"]

    with pytest.raises(HandcapError, match="no videos and no folders of images"):
        frame_sources([frames / "empty"])
    with pytest.raises(HandcapError, match="both camera 'int_cam01_img'"):  # the take and one of its cameras
        frame_sources([frames, frames / "int_cam01_img"])


def test_a_selection_of_frames_is_a_take_of_its_own(tmp_path):
    """--frames A:B --every N: frame k is input frame A + k N, from a folder (its files' numbers, a dropped frame
    still missing) and from a video (the frames between are stepped over), counted as the selection counts them."""
    from handcap.detect.sources import FrameSelection, select_frames

    names = [f"frame_{k:04d}.png" for k in range(100, 112)]
    cam_0 = _folder(tmp_path, "cam_0", names)
    cam_1 = _folder(tmp_path, "cam_1", names[:5] + names[6:])  # camera 1 dropped input frame 5
    _video(tmp_path / "cam_2.avi", [10 * (k + 1) for k in range(12)])
    pick = FrameSelection(2, 11, 3)  # input frames 2, 5, 8
    sources = select_frames(frame_sources([cam_0, cam_1, tmp_path / "cam_2.avi"]), pick)
    assert _frames(sources[0]) == [(0, 30), (1, 60), (2, 90)]
    assert _frames(sources[1]) == [(0, 30), (2, 80)]  # its file of input frame 8 is its 8th: grey 80
    levels = [(t, level) for t, level in _frames(sources[2])]
    assert [t for t, _ in levels] == [0, 1, 2] and all(abs(v - 10 * (3 * t + 3)) <= 3 for t, v in levels)
    assert [s.count() for s in sources] == [3, 2, 3] and [s.span() for s in sources] == [3, 3, 3]
    # Open at the end, every frame from the start: the whole input.
    assert _frames(select_frames(sources[:1], FrameSelection(0, None, 1))[0]) == _frames(frame_sources([cam_0])[0])
    with pytest.raises(HandcapError, match="hold frames 0 to 11 only"):
        select_frames(sources[:2], FrameSelection(20, 30))
    for bad, match in (((-1, 4, 1), "0 <= A < B"), ((4, 4, 1), "0 <= A < B"), ((0, None, 0), "--every 0")):
        with pytest.raises(HandcapError, match=match):
            FrameSelection(*bad)
