"""Hand and object of a steady grasp from one video: ICP, the object carried by the virtual cameras, the hand's
size measured against the contacts, and the refinement, against synthetic grasps with exact truth."""

import numpy as np
import pytest
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation

from handcap import HandcapError
from handcap.cli import main
from handcap.io import read_object_motion
from handcap.markerless.contact import contact_figures
from handcap.markerless.grasp import (capture_grasp, carry_object, hand_poses, object_pose_from_points,
                                     scale_from_contact)
from handcap.markerless.keypoints import hand_names
from handcap.markerless.synthetic import grasp_object_video
from handcap.multiview.detections import Detections, write_detections


@pytest.fixture(scope="module")
def grasp():
    return grasp_object_video("precision", "cuboid", 60, np.random.default_rng(1), noise_px=3.0)


def _true_poses(g):
    poses = np.zeros((len(g.video.rotation), 4, 4))
    poses[:, :3, :3] = Rotation.from_rotvec(g.video.rotation).as_matrix()
    poses[:, :3, 3] = g.video.translation
    poses[:, 3, 3] = 1.0
    return poses


def _perturbed(pose, rng, degrees=5.0, metres=0.005):
    out = pose.copy()
    axis = rng.normal(size=3)
    out[:3, :3] = Rotation.from_rotvec(axis / np.linalg.norm(axis) * np.deg2rad(degrees)).as_matrix() @ pose[:3, :3]
    out[:3, 3] += rng.normal(0.0, metres / np.sqrt(3), 3)
    return out


def _surface_error(vertices, estimated, truth):
    """Mean distance (metres) of the mesh posed by ``estimated`` to the one posed by ``truth`` (symmetry-blind)."""
    est = vertices @ estimated[:3, :3].T + estimated[:3, 3]
    true = vertices @ truth[:3, :3].T + truth[:3, 3]
    return cKDTree(true).query(est)[0].mean()


def test_the_virtual_cameras_carry_the_object_exactly_with_true_poses(grasp):
    carried = carry_object(_true_poses(grasp), 0, grasp.object_poses[0])
    assert np.abs(carried - grasp.object_poses).max() < 1e-9
    # the true object poses differ from frame to frame: the check above can fail
    assert np.abs(grasp.object_poses - grasp.object_poses[0]).max() > 0.01


def test_icp_recovers_the_object_pose_from_a_partial_noisy_view(grasp):
    cm = grasp.contact_map
    # a start 5 degrees and 5 mm off (the grasp settling, the paper's T_adj); from 15 degrees ICP can stop in a
    # local minimum 2-7 mm off on this view
    start = _perturbed(grasp.object_poses[0], np.random.default_rng(2), degrees=5.0, metres=0.005)
    pose, distance, notes = object_pose_from_points(cm.vertices, cm.faces, grasp.points, start)

    def error(p):  # mean distance of each vertex from its true place, metres
        return np.linalg.norm(cm.vertices @ (p[:3, :3] - grasp.object_poses[0, :3, :3]).T + p[:3, 3]
                              - grasp.object_poses[0, :3, 3], axis=1).mean()

    assert error(start) > 0.008
    assert error(pose) < 0.0018
    assert distance < 0.001 and not notes


def test_icp_without_a_start_warns_when_the_shape_is_symmetric(grasp):
    cm = grasp.contact_map
    _, distance, notes = object_pose_from_points(cm.vertices, cm.faces, grasp.points)
    assert distance < 0.001  # the points fit (some symmetric pose of the box)
    assert any("equally well" in n for n in notes)


def test_points_that_are_not_the_object_are_reported(grasp):
    cm = grasp.contact_map
    scattered = grasp.points + np.random.default_rng(0).normal(0, 0.01, grasp.points.shape)  # 1 cm noise
    _, _, notes = object_pose_from_points(cm.vertices, cm.faces, scattered, grasp.object_poses[0])
    assert any("from its fitted mesh" in n for n in notes)
    with pytest.raises(HandcapError):
        object_pose_from_points(cm.vertices, cm.faces, np.zeros((3, 3)))


def test_the_hands_size_is_measured_against_the_contacts(grasp):
    poses = _true_poses(grasp)
    hand = grasp.hand
    skin = hand.forward(np.zeros(10), np.zeros(3), None, np.zeros(3), phi=grasp.video.phi).vertices
    true = skin @ poses[0, :3, :3].T + poses[0, :3, 3]  # the true hand in the camera
    for factor in (0.87, 1.0, 1.12):
        # a hand assumed 1/factor times its size, scaled about the camera centre: the measure must undo it
        measured = scale_from_contact(true / factor, grasp.contact_map, grasp.object_poses[0])
        assert measured == pytest.approx(factor, abs=0.01)


def test_capture_grasp_places_the_object_and_refines_the_hand(grasp):
    cm = grasp.contact_map
    result = capture_grasp(grasp.video.pixels, grasp.video.camera, cm.vertices, cm.faces,
                           object_points=grasp.points, object_pose=_perturbed(grasp.object_poses[0],
                                                                              np.random.default_rng(2)),
                           contact_map=cm)
    motion, obj = result.video.motion, result.object_motion
    assert obj.n_frames == 60 and motion.n_frames == 60
    est = np.zeros((60, 4, 4))
    est[:, :3, :3] = Rotation.from_rotvec(obj.rotation).as_matrix()
    est[:, :3, 3] = obj.translation
    est[:, 3, 3] = 1.0
    errors = [_surface_error(cm.vertices, est[t], grasp.object_poses[t]) for t in range(0, 60, 6)]
    assert np.mean(errors) < 0.012  # the virtual cameras' error, carried (the object is 5-12 cm)

    def truth(m):
        """The hand against the true object, in the estimated object's frame (the hand-object relation)."""
        v = grasp.hand.forward(m.betas, m.global_orient[0], m.hand_pose[0], m.transl[0]).vertices
        return contact_figures((v - est[0, :3, 3]) @ est[0, :3, :3], grasp.hand.faces, cm, grasp.obj.signed_distance)

    before, after = truth(result.before), truth(motion)
    # the size measured against the contacts already puts the hand on them (about 1 mm here); the refinement
    # keeps it there and takes the hand out of the object
    assert after["contact_mm"] < 2.5 and after["contact_mm"] < before["contact_mm"] + 0.5
    assert after["penetration_max_mm"] < 3.0
    assert 0.97 < result.scale < 1.08  # the keypoints' offsets make the average hand's palm look 1-4 % larger
    # every frame holds the refined pose, and the hand keeps its relation to the object in every frame
    assert np.allclose(motion.phi, motion.phi[0])
    rel = np.linalg.inv(est) @ hand_poses(motion, grasp.hand)
    assert np.abs(rel - rel[0]).max() < 1e-6
    assert result.figures["contact_mm"][1] < result.figures["contact_mm"][0]


def test_capture_grasp_bad_input(grasp):
    cm = grasp.contact_map
    px, cam = grasp.video.pixels, grasp.video.camera
    with pytest.raises(HandcapError, match="pose or points"):
        capture_grasp(px, cam, cm.vertices, cm.faces)
    with pytest.raises(HandcapError, match="outside"):
        capture_grasp(px, cam, cm.vertices, cm.faces, object_pose=np.eye(4), frame=60)
    with pytest.raises(HandcapError, match="rigid"):
        capture_grasp(px, cam, cm.vertices, cm.faces, object_pose=2 * np.eye(4))


def test_markerless_verb_with_an_object(grasp, tmp_path, capsys):
    px = grasp.video.pixels
    t, k = np.nonzero(np.isfinite(px[..., 0]))
    det = Detections(("video",), hand_names("right"), t, np.zeros_like(t), k, px[t, k], np.ones(len(t)), 30.0, len(px))
    write_detections(det, tmp_path / "kp.npz")
    grasp.contact_map.save(tmp_path / "contact.npz")
    np.savez(tmp_path / "cloud.npz", points=grasp.points * 1000)  # millimetres, with --object-units mm
    pose = grasp.object_poses[0].copy()
    pose[:3, 3] *= 1000
    np.savetxt(tmp_path / "pose.txt", pose)
    c = grasp.video.camera
    intr = ",".join(str(float(v)) for v in [c.matrix[0][0], c.matrix[1][1], c.matrix[0][2], c.matrix[1][2],
                                            *c.distortions])
    import trimesh
    trimesh.Trimesh(grasp.contact_map.vertices * 1000, grasp.contact_map.faces).export(tmp_path / "box.ply")
    base = ["markerless", str(tmp_path / "kp.npz"), "--intrinsics", intr, "--out", str(tmp_path / "m.npz")]
    assert main(base + ["--object", str(tmp_path / "box.ply"), "--object-pose", str(tmp_path / "pose.txt"),
                        "--object-points", str(tmp_path / "cloud.npz"), "--object-units", "mm",
                        "--contact", str(tmp_path / "contact.npz")]) == 0
    obj = read_object_motion(tmp_path / "m-object.npz")
    assert obj.n_frames == 60 and obj.name == "box"
    assert np.linalg.norm(obj.translation[0] - grasp.object_poses[0, :3, 3]) < 0.003
    out = capsys.readouterr().out
    assert "contact" in out and "carried" in out
    # bad input: one clear line, exit 2, nothing written
    for extra, message in ((["--object", str(tmp_path / "box.ply"), "--object-pose", str(tmp_path / "pose.txt")],
                            "across"),
                           (["--object-pose", str(tmp_path / "pose.txt")], "need the object"),
                           (["--contact", str(tmp_path / "contact.npz"), "--object-pose", str(tmp_path / "kp.npz")],
                            "object pose"),
                           (["--contact", str(tmp_path / "contact.npz"), "--object-pose", str(tmp_path / "pose.txt"),
                             "--object-frame", "99", "--object-units", "mm"], "outside")):
        assert main(base[:-1] + [str(tmp_path / "bad.npz")] + extra) == 2
        assert message in capsys.readouterr().err
        assert not (tmp_path / "bad.npz").exists() and not (tmp_path / "bad-object.npz").exists()


def test_markerless_demo_meets_its_figures(tmp_path, capsys):
    from handcap.steps.markerless_demo import run_markerless_demo

    summary = run_markerless_demo(tmp_path / "demo", frames=40)
    assert summary["keypoint_error_pa_mm"] < 5.0 and summary["joint_angle_error_deg"] < 8.0
    _, after = summary["contact_distance_mm_before_after"]
    assert after < 3.0
    assert summary["object_surface_error_mm"] < 12.0
    for name in ("keypoints.npz", "camera.toml", "box.ply", "contact.npz", "box_points.npz", "motion.npz",
                 "motion-object.npz", "summary.json"):
        assert (tmp_path / "demo" / name).is_file()
    # the command the summary prints repeats the capture from the demo's files
    args = summary["command"].split()[1:]
    args[args.index("--out") + 1] = str(tmp_path / "again.npz")
    assert main(args) == 0
    assert main(["demo", "--images", "--markerless", "--out", str(tmp_path / "x")]) == 2
    assert "choose one" in capsys.readouterr().err
