import os
import tomllib

import numpy as np
import pytest

from handcap.core.cameras import Camera, CameraRig
from handcap.core.errors import HandcapError
from handcap.io.cameras import CAMERA_KEYS, read_cameras_toml, write_cameras_toml

# What aniposelib's CameraGroup.dump writes (through the ``toml`` package 0.10.2),
# metadata table included: two cameras named "A" and "B", translations in metres.
ANIPOSE = """\
[cam_0]
name = "A"
size = [ 2448, 2048,]
matrix = [ [ 2212.5, 0.0, 1224.25,], [ 0.0, 2213.75, 1019.5,], [ 0.0, 0.0, 1.0,],]
distortions = [ -0.11, 0.07, 0.001, -0.0005, -0.01,]
rotation = [ 0.1, -0.2, 0.3,]
translation = [ 0.05, -0.1, 1.5,]

[cam_1]
name = "B"
size = [ 1920, 1080,]
matrix = [ [ 1500.0, 0.0, 960.0,], [ 0.0, 1500.0, 540.0,], [ 0.0, 0.0, 1.0,],]
distortions = [ 0.0, 0.0, 0.0, 0.0, 0.0,]
rotation = [ 0.0, 0.0, 0.0,]
translation = [ 0.0, 0.0, 2.0,]

[metadata]
adjusted = false
error = 0.41
"""


def awkward_rig():
    """Cameras whose numbers need all 17 significant digits, tiny values and -0.0."""
    rng = np.random.default_rng(0)
    cameras = []
    for i in range(3):
        matrix = np.array([[2000 + rng.uniform(), 0, 1224 + rng.uniform()], [0, 2000 + 1 / 3, 1024 / 3], [0, 0, 1]])
        distortions = rng.normal(scale=0.05, size=5) * [1, 1, 1e-15, 1, -0.0]
        cameras.append(Camera(f"cam {i} \"left\"", (2448, 2048), matrix, distortions, rng.normal(size=3),
                              rng.normal(size=3)))
    return CameraRig(cameras)


def test_round_trip_is_exact(tmp_path):
    rig = awkward_rig()
    write_cameras_toml(rig, tmp_path / "rig.toml")
    back = read_cameras_toml(tmp_path / "rig.toml")
    assert back == rig
    for a, b in zip(rig, back):
        for key in ("matrix", "distortions", "rotation", "translation"):
            assert getattr(a, key).tobytes() == getattr(b, key).tobytes()  # bit for bit, -0.0 included
    assert os.listdir(tmp_path) == ["rig.toml"]  # no temporary file left behind


def test_identical_rigs_write_identical_bytes(tmp_path):
    write_cameras_toml(awkward_rig(), tmp_path / "a.toml")
    awkward_rig().save(tmp_path / "b.toml")
    assert (tmp_path / "a.toml").read_bytes() == (tmp_path / "b.toml").read_bytes()
    assert CameraRig.load(tmp_path / "b.toml") == awkward_rig()


def test_written_file_has_the_contract_keys_only(tmp_path):
    rig = awkward_rig()
    write_cameras_toml(rig, tmp_path / "rig.toml")
    document = tomllib.loads((tmp_path / "rig.toml").read_text(encoding="utf-8"))
    assert list(document) == ["cam_0", "cam_1", "cam_2"]
    for table, camera in zip(document.values(), rig):
        assert sorted(table) == sorted(CAMERA_KEYS)
        assert table["name"] == camera.name and table["size"] == [2448, 2048]
        assert np.array(table["matrix"]).shape == (3, 3) and len(table["distortions"]) == 5


def test_reads_anipose_file(tmp_path):
    (tmp_path / "calibration.toml").write_text(ANIPOSE, encoding="utf-8")
    rig = read_cameras_toml(tmp_path / "calibration.toml")
    assert rig.names == ("A", "B")
    assert rig["A"].size == (2448, 2048) and rig["B"].size == (1920, 1080)
    np.testing.assert_array_equal(rig["A"].matrix, [[2212.5, 0, 1224.25], [0, 2213.75, 1019.5], [0, 0, 1]])
    np.testing.assert_array_equal(rig["A"].distortions, [-0.11, 0.07, 0.001, -0.0005, -0.01])
    np.testing.assert_array_equal(rig["A"].rotation, [0.1, -0.2, 0.3])
    np.testing.assert_array_equal(rig["B"].center, [0.0, 0.0, -2.0])


def test_tables_are_read_in_file_order(tmp_path):
    # Keys other than cam_N are fine; order is the file's, not sorted.
    text = ANIPOSE.replace("[cam_0]", "[zeta]").replace("[cam_1]", "[alpha]")
    (tmp_path / "rig.toml").write_text(text, encoding="utf-8")
    assert read_cameras_toml(tmp_path / "rig.toml").names == ("A", "B")


def test_distortions_of_four_and_eight_values(tmp_path):
    text = ANIPOSE.replace("[ -0.11, 0.07, 0.001, -0.0005, -0.01,]", "[ -0.11, 0.07, 0.001, -0.0005]")
    text = text.replace("[ 0.0, 0.0, 0.0, 0.0, 0.0,]", "[ 0.01, 0.02, 0.0, 0.0, 0.03, 0.0, 0.0, 0.0]")
    (tmp_path / "rig.toml").write_text(text, encoding="utf-8")
    rig = read_cameras_toml(tmp_path / "rig.toml")
    np.testing.assert_array_equal(rig["A"].distortions, [-0.11, 0.07, 0.001, -0.0005, 0.0])
    np.testing.assert_array_equal(rig["B"].distortions, [0.01, 0.02, 0.0, 0.0, 0.03])


CAM_B = 'name = "B"'


@pytest.mark.parametrize("old, new, match", [
    ("[cam_0]", "[cam_0", r"rig\.toml: not valid TOML \("),
    ("[cam_0]", "answer = 42\n[cam_0]", r"rig\.toml: top-level key 'answer' is not a camera table"),
    ('name = "A"\n', "", r"rig\.toml: \[cam_0\] lacks name; each camera table needs name, size, matrix"),
    ("translation = [ 0.0, 0.0, 2.0,]\n", "", r"\[cam_1\] lacks translation"),
    ("size = [ 2448, 2048,]", "size = [2448, 2048, 3]", r"\[cam_0\] size must be \[width, height\]"),
    ("size = [ 2448, 2048,]", "size = [2448.5, 2048]", r"\[cam_0\] size must be two positive whole numbers"),
    ("size = [ 2448, 2048,]", 'size = ["2448", 2048]', r"\[cam_0\] size must be an array of numbers"),
    (", [ 0.0, 0.0, 1.0,],]", "]", r"\[cam_0\] matrix must be 3x3 .*got shape \(2, 3\)"),
    ("[ 0.0, 0.0, 1.0,],]", "[ 0.0, 0.0, 1.0, 0.0],]", r"\[cam_0\] matrix must be numbers"),
    ("[ -0.11, 0.07, 0.001, -0.0005, -0.01,]", "[ -0.11, 0.07, 0.001]", r"\[cam_0\] distortions must be 5 values"),
    ("[ 0.0, 0.0, 0.0, 0.0, 0.0,]", "[ 0.0, 0.0, 0.0, 0.0, 0.0, 0.5, 0.0, 0.0]",
     r"\[cam_1\] distortions has OpenCV's rational"),
    ("rotation = [ 0.1, -0.2, 0.3,]", "rotation = [ 0.1, nan, 0.3]", r"\[cam_0\] rotation must be finite"),
    ("translation = [ 0.05, -0.1, 1.5,]", "translation = [ 0.05, -0.1, inf]", r"\[cam_0\] translation must be finite"),
    ("translation = [ 0.05, -0.1, 1.5,]", "translation = [ true, false, 1.5]",
     r"translation must be an array of numbers"),
    ("translation = [ 0.05, -0.1, 1.5,]", "translation = 1.5", r"translation must have 3 values, got shape \(\)"),
    (CAM_B, 'name = "A"', r"rig\.toml: camera names must be unique, repeated: A"),
    (CAM_B, "name = 2", r"\[cam_1\] camera name must be a non-empty string"),
    (CAM_B, CAM_B + "\nfisheye = true", r"\[cam_1\] is a fisheye camera"),
])
def test_rejects_bad_files(tmp_path, old, new, match):
    assert old in ANIPOSE
    (tmp_path / "rig.toml").write_text(ANIPOSE.replace(old, new, 1), encoding="utf-8")
    with pytest.raises(HandcapError, match=match):
        read_cameras_toml(tmp_path / "rig.toml")


def test_rejects_missing_empty_and_binary_files(tmp_path):
    with pytest.raises(HandcapError, match=r"missing\.toml: no such file"):
        read_cameras_toml(tmp_path / "missing.toml")
    with pytest.raises(HandcapError, match="is a folder, expected a file"):
        read_cameras_toml(tmp_path)
    (tmp_path / "empty.toml").write_text("[metadata]\nadjusted = false\n", encoding="utf-8")
    with pytest.raises(HandcapError, match=r"empty\.toml: no camera tables"):
        read_cameras_toml(tmp_path / "empty.toml")
    (tmp_path / "binary.toml").write_bytes(b"\xff\xfe\x00garbage")
    with pytest.raises(HandcapError, match=r"binary\.toml: not valid TOML"):
        read_cameras_toml(tmp_path / "binary.toml")


def test_write_rejects_bad_arguments(tmp_path):
    with pytest.raises(HandcapError, match="needs a CameraRig, got list"):
        write_cameras_toml([awkward_rig()[0]], tmp_path / "rig.toml")
    with pytest.raises(HandcapError, match="does not exist"):
        write_cameras_toml(awkward_rig(), tmp_path / "no" / "rig.toml")
