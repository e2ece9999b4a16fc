"""A hand turning the 2x2x2 cube (``synth --moves``): the truth is consistent, the hand hides cube markers,
the riding finger follows its layer, and the tracker recovers the moves, pose and layers from the take."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from handcap.cli import main
from handcap.hand import OpenHand
from handcap.objects.articulated import load_articulated
from handcap.objects.cube import FACE_ORDER, FACES, apply_moves, cube_signed_distance, solved_state
from handcap.objects.cube_output import cube_errors
from handcap.objects.cube_track import track_cube
from handcap.synth.cube import cube_rotations, turning_motion
from handcap.synth.scene import SynthConfig, synthesize

CUBE = load_articulated("cube2x2")


def test_the_24_rotations_of_a_cube():
    rots = cube_rotations()
    assert len(rots) == 24 and len({r.tobytes() for r in rots}) == 24
    assert np.allclose(np.einsum("nji,njk->nik", rots, rots), np.eye(3))
    assert np.allclose(np.linalg.det(rots), 1.0)


def test_cube_signed_distance_against_a_box_and_a_turned_layer():
    pose = np.eye(4)[None]
    points = np.array([[[0.01, 0.01, 0.01], [0.0, 0.0, 0.04], [0.03, 0.01, 0.01], [0.028, 0.028, 0.028]]])
    d = cube_signed_distance(points, pose, solved_state()[None].astype(float))[0]
    assert np.isclose(d[0], -0.00975) and np.isclose(d[2], 0.03 - 0.02775)
    assert np.isclose(d[1], np.sqrt(2 * 0.00025 ** 2 + (0.04 - 0.02775) ** 2))  # the gap between cubies
    # the R layer turned 45 degrees: its corner sweeps out to 0.02775 * sqrt(2) about the x axis
    turned = solved_state().astype(float)
    right = np.array([0, 0, 0, 0, 1, 1, 1, 1], bool)
    turned[right] = Rotation.from_rotvec([-np.pi / 4, 0, 0]).as_matrix()
    corner = np.array([[[0.02, 0.0, 0.0385]]])
    assert cube_signed_distance(corner, pose, turned[None])[0, 0] < 0 < \
        cube_signed_distance(corner, pose, solved_state()[None].astype(float))[0, 0]


def test_turning_motion_rides_the_layer_and_ends_in_the_moves_state():
    hand = OpenHand("right")
    take = turning_motion(hand, "R U' F2", 100.0, np.random.default_rng(3))
    assert (take.state == apply_moves(solved_state(), "R U' F2")).all()
    assert np.allclose(take.cubie_rotation[-1], take.state) and take.motion.holding.all()
    assert len(take.motion.phi) == len(take.cube_pose) == len(take.layer_angle)
    out = hand.forward(np.zeros(10), take.motion.global_orient, hand.hand_pose_from_phi(take.motion.phi),
                       take.motion.transl)
    # the cube is held: the thumb and two fingertips stay within a finger's thickness of its surface
    tips = cube_signed_distance(out.joints[:, 16:19], take.cube_pose, take.cubie_rotation)
    assert np.median(tips) < 0.009 and np.percentile(tips, 95) < 0.012
    rode = 0
    for finger, (face, turns), (a, b) in zip(take.riding, take.moves, take.move_frames):
        if finger and abs(turns) == 1:  # the riding tip turns with its layer
            j = {"thumb": 16, "index": 17, "middle": 18}[finger]
            world = out.joints[a:b + 1, j]
            in_cube = np.einsum("tji,tj->ti", take.cube_pose[a:b + 1, :3, :3], world - take.cube_pose[a:b + 1, :3, 3])
            angle = take.layer_angle[a:b + 1, FACE_ORDER.index(face)]  # clockwise seen from the face
            in_layer = Rotation.from_rotvec(np.outer(angle, FACES[face])).apply(in_cube)
            assert np.linalg.norm(in_layer - in_layer[0], axis=1).max() < 0.006
            assert np.linalg.norm(in_cube[-1] - in_cube[0]) > 0.02  # while it travelled with the layer
            rode += 1
    assert rode >= 1
    # the skin presses into the cube no deeper than the grip's soft tissue, but in a few frames
    depth = cube_signed_distance(out.vertices, take.cube_pose, take.cubie_rotation).min(axis=1)
    assert np.median(depth) > -0.0035 and np.mean(depth < -0.006) < 0.05


def test_hand_hides_cube_markers_and_the_tracker_finds_moves_pose_and_layers():
    config = SynthConfig(motion="turn-cube", moves="R U' F2 D", seed=4, noise_mm=0.5, rate=100.0, cameras=8)
    capture = synthesize(config, progress=False)
    markers = capture.markers.select(list(CUBE.marker_names)).positions
    seen = np.isfinite(markers).all(axis=2)
    assert 0.6 < seen.mean() < 0.995  # the hand (and the cube itself) hide some
    track = track_cube(markers, CUBE)
    assert track.moves == "R U' F2 D" == str(capture.truth["cube_moves"])
    om = capture.object_motion
    pose = np.tile(np.eye(4), (len(markers), 1, 1))
    pose[:, :3, :3], pose[:, :3, 3] = Rotation.from_rotvec(om.rotation).as_matrix(), om.translation
    errors = cube_errors(track, pose, capture.truth["cube_cubie_rotation"])
    assert np.nanmean(errors["position_mm"]) < 0.5 and np.nanmax(errors["position_mm"]) < 1.0
    assert np.nanmean(errors["rotation_deg"]) < 0.6 and np.nanmax(errors["rotation_deg"]) < 1.5
    assert np.nanmax(errors["layer_deg"]) < 2.0


def test_synth_verb_with_moves_and_its_bad_inputs(tmp_path, capsys):
    out = tmp_path / "take"
    assert main(["synth", "--moves", "R U'", "--out", str(out), "--cameras", "6", "--rate", "60"]) == 0
    with np.load(out / "truth.npz") as truth:
        assert str(truth["cube_moves"]) == "R U'" and truth["cube_layer_angle"].shape[1] == 6
        assert "UFR_R" in [str(n) for n in truth["names"]]
    assert main(["track-object", str(out / "markers.c3d"), "--articulated", "cube2x2",
                 "--out", str(tmp_path / "cube.npz")]) == 0
    assert "R U'" in capsys.readouterr().out
    for argv, message in ((["--moves", "R X U"], "move 'X'"), (["--moves", "R", "--object", "cuboid"], "turn-cube"),
                          (["--moves", "R", "--motion", "grasp"], "turn-cube"), (["--moves", " "], "at least one")):
        assert main(["synth", *argv, "--out", str(tmp_path / "bad")]) == 2
        err = capsys.readouterr().err
        assert message in err and len(err.strip().splitlines()) == 1, err
        assert not (tmp_path / "bad").exists()


@pytest.mark.parametrize("moves", ["R R'", "U2 U2"])
def test_moves_that_undo_each_other_leave_the_cube_solved(moves):
    take = turning_motion(OpenHand("right"), moves, 60.0, np.random.default_rng(0))
    assert (take.state == solved_state()).all()


def test_marker_path_on_a_cube_take_solve_and_cube_metrics(tmp_path, capsys):
    """Track the cube, solve the hand (true attachment), and score both with the cube's own metrics."""
    import json

    from handcap.synth.scene import write_capture

    capture = synthesize(SynthConfig(motion="turn-cube", moves="R U'", seed=5, noise_mm=0.5, rate=60.0, cameras=8),
                         progress=False)
    write_capture(capture, tmp_path)
    capture.attachment.save(tmp_path / "attachment.npz")
    assert main(["track-object", str(tmp_path / "markers.c3d"), "--articulated", "cube2x2",
                 "--out", str(tmp_path / "cube.npz")]) == 0
    assert main(["solve", str(tmp_path / "markers.c3d"), "--attachment", str(tmp_path / "attachment.npz"),
                 "--out", str(tmp_path / "motion.npz")]) == 0
    capsys.readouterr()
    for motion in ("truth", "motion"):
        assert main(["metrics", str(tmp_path / f"{motion}.npz"), "--object", str(tmp_path / "cube.npz"),
                     "--truth", str(tmp_path / "truth.npz"), "--out", str(tmp_path / f"{motion}.json")]) == 0
    assert "cube moves             R U'" in capsys.readouterr().out
    truth = json.loads((tmp_path / "truth.json").read_text())
    solved = json.loads((tmp_path / "motion.json").read_text())
    assert truth["cube_moves"] == solved["cube_moves"] == "R U'" and truth["joint_error_mm"][0] < 1e-6
    # against an independent computation: the true hand's deepest vertex in the true cubies, frame by frame
    hand = OpenHand("right")
    hm = capture.hand_motion
    verts = hand.forward(hm.betas, hm.global_orient, hm.hand_pose, hm.transl).vertices
    om = capture.object_motion
    pose = np.tile(np.eye(4), (len(verts), 1, 1))
    pose[:, :3, :3], pose[:, :3, 3] = Rotation.from_rotvec(om.rotation).as_matrix(), om.translation
    depth = -cube_signed_distance(verts, pose, capture.truth["cube_cubie_rotation"]).min(axis=1)
    assert abs(truth["penetration_mm"][0] - 1000 * depth[depth > 0].mean()) < 0.3
    assert solved["joint_error_mm"][0] < 4.0 and 0 < solved["penetration_mm"][0] < 10.0
    assert truth["cube_msnr_db"] > 10 and truth["cube_jerk_m_s3"][0] > 0
