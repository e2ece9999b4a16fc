"""Single-video grasp capture: structure from motion (eq. 1) and the joint fit (eq. 2) on synthetic videos."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from handcap import HandcapError
from handcap.cli import main
from handcap.core.camera_rig import CameraRig
from handcap.hand import OpenHand
from handcap.markerless.capture import capture_video, video_keypoints
from handcap.markerless.keypoints import hand_names
from handcap.markerless.sfm import structure_from_motion, template_points
from handcap.markerless.synthetic import grasp_video
from handcap.multiview.detections import Detections, write_detections


def pa_error(a, b):
    """Mean distance (metres) of points a to b after the best similarity (Procrustes with scale, no mirror)."""
    a0, b0 = a - a.mean(0), b - b.mean(0)
    u, s, vt = np.linalg.svd(b0.T @ a0)
    d = np.diag([1.0, 1.0, np.sign(np.linalg.det(u @ vt))])
    rot = u @ d @ vt
    scale = (s * np.diag(d)).sum() / (a0 ** 2).sum()
    return np.linalg.norm(scale * a0 @ rot.T - b0, axis=1).mean()


@pytest.fixture(scope="module")
def video():
    return grasp_video(40, np.random.default_rng(5), noise_px=3.0, missing=0.1, wrong=0.02)


def test_structure_from_motion_recovers_the_hand(video):
    pixels = video.camera.undistort_pixels(video.pixels)
    structure = structure_from_motion(pixels, video.camera.matrix, template_points(OpenHand()))
    assert structure.placed.all()
    assert pa_error(structure.points, video.points) < 2e-3
    assert np.nanmedian(structure.residual_px) < 5.0
    # the template alone (no bundle adjustment) is far off: the check above can fail
    assert pa_error(template_points(OpenHand()), video.points) > 5e-3


def test_joint_fit_is_no_worse_than_two_stages(video):
    two = capture_video(video.pixels, video.camera, method="two-stage")
    joint = capture_video(video.pixels, video.camera, method="joint")
    for result in (two, joint):
        assert pa_error(result.structure.points, video.points) < 5e-3
        assert np.degrees(np.abs(result.motion.phi[0] - video.phi)).mean() < 8.0
        assert result.motion.joints.shape == (40, 21, 3) and np.isfinite(result.motion.joints).all()
    assert np.nanmedian(joint.structure.residual_px) <= np.nanmedian(two.structure.residual_px) + 0.05
    assert pa_error(joint.structure.points, video.points) <= pa_error(two.structure.points, video.points) + 0.5e-3
    # the motion is in the camera's frame: its keypoints project onto the given ones
    cam_points = joint.motion.marker_fit
    seen = np.isfinite(video.pixels[..., 0]) & ~video.wrong
    pixels, _ = video.camera.project(cam_points.reshape(-1, 3))
    err = np.linalg.norm(pixels.reshape(40, 21, 2) - video.pixels, axis=-1)[seen]
    assert np.median(err) < 6.0
    # with the learned offsets: the motion's keypoints are the structure's, seen as the fit saw them
    assert np.median(err) < np.nanmedian(joint.structure.residual_px) + 0.5


def test_bad_videos(video):
    with pytest.raises(HandcapError, match="no structure from motion"):
        capture_video(np.full((30, 21, 2), np.nan), video.camera)
    with pytest.raises(HandcapError, match="shape"):
        capture_video(np.zeros((30, 20, 2)), video.camera)
    with pytest.raises(HandcapError, match="method"):
        capture_video(video.pixels, video.camera, method="magic")


def test_video_keypoints_follow_the_hand_through_label_flips():
    rng = np.random.default_rng(0)
    track = rng.uniform(100, 200, (6, 21, 2))
    labels = ["right", "right", "left", "right", "left", "left"]  # the detector flips the label
    frame = np.repeat(np.arange(6), 21)
    names = hand_names("left") + hand_names("right")
    marker = np.array([names.index(f"{lab}:{n}") for lab in labels for n in hand_names()])
    det = Detections(("cam",), names, frame, np.zeros_like(frame), marker, track.reshape(-1, 2), np.ones(126),
                     30.0, 6)
    np.testing.assert_array_equal(video_keypoints(det), track)
    with pytest.raises(HandcapError, match="no camera"):
        video_keypoints(det, camera="other")


def test_command(video, tmp_path, capsys):
    t, k = np.nonzero(np.isfinite(video.pixels[..., 0]))
    det = Detections(("video",), hand_names("right"), t, np.zeros_like(t), k, video.pixels[t, k], np.ones(len(t)),
                     30.0, 40)
    write_detections(det, tmp_path / "kp.npz")
    CameraRig((video.camera,)).save(tmp_path / "cam.toml")
    assert main(["markerless", str(tmp_path / "kp.npz"), "--intrinsics", str(tmp_path / "cam.toml"), "--method",
                 "two-stage", "--out", str(tmp_path / "m.npz")]) == 0
    motion = np.load(tmp_path / "m.npz")
    assert np.degrees(np.abs(motion["phi"][0] - video.phi)).mean() < 8.0 and str(motion["side"]) == "right"
    assert main(["markerless", str(tmp_path / "kp.npz"), "--intrinsics", "1000,x,640,360", "--out",
                 str(tmp_path / "n.npz")]) == 2
    assert main(["markerless", str(tmp_path / "kp.npz"), "--intrinsics", "1000,1000,640,360", "--scale", "9",
                 "--out", str(tmp_path / "n.npz")]) == 2
    err = capsys.readouterr().err
    assert err.count("error:") == 2 and not (tmp_path / "n.npz").exists()


def test_a_frame_whose_pose_jumps_is_solved_again_from_its_neighbours(video):
    from handcap.markerless.sfm import continuous_poses

    pixels = video.camera.undistort_pixels(video.pixels)
    structure = structure_from_motion(pixels, video.camera.matrix, template_points(OpenHand()))
    assert continuous_poses(pixels, video.camera.matrix, structure).rotation == pytest.approx(structure.rotation)
    flipped = structure.rotation.copy()
    t = 17
    turn = Rotation.from_rotvec([0.0, np.pi, 0.0]) * Rotation.from_rotvec(flipped[t])  # 180 degrees off
    flipped[t] = turn.as_rotvec()
    broken = type(structure)(structure.points, flipped, structure.translation, structure.residual_px)
    repaired = continuous_poses(pixels, video.camera.matrix, broken)
    error = np.degrees((Rotation.from_rotvec(repaired.rotation[t]) * Rotation.from_rotvec(structure.rotation[t]).inv())
                       .magnitude())
    assert error < 2.0
    assert np.nanmedian(repaired.residual_px[t]) < 6.0


def test_learned_offsets_make_eq2_angles_better(video):
    import handcap.markerless.jointfit as jointfit

    pixels = video.camera.undistort_pixels(video.pixels)
    hand = OpenHand()
    two = capture_video(video.pixels, video.camera, method="two-stage")
    fitted_phi, betas = two.motion.phi[0], two.motion.betas
    rot, trans = two.structure.rotation, two.structure.translation
    errors = {}
    for offsets in (False, True):
        phi, _, structure = jointfit.joint_fit(pixels, video.camera.matrix, hand, two.two_stage, fitted_phi, betas, rot,
                                          trans, offsets=offsets)
        errors[offsets] = np.degrees(np.abs(phi - video.phi)).mean()
    assert errors[True] < errors[False], errors
