"""Camera rig formats of other tools, checked against the real files in ../shared/data/calibration.

Values are compared with the files as read here independently (xml.etree,
tomllib, cv2.FileStorage); conventions are checked with geometry that a wrong
reading fails: optical axes meeting in front of the cameras, upright images,
image sizes of the real photos, and lens distortion refitted to real
checkerboard photos.
"""

import os
import tomllib
import xml.etree.ElementTree as ET

import cv2
import numpy as np
import pytest

from handcap.core.cameras import Camera, CameraRig
from handcap.core.errors import HandcapError
from handcap.io import read_rig as exported_read_rig
from handcap.io import write_rig as exported_write_rig
from handcap.io.camera_formats import (
    QCA_SUBPIXELS,
    camera_format,
    read_cameras_caliscope,
    read_cameras_opencv,
    read_cameras_qca,
    read_rig,
    write_cameras_caliscope,
    write_cameras_opencv,
    write_rig,
)
from handcap.io.cameras import read_cameras_toml, write_cameras_toml


@pytest.fixture(scope="module")
def calibration(shared_data):
    return shared_data / "calibration"


@pytest.fixture(scope="module")
def qca_path(calibration):
    return calibration / "pose2sim_4cam" / "Calib.qca.txt"


@pytest.fixture(scope="module")
def caliscope_path(calibration):
    return calibration / "caliscope_4cam" / "camera_array.toml"


def awkward_rig(prefix="cam "):
    """Cameras with awkward names and numbers that need all 17 significant digits."""
    rng = np.random.default_rng(3)
    cameras = []
    for i in range(3):
        matrix = [[2000 + rng.uniform(), 0, 1224 + rng.uniform()], [0, 2000 + 1 / 3, 1024 / 3], [0, 0, 1]]
        distortions = rng.normal(scale=0.05, size=5) * [1, 1, 1e-15, 1, 1]
        name = f"{prefix}{i}" if prefix == "cam_" else f"{prefix}{i} \"left\" <&> 'x'"
        cameras.append(Camera(name, (2448, 2048), matrix, distortions, rng.normal(size=3), rng.normal(size=3)))
    return CameraRig(cameras)


def axes_meeting(centers, axes):
    """Point nearest to the lines ``centers + s * axes`` (least squares); miss distances and depths."""
    axes = axes / np.linalg.norm(axes, axis=1, keepdims=True)
    projectors = np.eye(3) - axes[:, :, None] * axes[:, None, :]
    point = np.linalg.solve(projectors.sum(0), np.einsum("cij,cj->i", projectors, centers))
    miss = np.linalg.norm(np.einsum("cij,cj->ci", projectors, point - centers), axis=1)
    depth = np.einsum("ci,ci->c", axes, point - centers)
    return point, miss, depth


def assert_one_line_naming(err, path):
    message = str(err.value)
    assert "\n" not in message
    assert os.fspath(path) in message


# -- OpenCV FileStorage ------------------------------------------------------------------
def test_reads_opencv_stereo_intrinsics(calibration):
    path = calibration / "opencv_stereo" / "intrinsics.yml"
    image = cv2.imread(str(calibration / "opencv_stereo" / "left01.jpg"), cv2.IMREAD_GRAYSCALE)
    size = image.shape[::-1]
    assert size == (640, 480)  # the sample's documented size, from its own photos
    rig = read_cameras_opencv(path, size=size, intrinsics_only=True)
    storage = cv2.FileStorage(str(path), cv2.FILE_STORAGE_READ)
    assert rig.names == ("cam_1", "cam_2")
    for i, camera in enumerate(rig, start=1):
        np.testing.assert_array_equal(camera.matrix, storage.getNode(f"M{i}").mat())
        np.testing.assert_array_equal(camera.distortions, storage.getNode(f"D{i}").mat().ravel())
        assert camera.size == size
        assert not camera.rotation.any() and not camera.translation.any()


def test_stereo_intrinsics_say_what_is_missing(calibration):
    path = calibration / "opencv_stereo" / "intrinsics.yml"
    with pytest.raises(HandcapError, match=r"M1 D1 M2 D2\) but no image size .*size=.* and no stereo extrinsics"):
        read_cameras_opencv(path)
    with pytest.raises(HandcapError, match=r"but no stereo extrinsics R, T .*intrinsics_only=True") as err:
        read_cameras_opencv(path, size=(640, 480))
    assert "image size" not in str(err.value)
    assert_one_line_naming(err, path)


@pytest.mark.parametrize("as_matrix", [True, False])
def test_stereo_extrinsics_place_the_second_camera(calibration, tmp_path, as_matrix):
    # An extrinsics.yml as OpenCV's stereo_calib.cpp writes it, T in centimetres (its square size unit).
    rvec = np.array([0.02, -0.31, 0.015])
    rotation = cv2.Rodrigues(rvec)[0]
    translation_cm = np.array([-6.2, 0.35, 0.8])
    storage = cv2.FileStorage(str(tmp_path / "extrinsics.yml"), cv2.FILE_STORAGE_WRITE)
    storage.write("R", rotation if as_matrix else rvec.reshape(3, 1))
    storage.write("T", translation_cm.reshape(3, 1))
    storage.release()
    intrinsics = calibration / "opencv_stereo" / "intrinsics.yml"
    rig = read_cameras_opencv(intrinsics, size=(640, 480), extrinsics=tmp_path / "extrinsics.yml", unit="cm")
    left, right = rig
    assert not left.rotation.any() and not left.translation.any()
    np.testing.assert_allclose(right.rotation_matrix, rotation, atol=1e-12)
    np.testing.assert_allclose(right.translation, translation_cm / 100, rtol=1e-15)
    np.testing.assert_allclose(right.center, -rotation.T @ translation_cm / 100, atol=1e-12)
    # Points in front of the pair project as OpenCV projects them with the file's own matrices.
    rng = np.random.default_rng(11)
    points = rng.uniform([-0.2, -0.15, 0.6], [0.2, 0.15, 1.2], size=(40, 3))
    reference = cv2.FileStorage(str(intrinsics), cv2.FILE_STORAGE_READ)
    expected, _ = cv2.projectPoints(points, rvec, translation_cm / 100, reference.getNode("M2").mat(),
                                    reference.getNode("D2").mat())
    np.testing.assert_allclose(right.project(points)[0], expected.reshape(-1, 2), atol=1e-7)


def test_reads_opencv_calibration_sample(calibration):
    path = calibration / "opencv_stereo" / "left_intrinsics.yml"
    rig = read_cameras_opencv(path)
    storage = cv2.FileStorage(str(path), cv2.FILE_STORAGE_READ)
    (camera,) = rig
    assert camera.name == "left_intrinsics"
    assert camera.size == (int(storage.getNode("image_width").real()), int(storage.getNode("image_height").real()))
    np.testing.assert_array_equal(camera.matrix, storage.getNode("camera_matrix").mat())
    np.testing.assert_array_equal(camera.distortions, storage.getNode("distortion_coefficients").mat().ravel())
    assert not camera.rotation.any() and not camera.translation.any()
    with pytest.raises(HandcapError, match=r"image is 640x480 pixels, but size= says \(480, 640\)"):
        read_cameras_opencv(path, size=(480, 640))


def test_an_image_list_is_not_a_calibration(calibration):
    path = calibration / "opencv_stereo" / "stereo_calib.xml"
    with pytest.raises(HandcapError, match=r"holds no camera calibration \(it has imagelist\)") as err:
        read_cameras_opencv(path)
    assert_one_line_naming(err, path)


@pytest.mark.parametrize("suffix", [".yml", ".yaml", ".xml"])
def test_opencv_round_trip_is_exact(tmp_path, suffix):
    rig = awkward_rig()
    write_cameras_opencv(rig, tmp_path / f"rig{suffix}")
    back = read_cameras_opencv(tmp_path / f"rig{suffix}")
    assert back == rig  # names, sizes and every number equal
    assert os.listdir(tmp_path) == [f"rig{suffix}"]  # no temporary file left behind


@pytest.mark.parametrize("suffix", [".yml", ".xml"])
def test_opencv_layout_as_opencv_reads_it(tmp_path, suffix):
    rig = awkward_rig()
    write_cameras_opencv(rig, tmp_path / f"rig{suffix}")
    storage = cv2.FileStorage(str(tmp_path / f"rig{suffix}"), cv2.FILE_STORAGE_READ)
    assert storage.getNode("camera_count").real() == len(rig)
    cameras = storage.getNode("cameras")
    assert cameras.isSeq() and cameras.size() == len(rig)
    for i, camera in enumerate(rig):
        node = cameras.at(i)
        assert node.keys() == ("name", "image_width", "image_height", "camera_matrix",
                               "distortion_coefficients", "rvec", "tvec")
        assert node.getNode("name").string() == camera.name
        assert (node.getNode("image_width").real(), node.getNode("image_height").real()) == camera.size
        np.testing.assert_array_equal(node.getNode("camera_matrix").mat(), camera.matrix)
        np.testing.assert_array_equal(node.getNode("distortion_coefficients").mat(), camera.distortions[:, None])
        rvec, tvec = node.getNode("rvec").mat(), node.getNode("tvec").mat()
        np.testing.assert_array_equal(rvec.ravel(), camera.rotation)
        np.testing.assert_array_equal(tvec.ravel(), camera.translation)
        # rvec/tvec are OpenCV's world-to-camera pose: projectPoints agrees with the camera.
        point = camera.center + camera.rotation_matrix[2] * 2.0 + [0.01, -0.02, 0.03]
        expected, _ = cv2.projectPoints(point[None], rvec, tvec, camera.matrix, camera.distortions)
        np.testing.assert_allclose(camera.project(point[None])[0], expected.reshape(1, 2), atol=1e-7)


def test_opencv_rig_layout_errors(tmp_path):
    write_cameras_opencv(awkward_rig(), tmp_path / "rig.yml")
    text = (tmp_path / "rig.yml").read_text(encoding="utf-8")
    lacking = tmp_path / "lacking.yml"
    lacking.write_text(text.replace("tvec:", "tvec_old:", 1), encoding="utf-8")
    with pytest.raises(HandcapError, match=r"cameras\[0\] \(cam 0 .*\) lacks tvec") as err:
        read_cameras_opencv(lacking)
    assert_one_line_naming(err, lacking)
    not_finite = tmp_path / "nan.yml"
    head, tail = text.split("data: [ ", 1)
    not_finite.write_text(head + "data: [ .nan, " + tail.split(",", 1)[1], encoding="utf-8")
    with pytest.raises(HandcapError, match=r"camera_matrix must be finite") as err:
        read_cameras_opencv(not_finite)
    assert_one_line_naming(err, not_finite)
    broken = tmp_path / "broken.yml"
    broken.write_text("%YAML:1.0\ncameras: [1, 2\n", encoding="utf-8")
    with pytest.raises(HandcapError, match=r"not an OpenCV YAML/XML file \(line \d+: ") as err:
        read_cameras_opencv(broken)
    assert_one_line_naming(err, broken)
    with pytest.raises(HandcapError, match=r"OpenCV camera files are \.yml, \.yaml, \.xml"):
        write_cameras_opencv(awkward_rig(), tmp_path / "rig.json")
    with pytest.raises(HandcapError, match="unit= is the unit of a stereo translation T"):
        read_cameras_opencv(tmp_path / "rig.yml", unit="mm")


# -- Qualisys QCA ------------------------------------------------------------------------
def test_qca_values_match_the_file(qca_path):
    rig = read_cameras_qca(qca_path)
    elements = ET.parse(qca_path).getroot().findall("cameras/camera")
    assert rig.names == tuple(element.get("serial") for element in elements)
    for camera, element in zip(rig, elements):
        i = {k: float(v) for k, v in element.find("intrinsic").attrib.items()}
        fov = {k: int(v) for k, v in element.find("fov_video").attrib.items()}
        t = {k: float(v) for k, v in element.find("transform").attrib.items()}
        assert camera.size == (fov["right"] - fov["left"] + 1, fov["bottom"] - fov["top"] + 1)
        np.testing.assert_allclose(camera.matrix, [
            [i["focalLengthU"] / 64, 0, i["centerPointU"] / 64 - fov["left"]],
            [0, i["focalLengthV"] / 64, i["centerPointV"] / 64 - fov["top"]],
            [0, 0, 1]], rtol=1e-15)
        np.testing.assert_array_equal(camera.distortions, [
            i["radialDistortion1"], i["radialDistortion2"], i["tangentalDistortion1"],
            i["tangentalDistortion2"], i["radialDistortion3"]])
        np.testing.assert_allclose(camera.center, [t["x"] / 1000, t["y"] / 1000, t["z"] / 1000], atol=1e-12)
    assert QCA_SUBPIXELS == 64
    assert rig[0].matrix[0, 0] == pytest.approx(107599.671875 / 64)  # ~1681 pixels


def test_qca_image_size_is_that_of_the_photos(qca_path):
    rig = read_cameras_qca(qca_path)
    for camera in rig:
        folder = qca_path.parent / "intrinsics" / f"int_{camera.name}_img"
        photo = cv2.imread(str(sorted(folder.glob("*.jpg"))[0]), cv2.IMREAD_REDUCED_GRAYSCALE_8)
        assert (photo.shape[1] * 8, photo.shape[0] * 8) == camera.size == (1088, 1920)


def test_qca_optical_axes_meet_in_front_of_every_camera(qca_path):
    rig = read_cameras_qca(qca_path)
    axes = np.stack([camera.rotation_matrix[2] for camera in rig])  # OpenCV's z: the optical axis
    point, miss, depth = axes_meeting(rig.centers, axes)
    assert miss.max() < 0.25 and depth.min() > 2.0
    pixels, depths = rig.project(point[None])
    assert rig.in_image(pixels).all() and (depths > 0).all()
    # Reading the matrix by columns, or x y z as a translation, fails the same test.
    elements = ET.parse(qca_path).getroot().findall("cameras/camera")
    raw = [{k: float(v) for k, v in e.find("transform").attrib.items()} for e in elements]
    matrices = np.array([[[t[f"r{i}{j}"] for j in (1, 2, 3)] for i in (1, 2, 3)] for t in raw])
    positions = np.array([[t["x"], t["y"], t["z"]] for t in raw]) / 1000
    for centers, wrong_axes in [(positions, -matrices[:, :, 2]), (positions, matrices[:, :, 2]),
                                (-np.einsum("cji,cj->ci", matrices, positions), -matrices[:, 2])]:
        _, wrong_miss, wrong_depth = axes_meeting(centers, wrong_axes)
        assert wrong_miss.max() > 0.25 or wrong_depth.min() < 2.0


def test_qca_cameras_see_the_world_upright(qca_path):
    # viewrotation="0": every image is upright, so world up (+z) goes up the image (v decreases).
    rig = read_cameras_qca(qca_path)
    point, _, _ = axes_meeting(rig.centers, np.stack([camera.rotation_matrix[2] for camera in rig]))
    pixels, _ = rig.project(np.stack([point, point + [0, 0, 0.3]]))
    rise = pixels[:, 0] - pixels[:, 1]
    assert (rise[:, 1] > 50).all()  # pixels up
    assert (np.abs(rise[:, 0]) < rise[:, 1]).all()  # within 45 degrees of straight up


@pytest.mark.parametrize("index", range(4))
def test_qca_lens_distortion_fits_the_checkerboard_photos(qca_path, index):
    # Refit k1 to the Pose2Sim demo's own checkerboard photos (4x7 inner corners), with
    # every other parameter as read: the QCA's k1 is in OpenCV's units, not 1/64 of them.
    camera = read_cameras_qca(qca_path)[index]
    folder = qca_path.parent / "intrinsics" / f"int_{camera.name}_img"
    board = np.zeros((28, 3), np.float32)
    board[:, :2] = np.mgrid[0:4, 0:7].T.reshape(-1, 2) * 0.06
    objects, images = [], []
    for photo in sorted(folder.glob("*.jpg")):
        gray = cv2.imread(str(photo), cv2.IMREAD_GRAYSCALE)
        found, corners = cv2.findChessboardCorners(gray, (4, 7))
        if found:
            criteria = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 50, 1e-4)
            objects.append(board)
            images.append(cv2.cornerSubPix(gray, corners, (11, 11), (-1, -1), criteria))
    assert len(objects) >= 5
    flags = (cv2.CALIB_USE_INTRINSIC_GUESS | cv2.CALIB_FIX_FOCAL_LENGTH | cv2.CALIB_FIX_PRINCIPAL_POINT
             | cv2.CALIB_FIX_K2 | cv2.CALIB_FIX_K3 | cv2.CALIB_FIX_TANGENT_DIST)
    rms, _, fitted, _, _ = cv2.calibrateCamera(objects, images, camera.size, camera.matrix.copy(),
                                               camera.distortions.copy(), flags=flags)
    assert rms < 1.5
    assert abs(fitted.ravel()[0] - camera.distortions[0]) < 0.012


def edited_qca(qca_path, tmp_path, old, new, count=1):
    text = qca_path.read_text(encoding="ascii")
    assert old in text
    path = tmp_path / "edited.qca.txt"
    path.write_text(text.replace(old, new, count), encoding="ascii")
    return path


@pytest.mark.parametrize("old, new, message", [
    ('focalLengthU="107118.695313" ', "", r"camera 'cam02' <intrinsic> lacks focalLengthU"),
    ('x="1460.2323709212087"', 'x="nan"', r"camera 'cam01' <transform> x must be finite, got 'nan'"),
    ('r11="0.5536380477336265"', 'r11="0.6"', r"camera 'cam01' <transform> r11..r33 is not a rotation matrix"),
    ('skew="0.000000"', 'skew="0.5"', r"camera 'cam01' <intrinsic> skew is 0.5"),
    ('viewrotation="0"', 'viewrotation="90"', r"camera 'cam01' has viewrotation=90: .*ignore_viewrotation=True"),
    ('viewrotation="0"', 'viewrotation="45"', r"viewrotation must be 0, 90, 180 or 270, got '45'"),
    ('<fov_video bottom="1919" left="0" right="1087" top="0"/>', "", r"camera 'cam01' lacks <fov_video>"),
    ('<fov_video bottom="1919" left="0" right="1087" top="0"/>',
     '<fov_video bottom="1919" left="0" right="2175" top="0"/>', r"<fov_video> .* lies outside the sensor"),
])
def test_qca_bad_cameras(qca_path, tmp_path, old, new, message):
    path = edited_qca(qca_path, tmp_path, old, new)
    with pytest.raises(HandcapError, match=message) as err:
        read_cameras_qca(path)
    assert_one_line_naming(err, path)


def test_qca_viewrotation_can_be_ignored_and_inactive_cameras_skipped(qca_path, tmp_path):
    path = edited_qca(qca_path, tmp_path, 'viewrotation="0"', 'viewrotation="180"')
    assert read_cameras_qca(path, ignore_viewrotation=True) == read_cameras_qca(qca_path)
    path = edited_qca(qca_path, tmp_path, 'active="1" avg-residual="0.450323"', 'active="0" avg-residual="0.450323"')
    assert read_cameras_qca(path).names == ("cam01", "cam02", "cam04")


def test_qca_video_crop_moves_the_principal_point(qca_path, tmp_path):
    old = '<fov_video bottom="1919" left="0" right="1087" top="0"/>'
    path = edited_qca(qca_path, tmp_path, old, '<fov_video bottom="1819" left="100" right="1087" top="200"/>')
    full, cropped = read_cameras_qca(qca_path)[0], read_cameras_qca(path)[0]
    assert cropped.size == (988, 1620)
    np.testing.assert_allclose(cropped.matrix[:2, 2], full.matrix[:2, 2] - [100, 200], rtol=1e-15)
    # A world point lands on the same sensor pixel, shifted by the crop.
    point = full.center + 3 * full.rotation_matrix[2] + [0.1, 0.2, -0.1]
    np.testing.assert_allclose(cropped.project(point[None])[0], full.project(point[None])[0] - [100, 200],
                               atol=1e-9)


def test_qca_reads_either_spelling_of_tangential(qca_path, tmp_path):
    path = edited_qca(qca_path, tmp_path, "tangentalDistortion", "tangentialDistortion", count=-1)
    assert read_cameras_qca(path) == read_cameras_qca(qca_path)


@pytest.mark.parametrize("text, message", [
    ("this is not XML", r"not a Qualisys calibration \(not valid XML"),
    ('<?xml version="1.0"?>\n<opencv_storage></opencv_storage>', r"its XML root is <opencv_storage>"),
    ("<calibration><cameras/></calibration>", r"no cameras; expected <cameras><camera"),
])
def test_qca_bad_files(tmp_path, text, message):
    path = tmp_path / "bad.qca.txt"
    path.write_text(text, encoding="utf-8")
    with pytest.raises(HandcapError, match=message) as err:
        read_cameras_qca(path)
    assert_one_line_naming(err, path)


# -- caliscope TOML ----------------------------------------------------------------------
def test_caliscope_values_match_the_file(caliscope_path):
    rig = read_cameras_caliscope(caliscope_path)
    tables = tomllib.loads(caliscope_path.read_text(encoding="utf-8"))["cameras"]
    assert rig.names == tuple(f"cam_{port}" for port in sorted(tables, key=int))
    for camera, port in zip(rig, sorted(tables, key=int)):
        table = tables[port]
        assert camera.size == tuple(table["size"])
        np.testing.assert_array_equal(camera.matrix, table["matrix"])
        np.testing.assert_array_equal(camera.distortions, table["distortions"])
        np.testing.assert_array_equal(camera.translation, table["translation"])
        np.testing.assert_allclose(camera.rotation_matrix, table["rotation"], atol=1e-14)


def test_caliscope_projection_is_opencvs_with_the_files_matrices(caliscope_path):
    rig = read_cameras_caliscope(caliscope_path)
    tables = tomllib.loads(caliscope_path.read_text(encoding="utf-8"))["cameras"]
    point, _, _ = axes_meeting(rig.centers, np.stack([camera.rotation_matrix[2] for camera in rig]))
    points = point + np.random.default_rng(5).uniform(-0.2, 0.2, size=(30, 3))
    pixels, depths = rig.project(points)
    assert (depths > 0).all()
    for c, port in enumerate(sorted(tables, key=int)):
        table = tables[port]
        rvec = cv2.Rodrigues(np.array(table["rotation"]))[0]
        expected, _ = cv2.projectPoints(points, rvec, np.array(table["translation"]), np.array(table["matrix"]),
                                        np.array(table["distortions"]))
        np.testing.assert_allclose(pixels[c], expected.reshape(-1, 2), atol=1e-7)


def test_caliscope_optical_axes_meet_in_front_of_every_camera(caliscope_path):
    rig = read_cameras_caliscope(caliscope_path)
    point, miss, depth = axes_meeting(rig.centers, np.stack([camera.rotation_matrix[2] for camera in rig]))
    assert miss.max() < 0.25 and depth.min() > 0.5
    assert rig.in_image(rig.project(point[None])[0]).all()


def triangulate_charuco(rig, detections):
    """Linear triangulation of caliscope's own ChArUco detections (xy.csv) seen by 2+ cameras.

    Returns the reprojection errors (pixels) and, for every pair of corners seen in
    the same frame, triangulated minus true distance on the board (metres).
    """
    cameras = detections["cam_id"].astype(int)
    normalised = np.empty((len(cameras), 2))
    for port in np.unique(cameras):
        here = cameras == port
        normalised[here] = rig[f"cam_{port}"].undistort_pixels(detections["xy"][here], normalised=True)
    errors, spacing = [], []
    for sync in np.unique(detections["sync_index"]):
        points, board = [], []
        for keypoint in np.unique(detections["keypoint_id"][detections["sync_index"] == sync]):
            rows = np.flatnonzero((detections["sync_index"] == sync) & (detections["keypoint_id"] == keypoint))
            if len(rows) < 2:
                continue
            equations = []
            for row in rows:
                projection = rig[f"cam_{cameras[row]}"].world2camera[:3]
                equations += [normalised[row, 0] * projection[2] - projection[0],
                              normalised[row, 1] * projection[2] - projection[1]]
            homogeneous = np.linalg.svd(np.array(equations))[2][-1]
            point = homogeneous[:3] / homogeneous[3]
            for row in rows:
                pixel = rig[f"cam_{cameras[row]}"].project(point[None])[0][0]
                errors.append(np.linalg.norm(pixel - detections["xy"][row]))
            points.append(point)
            board.append(detections["board"][rows[0]])
        points, board = np.array(points), np.array(board)
        for i in range(len(points)):
            spacing.extend(np.linalg.norm(points[i + 1:] - points[i], axis=1)
                           - np.linalg.norm(board[i + 1:] - board[i], axis=1))
    return np.array(errors), np.array(spacing)


def test_caliscope_rig_triangulates_its_own_detections(caliscope_path):
    # caliscope's detections of its ChArUco board (5.4 cm squares) in the same session:
    # triangulated with the rig as read, they reproject within a pixel or two and keep
    # the board's true spacing in metres. Read as camera-to-world, they reproject ~300 px off.
    table = np.genfromtxt(caliscope_path.parent / "xy.csv", delimiter=",", names=True)
    detections = {"sync_index": table["sync_index"].astype(int), "cam_id": table["cam_id"],
                  "keypoint_id": table["keypoint_id"].astype(int),
                  "xy": np.column_stack([table["img_loc_x"], table["img_loc_y"]]),
                  "board": np.column_stack([table["obj_loc_x"], table["obj_loc_y"]])}
    rig = read_cameras_caliscope(caliscope_path)
    errors, spacing = triangulate_charuco(rig, detections)
    assert len(errors) > 1000 and len(spacing) > 1000
    assert np.sqrt(np.mean(errors**2)) < 1.5
    assert np.sqrt(np.mean(spacing**2)) < 0.002
    inverted = CameraRig([Camera(c.name, c.size, c.matrix, c.distortions, -c.rotation,
                                 -c.rotation_matrix.T @ c.translation) for c in rig])
    wrong_errors, _ = triangulate_charuco(inverted, detections)
    assert np.sqrt(np.mean(wrong_errors**2)) > 20


def test_caliscope_round_trip(caliscope_path, tmp_path):
    for rig in (read_cameras_caliscope(caliscope_path), awkward_rig("cam_")):
        write_cameras_caliscope(rig, tmp_path / "camera_array.toml")
        back = read_cameras_caliscope(tmp_path / "camera_array.toml")
        assert back.names == rig.names
        for a, b in zip(rig, back):
            assert a.size == b.size
            np.testing.assert_array_equal(a.matrix, b.matrix)
            np.testing.assert_array_equal(a.distortions, b.distortions)
            np.testing.assert_array_equal(a.translation, b.translation)
            # The same rotation; its Rodrigues vector comes back with an angle of at most pi.
            np.testing.assert_allclose(a.rotation_matrix, b.rotation_matrix, rtol=0, atol=1e-12)
    document = tomllib.loads((tmp_path / "camera_array.toml").read_text(encoding="utf-8"))
    assert list(document) == ["cameras"] and list(document["cameras"]) == ["0", "1", "2"]
    assert np.array(document["cameras"]["1"]["rotation"]).shape == (3, 3)
    assert os.listdir(tmp_path) == ["camera_array.toml"]


def test_caliscope_writer_needs_port_names(tmp_path):
    with pytest.raises(HandcapError, match=r"camera 'cam 0 .*' must be renamed cam_0, cam_1"):
        write_cameras_caliscope(awkward_rig(), tmp_path / "camera_array.toml")
    assert not (tmp_path / "camera_array.toml").exists()


@pytest.mark.parametrize("old, new, message", [
    ("translation = [0.00043375420342479525, -0.0019919458836723174, 0.0025865337259615363]\n", "",
     r"\[cameras\.1\] lacks translation"),
    ("matrix = [[894.5288733178912,", "matrix = [[nan,", r"\[cameras\.0\] matrix must be finite"),
    ("rotation = [[0.999994984884606,", "rotation = [[0.9,", r"\[cameras\.1\] rotation is not a rotation matrix"),
    ("size = [1280, 720]", 'size = "1280x720"', r"\[cameras\.0\] size must be an array of numbers"),
    ("[cameras.0]", "[cameras.left]", r"not a caliscope camera array"),
])
def test_caliscope_bad_cameras(caliscope_path, tmp_path, old, new, message):
    text = caliscope_path.read_text(encoding="utf-8")
    assert old in text
    path = tmp_path / "camera_array.toml"
    path.write_text(text.replace(old, new, 1), encoding="utf-8")
    with pytest.raises(HandcapError, match=message) as err:
        read_cameras_caliscope(path)
    assert_one_line_naming(err, path)


def test_caliscope_ignored_cameras_are_left_out(caliscope_path, tmp_path):
    text = caliscope_path.read_text(encoding="utf-8")
    path = tmp_path / "camera_array.toml"
    path.write_text(text.replace("cam_id = 2\nrotation_count = 1\nerror = 0.656\nexposure = -5\ngrid_count = 28\n"
                                 "ignore = false", "cam_id = 2\nrotation_count = 1\nerror = 0.656\nexposure = -5\n"
                                 "grid_count = 28\nignore = true"), encoding="utf-8")
    assert read_cameras_caliscope(path).names == ("cam_0", "cam_1", "cam_3")


# -- choosing the format -----------------------------------------------------------------
@pytest.mark.parametrize("relative, fmt, options", [
    ("opencv_stereo/intrinsics.yml", "opencv", {"size": (640, 480), "intrinsics_only": True}),
    ("opencv_stereo/left_intrinsics.yml", "opencv", {}),
    ("pose2sim_4cam/Calib.qca.txt", "qca", {}),
    ("caliscope_4cam/camera_array.toml", "caliscope", {}),
])
def test_read_rig_chooses_the_format(calibration, relative, fmt, options):
    path = calibration / relative
    specific = {"opencv": read_cameras_opencv, "qca": read_cameras_qca, "caliscope": read_cameras_caliscope}[fmt]
    assert camera_format(path) == fmt
    assert read_rig(path, **options) == specific(path, **options)


def test_formats_told_by_content(qca_path, caliscope_path, tmp_path):
    write_cameras_toml(awkward_rig(), tmp_path / "anipose.toml")
    assert camera_format(tmp_path / "anipose.toml") == "anipose"
    (tmp_path / "calibration.xml").write_bytes(qca_path.read_bytes())
    assert camera_format(tmp_path / "calibration.xml") == "qca"
    assert read_rig(tmp_path / "calibration.xml") == read_cameras_qca(qca_path)
    (tmp_path / "calibration.qca").write_bytes(qca_path.read_bytes())
    assert camera_format(tmp_path / "calibration.qca") == "qca"
    write_cameras_opencv(awkward_rig(), tmp_path / "opencv.xml")
    assert camera_format(tmp_path / "opencv.xml") == "opencv"
    (tmp_path / "caliscope.toml").write_bytes(caliscope_path.read_bytes())
    assert camera_format(tmp_path / "caliscope.toml") == "caliscope"


@pytest.mark.parametrize("name", ["rig.toml", "rig.yml", "rig.yaml", "rig.xml"])
def test_write_rig_then_read_rig(tmp_path, name):
    rig = awkward_rig()
    exported_write_rig(rig, tmp_path / name)
    assert exported_read_rig(tmp_path / name) == rig
    if name.endswith(".toml"):
        assert read_cameras_toml(tmp_path / name) == rig  # handcap's own anipose layout


def test_dispatcher_refusals(calibration, tmp_path):
    rig = awkward_rig()
    for call, path, message in [
        (read_rig, tmp_path / "rig.json", r"cannot tell the camera file format from '\.json'"),
        (read_rig, tmp_path / "rig", r"from 'no extension'"),
        (read_rig, tmp_path / "missing.yml", r"no such file"),
        (read_rig, tmp_path / "missing.qca.txt", r"no such file"),
        (lambda path: write_rig(rig, path), tmp_path / "rig.json", r"cannot write cameras as '\.json'"),
        (lambda path: write_rig(rig, path), tmp_path / "rig.qca.txt", r"reads Qualisys QCA files but does not write"),
        (lambda path: read_rig(path, sise=(640, 480)), calibration / "opencv_stereo" / "left_intrinsics.yml",
         r"opencv camera files take no option sise; they take size, extrinsics, unit, intrinsics_only"),
        (lambda path: read_rig(path, size=(640, 480)), calibration / "pose2sim_4cam" / "Calib.qca.txt",
         r"qca camera files take no option size; they take ignore_viewrotation"),
    ]:
        with pytest.raises(HandcapError, match=message) as err:
            call(path)
        assert_one_line_naming(err, path)
    assert list(tmp_path.iterdir()) == []
