"""Camera calibration against independent results on real data, and rigs with known truth.

References (none computed by handcap):
* OpenCV's own stereo calibration of its sample images (``opencv_stereo/intrinsics.yml``,
  M1 for the left camera, M2 for the right);
* a Qualisys calibration of the pose2sim cameras (``Calib.qca.txt``; focal lengths in
  1/64 pixel, cameras matched to the image folders by ``serial``);
* caliscope's calibration of its 4-camera recording (``camera_array.toml``: ``rotation``
  and ``translation`` map the world to the camera, as OpenCV's do, so a camera sits at
  ``-R.T @ t``) and its 2-D detections (``xy.csv``).
"""

import tomllib
import xml.etree.ElementTree as ET

import cv2
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from handcap import HandcapError
from handcap.cli import main
from handcap.core.cameras import Camera, CameraRig
from handcap.io.cameras import read_cameras_toml
from handcap.multiview.boards import BoardDetections, detect_board, detect_in_files, detect_in_video, parse_board
from handcap.multiview import Detections
from handcap.multiview.calibration import bundle_adjust, calibrate_intrinsics, calibrate_rig
from handcap.multiview.board_sync import board_offsets, shift_boards
from handcap.multiview.sync import check_sync, estimate_sync
from handcap.objects.rigid import kabsch
from handcap.synth.cameras import cage_rig

OPENCV = "calibration/opencv_stereo"
POSE2SIM = "calibration/pose2sim_4cam"
CALISCOPE = "calibration/caliscope_4cam"
CALISCOPE_BOARD = "charuco:4x5:0.054:0.0405:DICT_4X4_1000:inverted"
FLIP = np.diag([1.0, -1.0, -1.0, 1.0])  # board frame -> world frame of origin="board"


# -- fixtures: detections of the real data, once per module ----------------------------
@pytest.fixture(scope="module")
def opencv_views(shared_data):
    folder = shared_data / OPENCV
    return {side: detect_in_files(sorted(folder.glob(f"{side}*.jpg")), "checkerboard:9x6:0.025")
            for side in ("left", "right")}


@pytest.fixture(scope="module")
def pose2sim_views(shared_data):
    folder = shared_data / POSE2SIM / "intrinsics"
    return {f"cam0{i}": detect_in_files(folder / f"int_cam0{i}_img", "checkerboard:4x7:0.06") for i in range(1, 5)}


@pytest.fixture(scope="module")
def caliscope_views(shared_data):
    return [detect_in_files(shared_data / CALISCOPE / f"cam_{i}.mp4", CALISCOPE_BOARD) for i in range(4)]


@pytest.fixture(scope="module")
def caliscope_reference(shared_data):
    with open(shared_data / CALISCOPE / "camera_array.toml", "rb") as fh:
        cameras = tomllib.load(fh)["cameras"]
    return [cameras[str(i)] for i in range(4)]


@pytest.fixture(scope="module")
def caliscope_rig(caliscope_views):
    return calibrate_rig(caliscope_views, names=[f"cam_{i}" for i in range(4)])


def _caliscope_centres(reference):
    return np.array([-np.array(c["rotation"]).T @ np.array(c["translation"]) for c in reference])


# -- intrinsics on real data -----------------------------------------------------------
@pytest.mark.parametrize("side, key", [("left", "M1"), ("right", "M2")])
def test_opencv_sample_intrinsics_match_opencv(shared_data, opencv_views, side, key):
    storage = cv2.FileStorage(str(shared_data / OPENCV / "intrinsics.yml"), cv2.FILE_STORAGE_READ)
    reference = storage.getNode(key).mat()
    storage.release()
    result = calibrate_intrinsics(opencv_views[side])
    assert len(result.views) >= 12
    assert result.rms < 0.5 and result.view_rms.max() < 0.5
    matrix = result.camera.matrix
    np.testing.assert_allclose(matrix[[0, 1], [0, 1]], reference[[0, 1], [0, 1]], rtol=0.01)
    np.testing.assert_allclose(matrix[:2, 2], reference[:2, 2], atol=15)  # pixels
    assert result.camera.size == (640, 480)


@pytest.mark.parametrize("serial", ["cam01", "cam02", "cam03", "cam04"])
def test_pose2sim_focal_lengths_match_qualisys(shared_data, pose2sim_views, serial):
    root = ET.parse(shared_data / POSE2SIM / "Calib.qca.txt").getroot()
    camera = next(c for c in root.iter("camera") if c.get("serial") == serial)
    intrinsic = camera.find("intrinsic")
    focal = np.array([float(intrinsic.get("focalLengthU")), float(intrinsic.get("focalLengthV"))]) / 64.0
    result = calibrate_intrinsics(pose2sim_views[serial])
    assert result.camera.size == (1088, 1920)
    assert result.rms < 0.5
    np.testing.assert_allclose(result.camera.matrix[[0, 1], [0, 1]], focal, rtol=0.01)


def test_outlier_views_are_rejected(pose2sim_views):
    # cam04_07 has a corner pulled 17 px off by the image's edge: it is dropped.
    views = pose2sim_views["cam04"]
    kept = calibrate_intrinsics(views)
    assert "cam04_07_int.jpg" in [views.labels[t] for t in kept.rejected]
    everything = calibrate_intrinsics(views, reject_outliers=False)
    assert everything.rms > 3 * kept.rms


def test_checkerboard_corners_keep_their_names_when_the_board_turns(shared_data, opencv_views):
    image = cv2.imread(str(shared_data / OPENCV / "left01.jpg"))
    board = opencv_views["left"].board
    upright = detect_board(image, board)
    turned = detect_board(cv2.rotate(image, cv2.ROTATE_180), board)
    w, h = 640, 480
    np.testing.assert_allclose(turned, np.array([w - 1, h - 1]) - upright, atol=0.05)
    np.testing.assert_allclose(upright, opencv_views["left"].pixels[0])


def test_charuco_detections_match_caliscope(shared_data, caliscope_views):
    xy = np.genfromtxt(shared_data / CALISCOPE / "xy.csv", delimiter=",", names=True)
    first = int(xy["sync_index"].min())  # the videos start at caliscope's first sync index
    for c, views in enumerate(caliscope_views):
        rows = xy[xy["cam_id"] == c]
        ours = views.pixels[(rows["sync_index"] - first).astype(int), rows["keypoint_id"].astype(int)]
        found = np.isfinite(ours[:, 0])
        assert found.mean() > 0.9
        difference = ours[found] - np.stack([rows["img_loc_x"], rows["img_loc_y"]], axis=1)[found]
        if c == 1:  # seen through the board's back: caliscope flips u back as w - u, we as w - 1 - u
            assert abs(np.median(difference[:, 0]) + 1.0) < 0.2
            difference[:, 0] += 1.0
        assert np.median(np.linalg.norm(difference, axis=1)) < 0.6


def test_a_board_seen_from_behind_is_found_in_the_mirror(shared_data):
    capture = cv2.VideoCapture(str(shared_data / CALISCOPE / "cam_0.mp4"))
    ok, image = capture.read()
    capture.release()
    assert ok
    board = parse_board(CALISCOPE_BOARD)
    front = detect_board(image, board)
    mirrored = detect_board(cv2.flip(image, 1), board)
    assert np.isfinite(front[:, 0]).sum() >= 6
    np.testing.assert_allclose(mirrored[:, 0], 1279 - front[:, 0], atol=0.3)
    np.testing.assert_allclose(mirrored[:, 1], front[:, 1], atol=0.3)
    assert np.isnan(detect_board(cv2.flip(image, 1), board, mirrored=False)).all()


# -- the caliscope rig end to end ------------------------------------------------------
def test_caliscope_rig_reprojects_within_a_pixel(caliscope_rig, caliscope_views):
    assert caliscope_rig.rms.max() < 1.0
    assert (caliscope_rig.views >= 20).all()
    assert caliscope_rig.rig.sizes.tolist() == [[1280, 720]] * 4
    frames = np.isfinite(caliscope_rig.errors).any(axis=(0, 2))
    assert frames.sum() >= 45
    # The world is the board at the first frame camera 0 sees it in: x along it, z out of its face.
    first = int(np.flatnonzero(caliscope_views[0].found)[0])
    np.testing.assert_allclose(caliscope_rig.board2world[first], FLIP, atol=1e-9)


def test_caliscope_rig_matches_caliscope(caliscope_rig, caliscope_reference):
    ours, theirs = caliscope_rig.rig.centers, _caliscope_centres(caliscope_reference)
    rotation, translation = kabsch(ours, theirs)
    assert np.linalg.norm(ours @ rotation.T + translation - theirs, axis=1).max() < 0.02
    distances = np.linalg.norm(ours[:, None] - ours[None], axis=-1)
    np.testing.assert_allclose(distances, np.linalg.norm(theirs[:, None] - theirs[None], axis=-1), atol=0.02)


def _board_detections(views, names, late) -> Detections:
    """The board's corners as named markers, each camera's frames renumbered as if it had started ``late`` frames
    after the others."""
    frames, cameras, markers, pixels = [], [], [], []
    for c, view in enumerate(views):
        t, m = np.nonzero(np.isfinite(view.pixels).all(axis=-1))
        keep = view.frames[t] >= late[c]
        frames.append(view.frames[t][keep] - late[c])
        cameras.append(np.full(keep.sum(), c))
        markers.append(m[keep])
        pixels.append(view.pixels[t[keep], m[keep]])
    n = views[0].board.n_corners
    return Detections(names, tuple(f"corner{k}" for k in range(n)), np.concatenate(frames), np.concatenate(cameras),
                      np.concatenate(markers), np.concatenate(pixels), np.ones(sum(map(len, frames))), 30.0,
                      int(max(v.frames.max() for v in views)) + 1)


def test_real_cameras_synchronised_and_one_started_late(caliscope_views, caliscope_rig):
    """caliscope's four webcams, whose frames it paired by their time stamps: the offsets found are 0 to a tenth
    of a frame; with camera 2's first 3 frames cut (it started late), its offset is 3 and the check warns."""
    rig = caliscope_rig.rig
    together = _board_detections(caliscope_views, rig.names, [0, 0, 0, 0])
    assert check_sync(together, rig).warnings == ()
    found = estimate_sync(together, rig)
    assert found.warnings == () and np.abs(found.offsets).max() < 0.1 and found.after < 0.6
    late = _board_detections(caliscope_views, rig.names, [0, 0, 3, 0])
    assert any("seem not synchronised" in w for w in check_sync(late, rig).warnings)
    shifted = estimate_sync(late, rig)
    assert np.abs(shifted.offsets - found.offsets - [0, 0, 3, 0]).max() < 0.1, shifted.summary()
    assert shifted.before > 2 * shifted.after


def test_real_cameras_offsets_from_the_board_before_the_rig_is_calibrated(caliscope_views, caliscope_reference):
    """From the board's motion alone (caliscope's intrinsics, no extrinsics): camera 2 with its first 3 frames cut
    comes out 3 frames later than with them."""
    cameras = [Camera(f"cam_{i}", c["size"], c["matrix"], c["distortions"]) for i, c in enumerate(caliscope_reference)]
    together = board_offsets(caliscope_views, cameras, max_offset=10)
    assert together.warnings == () and np.abs(together.offsets).max() < 0.5
    late = [BoardDetections(v.board, v.pixels[3:], v.size, v.source, v.labels[3:], v.frames[3:] - 3)
            if i == 2 else v for i, v in enumerate(caliscope_views)]
    offsets = board_offsets(late, cameras, max_offset=10).offsets
    assert np.abs(offsets - together.offsets - [0, 0, 3, 0]).max() < 0.1, (offsets, together.offsets)
    # on the reference's frames, the rig calibrates from them as from the videos as they are
    rig = calibrate_rig(shift_boards(late, together.offsets + [0, 0, 3, 0]), cameras=cameras, origin="camera").rig
    np.testing.assert_allclose(rig.centers, calibrate_rig(shift_boards(caliscope_views, together.offsets),
                                                          cameras=cameras, origin="camera").rig.centers, atol=0.01)


def test_caliscope_extrinsics_from_its_intrinsics(caliscope_views, caliscope_reference):
    given = [Camera(f"cam_{i}", c["size"], c["matrix"], c["distortions"]) for i, c in enumerate(caliscope_reference)]
    result = calibrate_rig(caliscope_views, cameras=given, origin="camera")
    assert result.rms.max() < 1.0
    assert np.isnan(result.intrinsic_rms).all()
    for ours, theirs in zip(result.rig, given):  # not refined when given
        np.testing.assert_array_equal(ours.matrix, theirs.matrix)
    # In camera 0's frame (fixed intrinsics leave no room for a tilt): centres within 1 cm.
    theirs = _caliscope_centres(caliscope_reference)
    rotation0 = np.array(caliscope_reference[0]["rotation"])
    np.testing.assert_allclose(result.rig[0].rotation_matrix, np.eye(3), atol=1e-12)
    np.testing.assert_allclose(result.rig.centers, (theirs - theirs[0]) @ rotation0.T, atol=0.01)


# -- synthetic rigs with known truth ---------------------------------------------------
def _synthetic_views(rig, board, n_poses, seed, noise_px=0.3):
    """Board poses around the cage's middle facing random directions; pixels (C, T, N, 2) with noise."""
    rng = np.random.default_rng(seed)
    middle = board.object_points.mean(axis=0)
    poses = np.zeros((n_poses, 4, 4))
    pixels = np.full((len(rig), n_poses, board.n_corners, 2), np.nan)
    for t in range(n_poses):
        centre = np.array([0.0, 0.0, 1.0]) + rng.uniform(-0.15, 0.15, 3)
        facing = rng.uniform(-1, 1, 3) * [1.2, 0.7, 0.3] + [0.0, 0.0, 1.0] - centre
        facing /= np.linalg.norm(facing)  # the printed face looks this way; the board's z is the opposite
        x = np.cross(-facing, [0.0, 0.0, 1.0])
        x /= np.linalg.norm(x)
        rotation = Rotation.from_rotvec(-facing * rng.uniform(-np.pi, np.pi)).as_matrix() \
            @ np.stack([x, np.cross(-facing, x), -facing], axis=1)
        poses[t] = np.eye(4)
        poses[t, :3, :3], poses[t, :3, 3] = rotation, centre - rotation @ middle
        projected, _ = rig.project(board.object_points @ rotation.T + poses[t, :3, 3])
        for c, camera in enumerate(rig):
            towards = camera.center - centre
            if facing @ towards > np.cos(np.radians(70)) * np.linalg.norm(towards) \
                    and camera.in_image(projected[c]).all():
                pixels[c, t] = projected[c] + rng.normal(0.0, noise_px, projected[c].shape)
    return poses, pixels


def _detections(board, pixels, rig):
    t_count = pixels.shape[1]
    return [BoardDetections(board, pixels[c], camera.size, f"{camera.name}.mp4",
                            [f"{camera.name}.mp4 frame {t}" for t in range(t_count)], np.arange(t_count))
            for c, camera in enumerate(rig)]


@pytest.fixture(scope="module")
def synthetic():
    board = parse_board("charuco:7x5:0.04")
    rig = cage_rig(4, seed=1)
    poses, pixels = _synthetic_views(rig, board, 40, seed=0)
    return board, rig, poses, pixels


def test_bundle_adjustment_recovers_a_known_rig(synthetic):
    board, truth, poses, pixels = synthetic
    rng = np.random.default_rng(3)
    start = []
    for c, camera in enumerate(truth):
        matrix = camera.matrix.copy()
        matrix[[0, 1], [0, 1]] *= 1 + rng.uniform(-0.03, 0.03)
        if c == 0:  # the first camera's pose sets the frame; its intrinsics are free
            start.append(Camera(camera.name, camera.size, matrix, camera.distortions, camera.rotation,
                                camera.translation))
            continue
        turn = Rotation.from_rotvec(rng.normal(0, np.radians(2), 3)).as_matrix() @ camera.rotation_matrix
        centre = camera.center + rng.normal(0, 0.05, 3)
        start.append(Camera(camera.name, camera.size, matrix, np.zeros(5), Rotation.from_matrix(turn).as_rotvec(),
                            -turn @ centre))
    jitter = np.array([np.eye(4)] * len(poses))
    jitter[:, :3, :3] = Rotation.from_rotvec(rng.normal(0, np.radians(2), (len(poses), 3))).as_matrix()
    jitter[:, :3, 3] = rng.normal(0, 0.02, (len(poses), 3))
    result = bundle_adjust(pixels, board, CameraRig(start), poses @ jitter, refine_intrinsics=True)
    assert result.success
    np.testing.assert_allclose(result.rig.centers, truth.centers, atol=0.004)
    for ours, camera in zip(result.rig, truth):
        np.testing.assert_allclose(ours.matrix[[0, 1], [0, 1]], camera.matrix[[0, 1], [0, 1]], rtol=0.005)
        # (turning a long lens trades against moving its principal point: a loose bound)
        assert np.degrees(Rotation.from_matrix(ours.rotation_matrix @ camera.rotation_matrix.T).magnitude()) < 1.0
    assert np.all(np.abs(result.rms - 0.3 * np.sqrt(2)) < 0.05)  # the noise, no more
    seen = np.isfinite(result.board2world[:, 0, 0])
    np.testing.assert_array_equal(seen, np.isfinite(pixels[..., 0]).any(axis=(0, 2)))
    np.testing.assert_allclose(result.board2world[seen, :3, 3], poses[seen, :3, 3], atol=0.004)


def test_calibrate_rig_from_scratch_recovers_a_known_rig(synthetic):
    board, truth, poses, pixels = synthetic
    result = calibrate_rig(_detections(board, pixels, truth))
    assert result.names == truth.names  # from the sources' file names
    ours = result.rig.centers
    rotation, translation = kabsch(ours, truth.centers)
    assert np.linalg.norm(ours @ rotation.T + translation - truth.centers, axis=1).max() < 0.005
    for camera, reference in zip(result.rig, truth):
        np.testing.assert_allclose(camera.matrix[0, 0], reference.matrix[0, 0], rtol=0.005)
    # The world is the board at the first frame camera 0 sees: camera centres in that board's frame, turned.
    first = int(np.flatnonzero(np.isfinite(pixels[0, :, 0, 0]))[0])
    expected = (truth.centers - poses[first, :3, 3]) @ poses[first, :3, :3] * [1, -1, -1]
    np.testing.assert_allclose(ours, expected, atol=0.01)
    assert len(result.tree) == 3 and "origin" in result.summary()


def test_origin_at_another_frame_or_camera(synthetic):
    board, truth, poses, pixels = synthetic
    detections = _detections(board, pixels, truth)
    seen = np.flatnonzero(np.isfinite(pixels[:, :, 0, 0]).any(axis=0))
    frame = int(seen[-1])
    known = list(truth)  # known intrinsics keep this quick
    result = calibrate_rig(detections, cameras=known, origin_frame=frame)
    np.testing.assert_allclose(result.board2world[frame], FLIP, atol=1e-9)
    camera = calibrate_rig(detections, cameras=known, origin="camera")
    np.testing.assert_allclose(camera.rig[0].world2camera, np.eye(4), atol=1e-12)
    unseen = int(np.setdiff1d(np.arange(pixels.shape[1]), seen)[0]) if len(seen) < pixels.shape[1] else 999
    with pytest.raises(HandcapError, match=f"origin_frame {unseen} is not a frame"):
        calibrate_rig(detections, cameras=known, origin_frame=unseen)


# -- rendered ChArUco images through the command line ----------------------------------
def _look_at(name, centre, focal=800.0, size=(640, 480)):
    z = -centre / np.linalg.norm(centre)  # towards the origin
    x = np.cross(z, [0.0, 0.0, 1.0])
    x /= np.linalg.norm(x)
    rotation = np.stack([x, np.cross(z, x), z])
    matrix = [[focal, 0.0, (size[0] - 1) / 2], [0.0, focal, (size[1] - 1) / 2], [0.0, 0.0, 1.0]]
    return Camera(name, size, matrix, rotation=Rotation.from_matrix(rotation).as_rotvec(),
                  translation=-rotation @ centre)


def _render(camera, board, board2world, pixels_per_metre=1000.0):
    """The board as ``camera`` sees it (no lens distortion), grey background."""
    picture = board.opencv_charuco().generateImage((round(board.columns * board.square * pixels_per_metre),
                                                    round(board.rows * board.square * pixels_per_metre)),
                                                   marginSize=0, borderBits=1)
    # board metres -> picture pixels (pixel centres at +0.5), then metres -> camera pixels
    metres2picture = np.array([[pixels_per_metre, 0, -0.5], [0, pixels_per_metre, -0.5], [0, 0, 1.0]])
    homography = (camera.projection @ board2world)[:, [0, 1, 3]] @ np.linalg.inv(metres2picture)
    return cv2.warpPerspective(picture, homography, camera.size, flags=cv2.INTER_AREA, borderValue=90)


@pytest.fixture(scope="module")
def rendered(tmp_path_factory):
    board = parse_board("charuco:5x7:0.04")
    folder = tmp_path_factory.mktemp("rendered")
    angles = np.radians([-40.0, 0.0, 40.0])
    rig = CameraRig([_look_at(f"cam_{i}", 0.8 * np.array([np.sin(a), -np.cos(a), 0.3]))
                     for i, a in enumerate(angles)])
    rng = np.random.default_rng(5)
    middle = board.object_points.mean(axis=0)
    upright = np.array([[1.0, 0, 0], [0, 0, 1], [0, -1, 0]])  # board z along +y, away from the cameras
    for c in range(len(rig)):
        (folder / f"cam_{c}").mkdir()
    for t in range(16):
        rotation = Rotation.from_rotvec(rng.uniform(-0.6, 0.6, 3)).as_matrix() @ upright
        pose = np.eye(4)
        pose[:3, :3], pose[:3, 3] = rotation, rng.uniform(-0.08, 0.08, 3) - rotation @ middle
        for c, camera in enumerate(rig):
            cv2.imwrite(str(folder / f"cam_{c}" / f"frame{t}.png"), _render(camera, board, pose))
    return board, rig, folder


def test_cli_rig_on_rendered_images(rendered, tmp_path, capsys):
    board, truth, folder = rendered
    out = tmp_path / "rig.toml"
    assert main(["calibrate", "rig", *(str(folder / f"cam_{c}") for c in range(3)), "--board", board.spec,
                 "--names", "left,middle,right", "--origin", "camera", "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "rig RMS" in printed and "left" in printed and str(out) in printed
    rig = read_cameras_toml(out)
    assert rig.names == ("left", "middle", "right")
    ours = rig.centers
    rotation, translation = kabsch(ours, truth.centers)
    assert np.linalg.norm(ours @ rotation.T + translation - truth.centers, axis=1).max() < 0.005
    np.testing.assert_allclose([c.matrix[0, 0] for c in rig], 800.0, rtol=0.01)


def test_cli_rig_on_caliscope_videos_with_its_intrinsics(shared_data, caliscope_reference, tmp_path, capsys):
    """With --sync auto (the path without it runs on rendered images above): its offsets are a fraction of a frame,
    and the rig lands where caliscope put it."""
    out = tmp_path / "rig.toml"
    videos = [str(shared_data / CALISCOPE / f"cam_{i}.mp4") for i in range(4)]
    assert main(["calibrate", "rig", *videos, "--board", CALISCOPE_BOARD, "--every", "2", "--origin", "camera",
                 "--intrinsics", str(shared_data / CALISCOPE / "camera_array.toml"), "--sync", "auto",
                 "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "board seen at 24 of 24 instants" in printed and "synchronised to cam_0 from 6 pairs" in printed
    rig = read_cameras_toml(out)
    assert rig.names == ("cam_0", "cam_1", "cam_2", "cam_3")
    theirs = _caliscope_centres(caliscope_reference)
    np.testing.assert_allclose(rig.centers, (theirs - theirs[0]) @ np.array(caliscope_reference[0]["rotation"]).T,
                               atol=0.015)


def test_cli_intrinsics(shared_data, tmp_path, capsys):
    out = tmp_path / "left.toml"
    images = sorted(str(p) for p in (shared_data / OPENCV).glob("left*.jpg"))
    assert main(["calibrate", "intrinsics", *images, "--board", "checkerboard:9x6:0.025", "--name", "left",
                 "--out", str(out)]) == 0
    assert "reprojection RMS" in capsys.readouterr().out
    rig = read_cameras_toml(out)
    assert rig.names == ("left",) and rig[0].size == (640, 480)
    np.testing.assert_allclose(rig[0].matrix[0, 0], 534.8, rtol=0.01)  # OpenCV's M1
    np.testing.assert_array_equal(rig[0].translation, 0.0)


# -- bad input -------------------------------------------------------------------------
@pytest.mark.parametrize("spec, message", [
    ("checkerboard:9x6", "incomplete"),
    ("chess:9x6:0.025", "unknown kind 'chess'"),
    ("checkerboard:9by6:0.025", "must be COLSxROWS"),
    ("checkerboard:9x6:25", "give it in metres"),
    ("checkerboard:9x6:-0.02", "positive number of metres"),
    ("checkerboard:2x6:0.02", "columns must be a whole number of inner corners >= 3"),
    ("checkerboard:9x6:0.025:0.01", "a checkerboard takes only"),
    ("charuco:4x5:0.054:0.06", "marker size must be positive and less than the square"),
    ("charuco:4x5:0.054:DICT_9X9_50", "unknown ArUco dictionary 'DICT_9X9_50'"),
    ("charuco:20x20:0.01:DICT_4X4_50", "needs 200 markers but DICT_4X4_50 has 50"),
    ("charuco:4x5:0.054:0.04:0.03", "gives the marker twice"),
])
def test_bad_board_specs(spec, message):
    with pytest.raises(HandcapError, match=message):
        parse_board(spec)


def test_board_specs_read_back():
    board = parse_board("charuco:4x5:0.054:inverted:4x4_1000")
    assert (board.marker, board.dictionary, board.inverted) == (pytest.approx(0.0405), "DICT_4X4_1000", True)
    assert parse_board(board.spec) == board
    assert board.n_corners == 12 and board.object_points[0].tolist() == [0.054, 0.054, 0.0]
    checker = parse_board("checkerboard:9x6:0.025")
    assert checker.n_corners == 54 and checker.object_points[10].tolist() == [0.025, 0.025, 0.0]


def test_unreadable_files_are_named(tmp_path):
    board = parse_board("checkerboard:9x6:0.025")
    broken = tmp_path / "broken.png"
    broken.write_bytes(b"not an image")
    with pytest.raises(HandcapError, match="broken.png: not a readable image"):
        detect_in_files([broken], board)
    video = tmp_path / "broken.mp4"
    video.write_bytes(b"not a video" * 100)
    with pytest.raises(HandcapError, match="broken.mp4: not a readable video"):
        detect_in_video(video, board)
    with pytest.raises(HandcapError, match="absent.mp4: no such file"):
        detect_in_files(tmp_path / "absent.mp4", board)
    (tmp_path / "empty").mkdir()
    with pytest.raises(HandcapError, match="empty: no images"):
        detect_in_files(tmp_path / "empty", board)


def test_a_board_never_seen_is_named(opencv_views, synthetic):
    views = opencv_views["left"]
    blind = BoardDetections(views.board, np.full_like(views.pixels, np.nan), views.size, "blind.mp4",
                            views.labels, views.frames)
    with pytest.raises(HandcapError, match="blind.mp4: the board checkerboard:9x6:0.025 is never seen"):
        calibrate_intrinsics(blind)
    board, rig, _, pixels = synthetic
    pixels = pixels.copy()
    pixels[2] = np.nan
    with pytest.raises(HandcapError, match=r"never seen by camera cam_2 \(cam_2.mp4\)"):
        calibrate_rig(_detections(board, pixels, rig))


def test_a_disconnected_camera_is_named(synthetic):
    board, rig, _, pixels = synthetic
    pixels = pixels.copy()
    seen = np.isfinite(pixels[:, :, 0, 0])
    pixels[2, seen[[0, 1, 3]].any(axis=0)] = np.nan  # cam_2 sees the board only alone
    assert np.isfinite(pixels[2, :, 0, 0]).any()
    with pytest.raises(HandcapError, match="camera cam_2 shares no board view with cam_0, cam_1, cam_3"):
        calibrate_rig(_detections(board, pixels, rig), cameras=list(rig))
    pixels[1, seen[[0, 3]].any(axis=0)] = np.nan  # and cam_1 only with cam_2
    with pytest.raises(HandcapError, match="cameras cam_1, cam_2 share no board view with cam_0, cam_3"):
        calibrate_rig(_detections(board, pixels, rig), cameras=list(rig))


def test_mismatched_frame_counts_are_named(synthetic):
    board, rig, _, pixels = synthetic
    detections = _detections(board, pixels, rig)
    short = detections[1]
    detections[1] = BoardDetections(board, short.pixels[:-1], short.size, short.source, short.labels[:-1],
                                    short.frames[:-1])
    with pytest.raises(HandcapError, match=r"different frame counts: cam_0 \(cam_0.mp4\) 40, cam_1 \(cam_1.mp4\) 39"):
        calibrate_rig(detections)


def test_an_ambiguous_checkerboard_is_refused_for_a_rig(opencv_views):
    views = opencv_views["left"]
    board = parse_board("checkerboard:8x6:0.025")
    fake = BoardDetections(board, np.full((13, 48, 2), np.nan), views.size, "a", views.labels, views.frames)
    with pytest.raises(HandcapError, match="looks the same turned half round"):
        calibrate_rig([fake, fake])


def _one_error_line(capsys, verb="calibrate"):
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith(f"handcap {verb}: error: ")
    return err


def test_cli_errors_exit_2_with_one_line_and_write_nothing(shared_data, tmp_path, capsys):
    out = tmp_path / "cam.toml"
    images = sorted(str(p) for p in (shared_data / OPENCV).glob("left0*.jpg"))
    videos = [str(shared_data / CALISCOPE / f"cam_{i}.mp4") for i in range(2)]
    cases = [
        (["intrinsics", *images, "--board", "checkerboard:9x6"], "incomplete"),
        (["intrinsics", *images[:3], "--board", "charuco:5x7:0.03"], "no ArUco markers of any dictionary"),
        (["intrinsics", str(tmp_path / "absent.jpg"), "--board", "checkerboard:9x6:0.025"], "absent.jpg: no such file"),
        (["rig", *videos, "--board", CALISCOPE_BOARD, "--every", "0"], "every must be a whole number"),
        (["rig", *videos, "--board", CALISCOPE_BOARD, "--names", "a"], "1 camera names for 2 cameras"),
    ]
    for args, message in cases:
        assert main(["calibrate", *args, "--out", str(out)]) == 2
        assert message in _one_error_line(capsys)
        assert not out.exists()
    assert main(["calibrate", "intrinsics", *images, "--board", "checkerboard:9x6:0.025",
                 "--out", str(tmp_path / "cam.yml")]) == 2
    assert "anipose-style .toml" in _one_error_line(capsys)
    assert main(["calibrate", "intrinsics", images[0], "--board", "checkerboard:9x6:0.025", "--out", images[0]]) == 2
    _one_error_line(capsys)


def test_cli_rig_names_cameras_of_unequal_length(shared_data, tmp_path, capsys):
    folder = tmp_path / "short"
    folder.mkdir()
    for i, path in enumerate(sorted((shared_data / OPENCV).glob("right*.jpg"))[:5]):
        (folder / f"{i:02d}.jpg").write_bytes(path.read_bytes())
    out = tmp_path / "rig.toml"
    assert main(["calibrate", "rig", str(shared_data / OPENCV), str(folder), "--board", "checkerboard:9x6:0.025",
                 "--out", str(out)]) == 2
    err = _one_error_line(capsys)
    assert "different frame counts" in err and "opencv_stereo) 26" in err and "short) 5" in err
    assert not out.exists()
