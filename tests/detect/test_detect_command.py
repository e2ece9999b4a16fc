"""handcap detect: the file it writes, its inputs (folders, images, videos) and bad input.

The networks here are untrained (their accuracy is measured by benchmarks/detect.py and the training
command); these tests check the plumbing: cameras, frames, the detections contract, errors."""

from __future__ import annotations

import os
import re
import struct
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import cv2
import numpy as np
import pytest

from handcap.cli import main
from handcap.patterns import Pattern, session_pattern
from handcap.detect.corners import CornerNet
from handcap.detect.reader import BlockReader
from handcap.detect.refine import CornerRefiner
from handcap.detect.sources import eight_bit, frame_sources, read_image
from handcap.detect.train import save_net
from handcap import HandcapError


@pytest.fixture(scope="module")
def weights(tmp_path_factory):
    folder = tmp_path_factory.mktemp("weights")
    import torch
    torch.manual_seed(0)
    save_net(CornerNet(), folder / "c.npz")
    save_net(BlockReader(), folder / "r.npz")
    save_net(CornerRefiner(), folder / "f.npz")
    return ["--corner-weights", str(folder / "c.npz"), "--reader-weights", str(folder / "r.npz"),
            "--refiner-weights", str(folder / "f.npz")]


@pytest.fixture()
def frames(tmp_path):
    rng = np.random.default_rng(0)
    for cam in ("cam_0", "cam_1"):
        (tmp_path / cam).mkdir()
        for t in range(2):
            board = np.kron((np.indices((6, 8)).sum(axis=0) % 2) * 200 + 20, np.ones((16, 16))).astype(np.uint8)
            image = np.full((160, 200), 90, np.uint8)
            image[20:116, 30:158] = board
            image = np.clip(image + rng.normal(0, 3, image.shape), 0, 255).astype(np.uint8)
            cv2.imwrite(str(tmp_path / cam / f"{t:06d}.png"), image)
    return tmp_path


def test_detections_file_holds_the_contract(frames, weights, tmp_path, capsys):
    pattern = tmp_path / "pattern.toml"
    session_pattern(("right",), ()).save(pattern)
    out = tmp_path / "det.npz"
    assert main(["detect", str(frames / "cam_0"), str(frames / "cam_1"), "--pattern", str(pattern), "--rate", "30",
                 "--out", str(out), *weights]) == 0
    data = np.load(out)
    assert list(data["camera_names"]) == ["cam_0", "cam_1"] and float(data["rate"]) == 30.0
    assert float(data["pitch"]) == session_pattern(("right",), ()).pitch == 0.005  # triangulate's ruler
    assert len(data["marker_names"]) == len(session_pattern(("right",), ()).corner_names())
    n, b = len(data["frame"]), len(data["block_text"])
    assert data["xy"].shape == (n, 2) and data["camera"].shape == data["marker"].shape == data["score"].shape == (n,)
    assert data["block_xy"].shape == (b, 4, 2) and data["block_frame"].shape == data["block_camera"].shape == (b,)
    assert "4 images from 2 camera(s)" in capsys.readouterr().out


def test_without_a_template_blocks_only_and_a_warning(frames, weights, tmp_path, capsys):
    out = tmp_path / "det.npz"
    assert main(["detect", str(frames / "cam_0" / "000000.png"), "--out", str(out), "--no-refine", "--whole-frames",
                 *weights]) == 0
    data = np.load(out)
    assert len(data["marker_names"]) == 0 and len(data["frame"]) == 0
    err = capsys.readouterr().err
    assert "no template" in err and "20 Hz assumed" in err
    assert any("no template" in w for w in data["warnings"])
    assert "draw alike" not in err  # handcap's alphabet holds no lookalikes
    alike = tmp_path / "alike.npz"
    assert main(["detect", str(frames / "cam_0" / "000000.png"), "--out", str(alike), "--no-refine", "--whole-frames",
                 "--alphabet", "0123456789OIZ", *weights]) == 0
    said = [w for w in np.load(alike)["warnings"] if "draw alike" in w]
    assert len(said) == 1 and "0 and O, 1 and I, 2 and Z, 7 and Z" in said[0]
    assert "draw alike" in capsys.readouterr().err


def _video(path, images, codec="MJPG"):
    """A grey video of ``images`` (each 48 x 64 px) at 25 frames a second; skips where OpenCV writes none."""
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*codec), 25.0, (64, 48), False)
    if not writer.isOpened():
        pytest.skip(f"OpenCV here writes no {codec} video")
    for image in images:
        writer.write(image)
    writer.release()
    return path


def test_videos_are_read_frame_by_frame(tmp_path):
    path = _video(tmp_path / "cam_9.avi", [np.full((48, 64), 40 * k, np.uint8) for k in range(3)])
    (source,) = frame_sources([path])
    frames = list(source.frames())
    assert source.camera == "cam_9" and [t for t, _ in frames] == [0, 1, 2] and frames[0][1].shape == (48, 64)
    assert source.fps() == pytest.approx(25.0)


@pytest.mark.parametrize("make, match", [
    (lambda d: (d / "x.png").write_bytes(b"\x89PNG\r\n\x1a\n" + bytes(20)), "not an image that can be decoded"),
    (lambda d: (d / "x.png").write_bytes(b""), "not an image"),
    (lambda d: (d / "x.txt").write_text("hello"), "not an image"),
    (lambda d: (d / "x.mp4").write_bytes(b"\x00\x00\x00\x18ftypmp42" + bytes(40)), "video"),
    (lambda d: cv2.imwrite(str(d / "x.png"), np.zeros((10, 40000), np.uint8)), "at most 32766 pixels on a side"),
])
def test_bad_image_files_are_one_clear_error(tmp_path, weights, capsys, make, match):
    make(tmp_path)
    target = next(p for p in tmp_path.iterdir() if p.name.startswith("x."))
    assert main(["detect", str(target), "--out", str(tmp_path / "d.npz"), *weights]) == 2
    err = capsys.readouterr().err
    assert match in err and len(err.strip().splitlines()) == 1 and not (tmp_path / "d.npz").exists()


def test_truncated_png_in_a_folder(frames, weights, tmp_path, capsys):
    good = (frames / "cam_0" / "000001.png").read_bytes()
    (frames / "cam_0" / "000001.png").write_bytes(good[: len(good) // 3])
    assert main(["detect", str(frames / "cam_0"), "--out", str(tmp_path / "d.npz"), *weights]) == 2
    assert "000001.png" in capsys.readouterr().err


def test_other_bad_input(frames, weights, tmp_path, capsys, monkeypatch):
    import handcap.parallel as parallel
    monkeypatch.setattr(parallel, "_CONNECT_TIMEOUT", "1s")  # refused at once; Dask tries again until then
    (tmp_path / "empty").mkdir()
    rig = tmp_path / "rig.toml"
    rig.write_text('[cam_a]\nname = "cam_a"\nsize = [200, 160]\nmatrix = [[100, 0, 100], [0, 100, 80], [0, 0, 1]]\n'
                   'distortions = [0, 0, 0, 0, 0]\nrotation = [0, 0, 0]\ntranslation = [0, 0, 1]\n')
    both = tmp_path / "both.toml"
    both.write_text(rig.read_text().replace("cam_a", "cam_0") + "\n"
                    + rig.read_text().replace("cam_a", "cam_1")
                    .replace("translation = [0, 0, 1]", "translation = [0.1, 0, 1]"))
    pattern = tmp_path / "pattern.toml"
    session_pattern(("right",), ()).save(pattern)
    cases = [
        (["detect", str(tmp_path / "empty"), "--out", str(tmp_path / "d.npz")], "holds no images"),
        (["detect", str(tmp_path / "nowhere"), "--out", str(tmp_path / "d.npz")], "no such file"),
        (["detect", str(frames / "cam_0"), "--out", str(tmp_path / "d.txt")], ".npz"),
        (["detect", str(frames / "cam_0"), "--rig", str(rig), "--out", str(tmp_path / "d.npz")], "no camera 'cam_0'"),
        (["detect", str(frames / "cam_0"), "--pattern", str(pattern), "--alphabet", "0123", "--out",
          str(tmp_path / "d.npz")], "lacks glyphs"),
        (["detect", str(frames / "cam_0"), "--alphabet", "0123\u00e9", "--out", str(tmp_path / "d.npz")], "knows no"),
        (["detect", str(frames / "cam_0"), "--threshold", "1.5", "--out", str(tmp_path / "d.npz")], "between 0 and 1"),
        (["detect", str(frames / "cam_0"), "--workers", "0", "--out", str(tmp_path / "d.npz")], "--workers 0: give"),
        (["detect", str(frames / "cam_0"), str(frames / "cam_1"), "--scheduler", "tcp://127.0.0.1:9", "--out",
          str(tmp_path / "d.npz")], "cannot reach the Dask scheduler"),
        # Offsets time the other cameras' views for the naming: they need the rig and the template, and good offsets.
        (["detect", str(frames / "cam_0"), "--sync", "auto", "--out", str(tmp_path / "d.npz")], "needs --rig and"),
        (["detect", str(frames / "cam_0"), str(frames / "cam_1"), "--rig", str(both), "--pattern", str(pattern),
          "--sync", "auto", "--sync", "cam_1=2", "--out", str(tmp_path / "d.npz")], "give it alone"),
        (["detect", str(frames / "cam_0"), str(frames / "cam_1"), "--rig", str(both), "--pattern", str(pattern),
          "--sync", "cam_9=2", "--out", str(tmp_path / "d.npz")], "which the inputs lack"),
        (["detect", str(frames / "cam_0"), str(frames / "cam_1"), "--rig", str(both), "--pattern", str(pattern),
          "--sync", "auto", "--max-offset", "0", "--out", str(tmp_path / "d.npz")], "--max-offset 0"),
        (["detect", str(frames / "cam_0"), str(frames / "cam_1"), "--rig", str(both), "--pattern", str(pattern),
          "--sync", "cam_1 2", "--out", str(tmp_path / "d.npz")], "CAMERA=FRAMES"),
        (["detect", str(frames / "cam_0"), str(frames / "cam_1"), "--rig", str(both), "--pattern", str(pattern),
          "--no-views", "--sync", "cam_1=2", "--out", str(tmp_path / "d.npz")], "not --no-views"),
        # An input image as the output: refused (outputs are .npz) and left as it was.
        (["detect", str(frames / "cam_0" / "000000.png"), "--out", str(frames / "cam_0" / "000000.png")], ".npz"),
    ]
    before = (frames / "cam_0" / "000000.png").read_bytes()
    for args, match in cases:
        assert main(args + weights) == 2, args
        err = capsys.readouterr().err
        assert match in err and len(err.strip().splitlines()) == 1, (args, err)
    assert (frames / "cam_0" / "000000.png").read_bytes() == before


def test_read_image_converts_colour_and_16_bit(tmp_path):
    colour = np.zeros((10, 12, 3), np.uint8)
    colour[..., 2] = 255
    cv2.imwrite(str(tmp_path / "c.png"), colour)
    cv2.imwrite(str(tmp_path / "d.png"), np.full((10, 12), 65535, np.uint16))
    assert read_image(tmp_path / "c.png").shape == (10, 12) and read_image(tmp_path / "c.png")[0, 0] == 76
    assert read_image(tmp_path / "d.png").dtype == np.uint8 and read_image(tmp_path / "d.png")[0, 0] == 255
    with pytest.raises(HandcapError, match="no such image"):
        read_image(tmp_path / "none.png")


def test_a_machine_vision_cameras_10_and_12_bit_images_and_float_images_keep_their_grey_levels(tmp_path):
    # 10- and 12-bit pixels in a 16-bit file (Mono10 and Mono12) fill 0..1023 and 0..4095 only: read as 16-bit they
    # would come out in 4 or 16 grey levels, where a square's glyphs fall apart.
    levels = np.random.default_rng(0).integers(0, 256, (20, 30)).astype(np.uint8)
    deep = levels.astype(np.uint16)
    for name, pixels in (("mono10.png", deep * 4 + 1), ("mono12.png", deep * 16), ("full.png", deep * 257),
                         ("unit.tiff", levels / np.float32(255)), ("scaled.tiff", levels.astype(np.float32))):
        cv2.imwrite(str(tmp_path / name), pixels)
        got = read_image(tmp_path / name)
        assert got.dtype == np.uint8 and np.abs(got.astype(int) - levels).max() <= 1, name
    spoiled = (levels / np.float32(255)).copy()
    spoiled[0, :3] = (np.nan, np.inf, -np.inf)
    cv2.imwrite(str(tmp_path / "nan.tiff"), spoiled)
    got = read_image(tmp_path / "nan.tiff")
    assert (got[0, :3] == 0).all() and np.abs(got[1:].astype(int) - levels[1:]).max() <= 1
    assert np.array_equal(eight_bit(levels), levels)


def test_the_shipped_networks_say_how_good_they_measured(frames, tmp_path, capsys):
    out = tmp_path / "det.npz"
    assert main(["detect", str(frames / "cam_0"), "--rate", "20", "--out", str(out)]) == 0
    err = capsys.readouterr().err
    assert "short of handcap's targets" in err and "corners.npz: corners: recall" in err
    assert "reader on a font it never saw" in err and "checker.npz: checker: gate" in err
    assert any("short of handcap's targets" in w for w in np.load(out)["warnings"])


def test_the_block_checker_can_be_turned_off_or_replaced(frames, weights, tmp_path, capsys):
    pattern = tmp_path / "pattern.toml"
    session_pattern(("right",), ()).save(pattern)
    common = [str(frames / "cam_0"), "--pattern", str(pattern), "--rate", "30", "--whole-frames", *weights]
    assert main(["detect", *common, "--no-checker", "--out", str(tmp_path / "ruled.npz")]) == 0
    # Weights that are not a checker's, or none where they are said to be: one clear line, exit 2, no file.
    for bad, match in ((weights[1], "holds a CornerNet, not a BlockChecker"), (str(tmp_path / "none.npz"),
                                                                              "no BlockChecker weights there")):
        capsys.readouterr()
        assert main(["detect", *common, "--checker-weights", bad, "--out", str(tmp_path / "bad.npz")]) == 2
        assert match in capsys.readouterr().err and not (tmp_path / "bad.npz").exists()


def _with_orientation(jpeg: bytes, orientation: int) -> bytes:
    """A JPEG file's bytes with an EXIF block that holds only the orientation tag (as a phone writes it)."""
    tiff = b"MM\x00\x2a" + struct.pack(">IH", 8, 1) + struct.pack(">HHIHH", 0x0112, 3, 1, orientation, 0) + bytes(4)
    app1 = b"Exif\x00\x00" + tiff
    return jpeg[:2] + b"\xff\xe1" + struct.pack(">H", len(app1) + 2) + app1 + jpeg[2:]


@pytest.mark.parametrize("orientation, turned", [(1, lambda a: a), (3, lambda a: a[::-1, ::-1]),
                                                 (6, lambda a: np.rot90(a, -1)), (8, lambda a: np.rot90(a, 1))])
def test_photographs_are_turned_upright_as_their_exif_says(tmp_path, orientation, turned):
    stored = np.full((40, 100), 30, np.uint8)
    stored[:10, :20] = 230  # a bright block at the stored image's top left
    ok, code = cv2.imencode(".jpg", stored, [cv2.IMWRITE_JPEG_QUALITY, 100])
    path = tmp_path / "photo.jpg"
    path.write_bytes(_with_orientation(code.tobytes(), orientation))
    grey, colour = read_image(path), read_image(path, colour=True)
    expected = turned(stored)
    assert grey.shape == expected.shape and colour.shape == (*expected.shape, 3)
    assert np.abs(grey.astype(int) - expected).max() < 12  # JPEG's error only: the block where the viewer shows it
    # The calibration board's images are read by cv2.imread: the same upright pixels, so the rig and the
    # detections agree.
    np.testing.assert_array_equal(grey, cv2.imread(str(path), cv2.IMREAD_GRAYSCALE))


def test_a_video_that_ends_before_its_header_says_is_a_stored_warning(weights, tmp_path, capsys):
    for name in ("whole", "cut"):
        (tmp_path / name).mkdir()
    rng = np.random.default_rng(0)
    whole = _video(tmp_path / "whole" / "cam_0.avi", rng.integers(0, 255, (40, 48, 64), dtype=np.uint8))
    data = whole.read_bytes()
    cut = tmp_path / "cut" / "cam_0.avi"
    cut.write_bytes(data[:int(len(data) * 0.55)])
    said = {}
    for name, path in (("whole", whole), ("cut", cut)):
        out = tmp_path / f"{name}.npz"
        assert main(["detect", str(path), "--out", str(out), "--no-refine", *weights]) == 0
        said[name] = ([w for w in capsys.readouterr().err.splitlines() if "ended after" in w],
                      [w for w in np.load(out)["warnings"] if "ended after" in w])
    assert said["whole"] == ([], [])
    read = int(re.search(r"ended after (\d+) of the 40 frames", said["cut"][1][0]).group(1))
    assert 10 <= read < 30 and len(said["cut"][0]) == 1 and "cam_0.avi" in said["cut"][1][0]


def test_ffmpegs_own_messages_do_not_join_the_one_line_of_an_error(weights, tmp_path):
    whole = _video(tmp_path / "cam_0.mp4", [np.full((48, 64), 20 * k, np.uint8) for k in range(10)], "mp4v")
    cut = tmp_path / "cut.mp4"
    cut.write_bytes(whole.read_bytes()[:200])  # no index ("moov atom not found", says FFmpeg)
    done = subprocess.run([sys.executable, "-m", "handcap.cli", "detect", str(cut), "--out", str(tmp_path / "d.npz"),
                           *weights], capture_output=True, text=True, timeout=300,
                          env={k: v for k, v in os.environ.items() if k != "OPENCV_FFMPEG_LOGLEVEL"})
    assert done.returncode == 2
    assert done.stderr.strip().splitlines() == [f"handcap detect: error: {cut}: cannot be opened as a video "
                                                "(unknown format or damaged file)"]


def test_noisy_images_are_denoised_and_a_stored_warning_says_so(frames, weights, tmp_path, capsys):
    rng = np.random.default_rng(1)
    for path in sorted(frames.glob("cam_1/*.png")):
        image = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)
        cv2.imwrite(str(path), np.clip(image + rng.normal(0, 15, image.shape), 0, 255).astype(np.uint8))
    said = {}
    for flag in ((), ("--no-denoise",)):
        out = tmp_path / f"d{len(flag)}.npz"
        assert main(["detect", str(frames / "cam_0"), str(frames / "cam_1"), "--out", str(out), *flag, *weights]) == 0
        said[flag] = [w for w in np.load(out)["warnings"] if "sensor noise" in w]
        assert said[flag] == [line.split("warning: ", 1)[1] for line in capsys.readouterr().err.splitlines()
                              if "sensor noise" in line]
    # cam_0's frames (noise of 3 grey levels) are searched as they are; cam_1's (15) are denoised first.
    assert len(said[()]) == 1 and said[()][0].startswith("2 of 4 images") and "denoised first" in said[()][0]
    assert len(said[("--no-denoise",)]) == 1 and "not denoised" in said[("--no-denoise",)][0]


def test_a_dropped_frame_is_a_stored_warning_and_keeps_the_frame_count(frames, weights, tmp_path, capsys):
    image = cv2.imread(str(frames / "cam_0" / "000000.png"))
    for cam, numbers in (("a", (7, 8, 9)), ("b", (7, 9))):  # camera b dropped frame 8 of the rig's counter
        (tmp_path / cam).mkdir()
        for k in numbers:
            cv2.imwrite(str(tmp_path / cam / f"shot_{k}.png"), image)
    out = tmp_path / "det.npz"
    assert main(["detect", str(tmp_path / "a"), str(tmp_path / "b"), "--out", str(out), "--no-refine",
                 "--whole-frames", *weights]) == 0
    data = np.load(out)
    assert int(data["n_frames"]) == 3
    assert "b: 1 frame(s) missing" in capsys.readouterr().err
    assert any("b: 1 frame(s) missing" in w for w in data["warnings"])
    assert set(data["block_frame"][data["block_camera"] == 1].tolist()) <= {0, 2}


@pytest.mark.parametrize("size, match", [("[200, 160]", None), ("[160, 200]", "turned a quarter"),
                                         ("[400, 320]", "scaled or cropped")])
def test_images_of_another_size_than_the_rigs_are_refused(frames, weights, tmp_path, capsys, size, match):
    rig = tmp_path / "rig.toml"
    rig.write_text("".join(f'[{cam}]\nname = "{cam}"\nsize = {size}\n'
                           'matrix = [[100, 0, 100], [0, 100, 80], [0, 0, 1]]\n'
                           f'distortions = [0, 0, 0, 0, 0]\nrotation = [0, 0, 0]\ntranslation = [{k}, 0, 1]\n'
                           for k, cam in enumerate(("cam_0", "cam_1"))))
    out = tmp_path / "d.npz"
    code = main(["detect", str(frames / "cam_0"), str(frames / "cam_1"), "--rig", str(rig), "--out", str(out),
                 "--no-refine", "--whole-frames", *weights])
    err = capsys.readouterr().err
    if match is None:
        assert code == 0 and out.is_file()
    else:
        assert code == 2 and not out.exists()
        assert match in err and "cam_0 frame 0: the image is 200x160 px" in err and len(err.strip().splitlines()) == 1


def test_mirrored_photographs_read_nothing_and_say_so(tmp_path, capsys):
    from handcap.detect.scenes import PageMaker
    from handcap.synth.pages import PageLook

    maker = PageMaker(5, look=PageLook(square_px=(24.0, 30.0), tilt_deg=(0.0, 15.0), occluders=(0, 0),
                                       size=(640, 480), glint=0.0))
    pattern = tmp_path / "pattern.toml"
    session_pattern().save(pattern)
    image = maker.scene().image
    for name, pixels in (("plain", image), ("selfie", image[:, ::-1]), ("negative", 255 - image)):
        (tmp_path / name).mkdir()
        cv2.imwrite(str(tmp_path / name / "0.png"), pixels)
        assert main(["detect", str(tmp_path / name), "--pattern", str(pattern), "--out", str(tmp_path / f"{name}.npz"),
                     "--rate", "30"]) == 0
    data = {name: np.load(tmp_path / f"{name}.npz") for name in ("plain", "selfie", "negative")}
    assert len(data["plain"]["block_text"]) > 20 and len(data["selfie"]["block_text"]) == 0  # none read wrong
    assert len(data["negative"]["block_text"]) == 0
    (warning,) = [w for w in data["selfie"]["warnings"] if "no tag was read" in w]
    assert "look mirrored" in warning and "flip them" in warning
    (warning,) = [w for w in data["negative"]["warnings"] if "no tag was read" in w]
    assert "look inverted" in warning and "invert them" in warning
    assert not any("mirrored" in w or "inverted" in w or "do not fit" in w for w in data["plain"]["warnings"])
    # Another template over the same patches (the same tags, shuffled among the squares): said, not silent.
    whole = session_pattern()
    tags = [t for p in whole.patches for row in p.tags for t in row if t]
    swap = dict(zip(tags, np.random.default_rng(0).permutation(tags)))
    other = Pattern(tuple(replace(p, tags=tuple(tuple(swap.get(t, t) for t in row) for row in p.tags))
                          for p in whole.patches), whole.alphabet, whole.pitch)
    other.save(tmp_path / "other.toml")
    assert main(["detect", str(tmp_path / "plain"), "--pattern", str(tmp_path / "other.toml"), "--rate", "30",
                 "--out", str(tmp_path / "other.npz")]) == 0
    (warning,) = [w for w in np.load(tmp_path / "other.npz")["warnings"] if "do not fit" in w]
    assert "other.toml the pattern.toml these patches were printed from" in warning
    assert "do not fit" in capsys.readouterr().err


def test_an_object_added_to_a_printed_session_is_named_with_the_extended_template(tmp_path, capsys):
    """`handcap pattern --extend` gives a lab's own object tags the printed hand patches do not use: photographs
    of both are named right with the new template, and the object's tags do not fit the old one (a warning)."""
    from handcap.detect.scenes import PageMaker
    from handcap.synth.pages import PageLook

    first, later = tmp_path / "first", tmp_path / "later"
    assert main(["pattern", "--out", str(first), "--hands", "right", "--objects", "none", "--no-svg"]) == 0
    assert main(["pattern", "--out", str(later), "--extend", str(first / "pattern.toml"), "--object",
                 "mug=side:3x8,lid:3x3", "--no-svg"]) == 0
    whole = Pattern.load(later / "pattern.toml")
    sheet = Pattern((whole.patch("right:index_middle"), whole.patch("mug:side"), whole.patch("mug:lid")),
                    whole.alphabet, whole.pitch)
    maker = PageMaker(8, pattern=sheet, look=PageLook(square_px=(22.0, 28.0), tilt_deg=(0.0, 15.0), occluders=(0, 0),
                                                      size=(640, 480), glint=0.0))
    (tmp_path / "cam").mkdir()
    scenes = [maker.scene() for _ in range(3)]
    for k, scene in enumerate(scenes):
        cv2.imwrite(str(tmp_path / "cam" / f"{k}.png"), scene.image)
    runs = {}
    for name, template in (("extended", later), ("printed", first)):
        out = tmp_path / f"{name}.npz"
        assert main(["detect", str(tmp_path / "cam"), "--pattern", str(template / "pattern.toml"), "--rate", "30",
                     "--response", "linear", "--out", str(out)]) == 0
        runs[name] = np.load(out)
    data = runs["extended"]
    names = data["marker_names"][data["marker"]]
    mug = np.char.startswith(names, "mug:")
    truth = [dict(zip(s.corner_names, s.corners)) for s in scenes]
    visible = sum(n.startswith("mug:") for s in scenes for n in s.corner_names)
    assert mug.sum() > 0.6 * visible and (~mug).sum() > 0.6 * (sum(len(s.corner_names) for s in scenes) - visible)
    error = [np.linalg.norm(xy - truth[t][n]) for t, n, xy in zip(data["frame"], names, data["xy"])]
    assert max(error) < 1.0  # every corner named where the truth puts that name
    old = runs["printed"]
    assert not np.char.startswith(old["marker_names"][old["marker"]], "mug:").any()
    (warning,) = [w for w in old["warnings"] if "do not fit" in w]
    assert "first/pattern.toml the pattern.toml these patches were printed from" in warning
    assert not any("do not fit" in w for w in data["warnings"])
    capsys.readouterr()


def test_patches_printed_twice_are_said_to_be(tmp_path, capsys):
    """Two copies of a patch in view (a page printed twice, or two sessions' patches sharing tags): every tag is read
    at two white squares of one image. The vote drops them, and a warning says why; one copy reads as before."""
    from handcap.detect.scenes import PageMaker
    from handcap.synth.pages import PageLook

    whole = session_pattern(("right",), ())
    sheet = Pattern((whole.patch("right:dorsum_proximal"),), whole.alphabet, whole.pitch)
    whole.save(tmp_path / "pattern.toml")
    maker = PageMaker(6, pattern=sheet, look=PageLook(square_px=(22.0, 26.0), tilt_deg=(0.0, 10.0), curl=(0.0, 0.0),
                                                      occluders=(0, 0), size=(480, 400), glint=0.0))
    one, other = maker.scene().image, maker.scene().image
    h = min(len(one), len(other))
    for name, image in (("once", one), ("twice", np.hstack([one[:h], other[:h]]))):
        (tmp_path / name).mkdir()
        cv2.imwrite(str(tmp_path / name / "0.png"), image)
    runs = {}
    for name, extra in (("once", ["--pattern"]), ("twice", ["--pattern"]), ("free", [])):
        out = tmp_path / f"{name}.npz"
        folder = tmp_path / ("once" if name == "once" else "twice")
        assert main(["detect", str(folder), *extra, *([str(tmp_path / "pattern.toml")] if extra else []), "--rate",
                     "30", "--response", "linear", "--out", str(out)]) == 0
        runs[name] = np.load(out)
    said = {k: [w for w in v["warnings"] if "read at another white square" in w] for k, v in runs.items()}
    assert said["once"] == [] and len(runs["once"]["block_text"]) > 15
    (warning,) = said["twice"]
    assert "patches printed twice" in warning and "the vote drops such tags" in warning
    assert len(runs["twice"]["block_text"]) < len(runs["once"]["block_text"])  # two copies: fewer kept than one
    (warning,) = said["free"]
    assert "both are reported" in warning
    texts = runs["free"]["block_text"].tolist()
    assert sum(texts.count(t) == 2 for t in set(texts)) > 10  # without a template each copy's tag is reported
    capsys.readouterr()


def test_a_sheet_read_unsurely_without_a_template_says_so(tmp_path, capsys):
    """Another generator's sheet (DexterCap's glyphs and layout, a font the reader never saw), read without a
    template: the reader sees tags in most squares but reports few, and the warning says so with its counts;
    handcap's own page reads surely and gets no such warning."""
    from handcap.detect.scenes import PageMaker, SheetMaker
    from handcap.patterns.alphabet import DEXTERCAP_ALPHABET
    from handcap.patterns.glyphs import GlyphLayout
    from handcap.synth.pages import PageLook

    look = PageLook(square_px=(16.0, 22.0), tilt_deg=(0.0, 15.0), occluders=(0, 0), size=(640, 480), glint=0.0)
    theirs = GlyphLayout(cap_height=0.43, glyph_top=0.27, underline_top=0.8, underline_thickness=0.083, gap=0.067,
                         underline_span=(0.1, 0.5))
    noto = "/usr/share/fonts/truetype/noto/NotoSansMono-Bold.ttf"
    sheets = {"theirs": SheetMaker(3, DEXTERCAP_ALPHABET, font=noto if Path(noto).is_file() else None,
                                   layout=theirs, look=look), "own": PageMaker(3, look=look)}
    found = {}
    for name, maker in sheets.items():
        (tmp_path / name).mkdir()
        cv2.imwrite(str(tmp_path / name / "0.png"), maker.scene().image)
        # The reader is not adapted to the take here (tests/detect/test_adapt.py does that): the warning's counts.
        alphabet = ["--alphabet", DEXTERCAP_ALPHABET, "--adapt-steps", "0"] if name == "theirs" else []
        assert main(["detect", str(tmp_path / name), "--out", str(tmp_path / f"{name}.npz"), "--rate", "30",
                     *alphabet]) == 0
        data = np.load(tmp_path / f"{name}.npz")
        found[name] = len(data["block_text"]), [w for w in data["warnings"] if "white squares" in w]
    kept, (warning,) = found["theirs"]
    seen = int(re.search(r"saw tags in (\d+) white squares and reports (\d+) ", warning).group(1))
    assert f"reports {kept} (" in warning and seen >= 20 and kept < 0.5 * seen and "--pattern" in warning
    assert "white squares" in capsys.readouterr().err
    assert found["own"][0] > 30 and found["own"][1] == []


def test_another_generators_patches_read_through_their_imported_template(tmp_path, capsys):
    """Another generator's sheet (DexterCap's 22 glyphs and glyph layout, a font the reader never saw), cut into
    strips as its template lists them: its template imported (``pattern --import``) lets the vote read far more of
    the tags than the reader alone, none wrong, and names the strips' corners where the truth has them."""
    import json

    from handcap.detect.evaluation import tag_is_right
    from handcap.detect.scenes import SheetMaker, renamed
    from handcap.patterns.glyphs import GlyphLayout
    from handcap.synth.pages import PageLook

    alphabet = "0123456789ACEHNPRSTVXZ"
    theirs = GlyphLayout(cap_height=0.43, glyph_top=0.27, underline_top=0.8, underline_thickness=0.083, gap=0.067,
                         underline_span=(0.1, 0.5))
    noto = "/usr/share/fonts/truetype/noto/NotoSansMono-Bold.ttf"
    sheet = SheetMaker(5, alphabet, font=noto if Path(noto).is_file() else None, layout=theirs,
                       look=PageLook(square_px=(16.0, 22.0), tilt_deg=(0.0, 15.0), occluders=(0, 0), size=(640, 480),
                                     glint=0.0))
    grids, rename = sheet.strips()
    (tmp_path / "theirs.json").write_text(json.dumps(grids))
    assert main(["pattern", "--import", str(tmp_path / "theirs.json"), "--owner", "*=sheet", "--alphabet", alphabet,
                 "--out", str(tmp_path / "template")]) == 0
    template = Pattern.load(tmp_path / "template" / "pattern.toml")
    scenes = [renamed(sheet.scene(), rename) for _ in range(3)]
    (tmp_path / "photos").mkdir()
    for k, scene in enumerate(scenes):
        cv2.imwrite(str(tmp_path / "photos" / f"{k}.png"), scene.image)
    read = {}
    for name, args in (("alone", ["--alphabet", alphabet, "--adapt-steps", "0"]),
                       ("template", ["--pattern", str(tmp_path / "template" / "pattern.toml")])):
        out = tmp_path / f"{name}.npz"
        assert main(["detect", str(tmp_path / "photos"), "--out", str(out), "--rate", "30", *args]) == 0
        data = np.load(out)
        right = wrong = 0
        for k, scene in enumerate(scenes):
            here = data["block_frame"] == k
            for tag, xy in zip(data["block_text"][here], data["block_xy"][here]):
                # Right where the template's corners of that tag lie there (one at the image's edge, too).
                ok = tag_is_right(template, str(tag), xy, scene.projected)
                right, wrong = right + (ok and str(tag) in scene.block_text), wrong + (not ok)
            if name == "template":
                named = data["frame"] == k
                assert named.sum() > 50
                for index, xy in zip(data["marker"][named], data["xy"][named]):
                    assert np.linalg.norm(scene.projected[str(data["marker_names"][index])] - xy) < 1.5
        read[name] = right, wrong
    visible = sum(len(s.block_text) for s in scenes)
    assert read["template"][1] == 0 and read["alone"][1] == 0
    assert read["template"][0] >= 0.5 * visible and read["template"][0] >= 1.5 * read["alone"][0]


def test_a_selection_of_frames_reads_those_frames_as_a_take_of_their_own(tmp_path, capsys):
    """detect --frames 1:6 --every 2 reads input frames 1, 3 and 5 as frames 0, 1 and 2 at half the rate: the
    same tags at the same pixels as a run over every frame gives them there; overlay draws those three frames."""
    from handcap.detect.scenes import PageMaker
    from handcap.synth.pages import PageLook

    maker = PageMaker(4, look=PageLook(square_px=(16.0, 22.0), tilt_deg=(0.0, 15.0), occluders=(0, 0),
                                       size=(480, 360), glint=0.0))
    (tmp_path / "cam").mkdir()
    for t in range(6):
        cv2.imwrite(str(tmp_path / "cam" / f"{t:04d}.png"), maker.scene().image)
    runs = {}
    for name, extra in (("all", []), ("some", ["--frames", "1:6", "--every", "2"])):
        out = tmp_path / f"{name}.npz"
        assert main(["detect", str(tmp_path / "cam"), "--out", str(out), "--rate", "30", "--whole-frames",
                     *extra]) == 0
        runs[name] = dict(np.load(out))
    some, every = runs["some"], runs["all"]
    assert float(some["rate"]) == 15.0 and int(some["first_frame"]) == 1 and int(some["frame_step"]) == 2
    assert "first_frame" not in every and int(some["n_frames"]) == 3
    assert "input frames 1:6 every 2: frame k of some.npz is input frame 1 + 2 k, at 15 Hz" in capsys.readouterr().out
    for k in range(3):
        mine = sorted(zip(some["block_text"][some["block_frame"] == k].tolist(),
                          np.round(some["block_xy"][some["block_frame"] == k], 6).tolist()))
        theirs = sorted(zip(every["block_text"][every["block_frame"] == 1 + 2 * k].tolist(),
                            np.round(every["block_xy"][every["block_frame"] == 1 + 2 * k], 6).tolist()))
        assert len(mine) > 5 and mine == theirs
    assert main(["overlay", str(tmp_path / "some.npz"), str(tmp_path / "cam"), "--out", str(tmp_path / "look")]) == 0
    assert sorted(p.name for p in (tmp_path / "look" / "cam").iterdir()) == ["000000.jpg", "000001.jpg", "000002.jpg"]
    assert main(["detect", str(tmp_path / "cam"), "--out", str(tmp_path / "bad.npz"), "--frames", "7:9"]) == 2
    assert "hold frames 0 to 5 only" in capsys.readouterr().err and not (tmp_path / "bad.npz").exists()
