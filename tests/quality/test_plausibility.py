"""Plausibility checks: a plausible result gives no warning, a corrupted one the expected warning.

Plausible results come from handcap's synthetic captures (known truth); corruptions are the ones issue 14
met on real captures: units off by 1000, shape values at their bounds, spikes, stretched bones, a fit far
from its markers.
"""

import warnings

import numpy as np
import pytest

from handcap.core.errors import HandcapWarning
from handcap.core.markers import MarkerSequence
from handcap.core.motion import HandMotion
from handcap.hand.anthropometry import HAND_LENGTH, SEGMENT_RATIOS, rest_joints
from handcap.io import read_markers, write_markers
from handcap.quality import plausibility as p
from handcap.synth.scene import SynthConfig, synthesize


@pytest.fixture(scope="module")
def capture():
    return synthesize(SynthConfig(layout="glove-13", motion="open-close", frames=120, rate=60, seed=5,
                                  noise_mm=0.5, object="none"))


def _rest_joints(scale=1.0, frames=10):
    joints, tips = rest_joints()
    return scale * np.repeat(np.concatenate([joints, tips])[None], frames, axis=0)


# -- residuals, limits, shape ------------------------------------------------------------------------


def test_residuals_below_the_limit_give_no_warning():
    rng = np.random.default_rng(0)
    residuals = np.abs(rng.normal(0, 0.0015, (200, 13)))
    residuals[rng.random(residuals.shape) < 0.1] = np.nan
    assert p.residual_warnings(residuals) == []


def test_a_13_mm_fit_is_reported_with_its_value_and_the_limit():
    rng = np.random.default_rng(1)
    residuals = 0.013 + rng.normal(0, 0.001, (100, 19))
    (line,) = p.residual_warnings(residuals, what="solve MRE")
    assert f"solve MRE {1000 * residuals.mean():.2f} mm" in line and "<= 5 mm" in line


def test_one_bad_marker_is_named_without_an_overall_warning():
    residuals = np.full((50, 13), 0.001)
    residuals[:, 4] = 0.009
    names = [f"m{i}" for i in range(13)]
    (line,) = p.residual_warnings(residuals, names=names)
    assert "1 marker(s)" in line and "m4 (9.0 mm)" in line


def test_markers_held_at_the_shift_cap_are_named():
    shift = np.array([0.004, 0.0199999, 0.011, 0.02])
    (line,) = p.limit_warnings(shift, 0.02, names=["a", "b", "c", "d"])
    assert line.startswith("2 marker(s)") and "b (20.0 mm)" in line and "d (20.0 mm)" in line and "c" not in line
    assert p.limit_warnings(shift[[0, 2]], 0.02) == []


def test_an_average_subject_shape_gives_no_warning(capture):
    assert p.shape_warnings(capture.hand_motion.betas) == []


@pytest.mark.parametrize("value", [3.0, -3.0, 4.0])
def test_a_shape_value_at_its_bound_is_reported(value):
    betas = np.zeros(10)
    betas[2] = value
    (line,) = p.shape_warnings(betas)
    assert f"betas[2] = {value:.2f}" in line


def test_a_shape_fit_driven_to_its_bound_by_a_giant_hand_is_reported():
    from handcap.hand import OpenHand
    from handcap.solve import betas_from_measurements
    betas = betas_from_measurements(OpenHand(), hand_length=0.40)  # no adult hand is 40 cm long
    assert p.shape_warnings(betas) and p.shape_warnings(betas_from_measurements(OpenHand(), hand_length=0.19)) == []


# -- labels ---------------------------------------------------------------------------------------


def test_labeling_checks():
    points = np.full(100, 14)
    # 13 labels and a ghost in every frame: no label was missed.
    assert p.labeling_warnings(points, np.full(100, 13), n_labels=13) == []
    (line,) = p.labeling_warnings(points, np.full(100, 11), n_labels=13)
    assert "84.6 %" in line and ">= 95 %" in line
    (line,) = p.labeling_warnings(points, points, lost_frames=[7, 3, 9])
    assert "hand frame lost in 3 of 100 frames (first: 3)" in line


# -- jerk spikes --------------------------------------------------------------------------------------


@pytest.mark.parametrize("motion,rate", [("open-close", 60), ("tapping", 120), ("wrist", 100), ("pinch", 30)])
def test_true_motions_have_no_jerk_spikes(motion, rate):
    c = synthesize(SynthConfig(layout="tips-5", motion=motion, frames=150, rate=rate, seed=11, object="none",
                               cameras=4))
    assert p.jerk_warnings(c.hand_motion.joints, rate) == []


def test_an_injected_spike_is_found_at_its_frame(capture):
    joints = capture.hand_motion.joints.copy()
    joints[70, 18] += [0.0, 0.02, 0.0]  # the middle fingertip jumps 2 cm for one frame
    spikes = p.jerk_spikes(joints, 60)
    # A one-frame jump shows in the third differences starting at frames 67..70.
    assert set(spikes) <= {67, 68, 69, 70} and 67 in spikes and 70 in spikes
    (line,) = p.jerk_warnings(joints, 60)
    assert "jerk spikes in" in line and "first: frame 67" in line


def _moving_point(rate, frames=200, seed=0):
    """A point on a smooth path (about 0.4 m/s), 0.3 mm of noise: (frames, 1, 3) metres."""
    t = np.arange(frames) / rate
    path = np.stack([np.sin(2 * t) * 0.2, np.cos(2 * t) * 0.2, 0.1 * t], axis=-1)[:, None]
    return path + np.random.default_rng(seed).normal(0, 0.0003, (frames, 1, 3))


def _bouncing_point(rate, frames=200, seed=0):
    """A point falling at 1.5 m/s that bounces back at frame 100, keeping 80 % of its speed."""
    velocity, x, out = np.array([0.0, -1.5, 0.0]), np.array([0.0, 0.3, 0.0]), []
    for i in range(frames):
        out.append(x.copy())
        x = x + velocity / rate
        if i == 100:
            velocity = -0.8 * velocity
    return np.array(out)[:, None] + np.random.default_rng(seed).normal(0, 0.0003, (frames, 1, 3))


@pytest.mark.parametrize("kind", ["one frame", "four frames", "for good"])
def test_a_jump_is_told_from_a_change_of_course(kind):
    jumped = _moving_point(100)
    jumped[100:{"one frame": 101, "four frames": 104, "for good": None}[kind], 0] += [0.0, 0.02, 0.0]
    spikes = p.jerk_spikes(jumped, 100)
    assert len(spikes) and not any(turns for _, _, turns in p.spike_events(jumped, 100, spikes))
    (line,) = p.jerk_warnings(jumped, 100)
    assert line.endswith("look for label swaps or a lost fit there") and "impact" not in line
    bounced = _bouncing_point(100)
    spikes = p.jerk_spikes(bounced, 100)
    assert [turns for _, _, turns in p.spike_events(bounced, 100, spikes)] == [True]
    (line,) = p.jerk_warnings(bounced, 100)
    assert "each of the 1 changes course at once and keeps to it (an impact" in line and "swaps" not in line
    # Both in one take: counted apart, the first jump named.
    both = bounced.copy()
    both[150, 0] += [0.0, 0.0, 0.02]
    (line,) = p.jerk_warnings(both, 100)
    assert "1 of the 2 change course" in line and "; 1 jump (first: frame 147, 1.47 s)" in line
    # A point missing beside its spike cannot be told.
    both[104:106] = np.nan
    events = p.spike_events(both, 100, p.jerk_spikes(both, 100))
    assert [kind for *_, kind in events] == [None, False]
    assert "1 cannot be told, points missing around them (first: frame 99" in p.jerk_warnings(both, 100)[0]


def test_a_real_hand_hitting_a_rim_changes_course(shared_data):
    # kineticstoolkit's wheelchair racing: the right glove's 3-marker cluster at 70 Hz, the hand hitting the push
    # rim at up to 5.8 m/s once a push. Every event is a change of course, none a jump.
    take = read_markers(shared_data / "markers/kineticstoolkit/kinematics_racing_propulsion.c3d")
    glove = take.positions_of(["GloveR1", "GloveR2", "GloveR3"])
    spikes = p.jerk_spikes(glove, take.rate)
    events = p.spike_events(glove, take.rate, spikes)
    assert len(events) == 17 and all(kind for *_, kind in events)
    (line,) = p.jerk_warnings(glove, take.rate, what="marker")
    assert "each of the 17 changes course at once and keeps to it (an impact" in line and "swaps" not in line
    # The left hand's too, with its two rebounds off the rim (the velocity strays 1.04 and 1.08 times the change).
    left = take.positions_of(["GloveL1", "GloveL2", "GloveL3"])
    assert all(kind for *_, kind in p.spike_events(left, take.rate, p.jerk_spikes(left, take.rate)))


def test_noise_alone_is_not_a_spike():
    rng = np.random.default_rng(3)
    t = np.arange(300) / 100
    joints = np.stack([np.sin(t), np.cos(t), t], axis=-1)[:, None] * 0.1 + rng.normal(0, 0.001, (300, 21, 3))
    assert p.jerk_warnings(joints, 100) == []


# -- bones ----------------------------------------------------------------------------------------


def test_bone_lengths_match_the_anthropometric_table():
    lengths = p.bone_lengths(_rest_joints(frames=1)[0])
    for finger, tip in (("index", "index_tip"), ("middle", "middle_tip"), ("ring", "ring_tip")):
        bone = p.BONE_NAMES.index(f"{finger}3-{tip}")
        assert lengths[bone] == pytest.approx(SEGMENT_RATIOS[finger][3] * HAND_LENGTH, rel=1e-9)
    assert lengths[p.BONE_NAMES.index("thumb1-thumb2")] == pytest.approx(SEGMENT_RATIOS["thumb"][0] * HAND_LENGTH)


def test_a_synthetic_subject_has_plausible_bones(capture):
    assert p.bone_warnings(capture.hand_motion.joints) == []


@pytest.mark.parametrize("scale,word", [(1000, "1.825e+05 mm"), (0.001, "0.1825 mm"), (1.5, "273.8 mm")])
def test_a_hand_of_the_wrong_size_is_reported(scale, word):
    (line,) = p.bone_warnings(_rest_joints(scale))
    assert f"hand length {word}" in line and "135-230 mm" in line


def test_a_stretched_bone_is_named():
    joints = _rest_joints()
    joints[:, 17] = joints[:, 3] + 1.8 * (joints[:, 17] - joints[:, 3])
    (line,) = p.bone_warnings(joints)
    assert line.startswith("1 bone(s)") and "index3-index_tip" in line and "(1.80 x)" in line


def test_bones_that_change_length_are_reported():
    joints = _rest_joints(frames=40)
    joints[::2, 20] = joints[::2, 9] + 1.3 * (joints[::2, 20] - joints[::2, 9])
    (line,) = p.bone_warnings(joints)
    # Half the frames 1.3 x: the median length is 1.15 x, the 10-90 % range 0.3 x of the rest length.
    assert "change length" in line and f"pinky3-pinky_tip {100 * 0.3 / 1.15:.0f} %" in line


# -- markers: size and speed ------------------------------------------------------------------------------


def test_a_synthetic_capture_gives_no_marker_warning(capture):
    assert p.marker_warnings(capture.markers, hand=capture.hand_motion.marker_names) == []


@pytest.mark.parametrize("scale,hint", [(1000, "millimetres read as metres"), (0.001, "metres read as millimetres")])
def test_markers_in_the_wrong_units_are_reported_once(capture, scale, hint):
    m = capture.markers
    wrong = MarkerSequence(m.positions * scale, m.names, m.rate)
    lines = p.marker_warnings(wrong, hand=capture.hand_motion.marker_names)
    assert len(lines) == 2 and all(hint in line for line in lines)  # all markers and the hand's; no speed line
    assert "the hand's markers span" in lines[1]


def test_a_marker_jumping_half_a_metre_is_too_fast(capture):
    m = capture.markers
    positions = m.positions.copy()
    i = m.index("index_tip")
    seen = np.flatnonzero(~np.isnan(positions[:, i, 0]))
    frame = seen[(seen > 0) & np.isin(seen - 1, seen) & np.isin(seen + 1, seen)][10]
    positions[frame, i] += [0.5, 0, 0]
    (line,) = p.marker_warnings(MarkerSequence(positions, m.names, m.rate))
    assert line.startswith("2 samples") and "index_tip" in line and "> " not in line
    assert p.speeds(positions, m.rate)[frame - 1, i] > 0.5 * m.rate - 2


def test_the_typical_speed_names_the_rate():
    t = np.arange(100)[:, None, None] * np.array([0.5, 0, 0])  # 0.5 m a frame: 50 m/s at 100 Hz
    positions = t + np.array([[0.0, 0, 0], [0.05, 0, 0], [0, 0.05, 0]])
    (line,) = p.speed_warnings(positions, 100)
    assert "50 m/s typically" in line and "100 Hz" in line


# -- objects, triangulation, cameras ---------------------------------------------------------------------------------


def _object_take(canonical, frames=80, noise=0.0003, seed=0):
    from scipy.spatial.transform import Rotation
    rng = np.random.default_rng(seed)
    rot = Rotation.from_rotvec(np.linspace(0, 1, frames)[:, None] * [0.3, 1.0, -0.2]).as_matrix()
    translation = np.linspace([0, 0, 1], [0.2, 0.1, 1.1], frames)
    positions = np.einsum("tij,mj->tmi", rot, canonical) + translation[:, None]
    return MarkerSequence(positions + rng.normal(0, noise, positions.shape), [f"box:{i}" for i in range(4)], 100.0)


def test_a_rigid_object_gives_no_warning_and_a_deformed_one_is_reported():
    from handcap.objects import track_rigid
    canonical = np.array([[0.0, 0, 0], [0.08, 0, 0], [0, 0.06, 0], [0, 0, 0.05]])
    track = track_rigid(_object_take(canonical), canonical=canonical, threshold=0.005)
    assert p.object_warnings(track, threshold=0.005) == []
    track = track_rigid(_object_take(canonical * 1.06), canonical=canonical, threshold=0.005)
    (line,) = p.object_warnings(track, threshold=0.005)
    assert f"mean residual {1000 * track.mean_residual:.2f} mm" in line and "<= 2.5 mm" in line


def test_triangulation_with_moved_cameras_is_reported(capture, tmp_path):
    from handcap.core.cameras import Camera, CameraRig
    from handcap.io import save_npz
    from handcap.multiview import read_detections, triangulate_detections
    save_npz(tmp_path / "detections.npz", capture.detections)
    detections = read_detections(tmp_path / "detections.npz")
    good = triangulate_detections(detections, capture.rig, workers=1)
    assert p.triangulation_warnings(good.error_px, good.views, threshold_px=5.0, used=good.used) == []
    # Every other camera moved by 3 cm after the calibration: their views disagree with the others'.
    moved = CameraRig([Camera(c.name, c.size, c.matrix, c.distortions, c.rotation,
                              c.translation + [0.03 * (i % 2), 0, 0]) for i, c in enumerate(capture.rig)])
    bad = triangulate_detections(detections, moved, workers=1)
    (line,) = p.triangulation_warnings(bad.error_px, bad.views, threshold_px=5.0, used=bad.used)
    assert f"{100 * (1 - bad.used.mean()):.0f} % of the detections were rejected" in line


def test_markers_too_few_cameras_saw_are_told_apart_from_a_wrong_cameras_file(capture, tmp_path, capsys):
    from handcap.cli import main
    from handcap.io import save_npz, write_rig
    two = {k: v for k, v in capture.detections.items()}
    pairs = list(zip(np.asarray(two["frame"]).tolist(), np.asarray(two["marker"]).tolist()))
    keep = np.array([pairs[:k].count(pair) < 2 for k, pair in enumerate(pairs)])  # two views of each marker at most
    for key in ("frame", "camera", "marker", "xy", "score"):
        two[key] = np.asarray(two[key])[keep]
    two.pop("wrong_id", None)
    save_npz(tmp_path / "two.npz", two)
    write_rig(capture.rig, tmp_path / "cameras.toml")
    assert main(["triangulate", str(tmp_path / "two.npz"), "--cameras", str(tmp_path / "cameras.toml"), "--out",
                 str(tmp_path / "m.npz")]) == 0
    err = capsys.readouterr().err
    assert "none was seen by 3 cameras in one frame (--min-views 3); at most 2 saw one" in err
    assert "cameras file" not in err
    assert main(["triangulate", str(tmp_path / "two.npz"), "--cameras", str(tmp_path / "cameras.toml"), "--out",
                 str(tmp_path / "m2.npz"), "--min-views", "2"]) == 0
    assert "no marker was triangulated" not in capsys.readouterr().err
    # Where the views were there but disagree, the cameras file is blamed, as before.
    (line,) = p.triangulation_warnings(np.full((3, 4), np.nan), np.zeros((3, 4)), threshold_px=5.0,
                                       seen=np.full((3, 4), 4), min_views=3)
    assert "check that the cameras file matches the detections" in line


def test_camera_checks():
    assert p.camera_warnings([0.3, 0.6], names=["a", "b"]) == []
    (line,) = p.camera_warnings([0.3, 2.5, np.nan], names=["a", "b", "c"])
    assert "b (2.5 px)" in line and "c (inf px)" in line and "a (" not in line


# -- attach and summary -----------------------------------------------------------------------------------


def test_attached_warnings_are_issued_and_survive_a_file(tmp_path, capture):
    lines = p.marker_warnings(MarkerSequence(capture.markers.positions * 1000, capture.markers.names, 60.0))
    with pytest.warns(HandcapWarning, match="millimetres read as metres"):
        markers = p.attach(capture.markers, lines)
    assert markers.warnings == tuple(lines)
    write_markers(markers, tmp_path / "m.npz")
    assert read_markers(tmp_path / "m.npz").warnings == tuple(lines)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert p.attach(capture.markers, []) is capture.markers


def test_summary_is_compact():
    text = p.summary("out.npz: 10 frames", {"MRE (mm)": 1.23456, "frames": 10, "skipped": None}, ["a", "b", "a"])
    lines = text.splitlines()
    assert lines[0] == "out.npz: 10 frames" and len(lines) == 4
    assert lines[1].split() == ["MRE", "(mm)", "1.235"] and "2 warning(s)" in lines[3]
    assert "no warnings" in p.summary("x", [("a", 1.0)])


def test_motion_warnings_collect_every_check(capture):
    motion = capture.hand_motion
    assert p.motion_warnings(motion) == []
    bad = HandMotion(np.r_[3.0, np.zeros(9)], motion.global_orient, motion.hand_pose, motion.transl, motion.rate,
                     joints=motion.joints * 1000, marker_names=("a", "b"),
                     marker_residuals=np.full((motion.n_frames, 2), 0.02))
    lines = p.motion_warnings(bad)
    assert [w.split()[0] for w in lines] == ["solve", "shape", "hand"]


def test_reprojection_errors_crowding_the_threshold_are_reported():
    error = np.full((20, 5), 3.2)
    error[:, 0] = np.nan
    (line,) = p.triangulation_warnings(error, np.where(np.isnan(error), 0, 3), threshold_px=5.0)
    assert "mean reprojection error 3.20 px" in line and "<= 2.5 px" in line
    assert p.triangulation_warnings(error / 4, np.full((20, 5), 3), threshold_px=5.0) == []


def test_cleaning_that_removes_a_fifth_of_the_take_is_reported(capture):
    from handcap.multiview.clean import clean_markers
    m = capture.markers.select(list(capture.hand_motion.marker_names))
    assert p.clean_warnings(clean_markers(m, "glove-13")[1], m.missing) == []
    rng = np.random.default_rng(4)
    positions = m.positions.copy()
    bad = rng.random(positions.shape[:2]) < 0.2
    positions[bad] += rng.normal(0, 0.1, (int(bad.sum()), 3))  # a fifth of the samples thrown ~17 cm off
    corrupted = MarkerSequence(positions, m.names, m.rate)
    cleaned, report = clean_markers(corrupted, "glove-13")
    (line,) = p.clean_warnings(report, corrupted.missing)
    removed = (report.cluster_removed.sum() + report.outlier_removed.sum()) / (~corrupted.missing).sum()
    assert f"cleaning removed {100 * removed:.1f} %" in line and removed > 0.1


def test_the_real_glove_recording_is_plausible_and_not_in_millimetres(shared_data):
    markers = read_markers(shared_data / "markers" / "hand_embodiment_glove" / "recording.tsv")
    assert p.marker_warnings(markers) == []
    figures = p.marker_figures(markers)
    assert 0.1 < figures["extent (m)"] < 3 and figures["speed p99 (m/s)"] < 2
    wrong = MarkerSequence(markers.positions * 1000, markers.names, markers.rate)
    (line,) = p.marker_warnings(wrong)
    assert "millimetres read as metres" in line


def test_the_patches_square_side_against_their_printed_pitch():
    rng = np.random.default_rng(0)
    r, c = np.meshgrid(np.arange(4), np.arange(5), indexing="ij")
    grid = np.stack([c.ravel(), r.ravel(), np.zeros(r.size)], axis=1) * 0.005  # one flat patch, 5 mm squares
    names = tuple(f"right:palm_r{i}c{j}" for i, j in zip(r.ravel(), c.ravel())) + ("wrist",)
    positions = np.concatenate([grid[None] + rng.normal(0, 0.0002, (30, len(grid), 3)), np.zeros((30, 1, 3))], axis=1)
    markers = MarkerSequence(positions, names, 100.0)
    figures, warned = p.pitch_check(markers, 0.005)
    assert abs(figures["patch square (mm)"] - 5.0) < 0.05 and figures["of the printed pitch (%)"] == pytest.approx(
        100, abs=1) and warned == []
    figures, warned = p.pitch_check(markers, 0.006)  # a board's square size given 20 % too large
    assert figures["of the printed pitch (%)"] == pytest.approx(83.3, abs=1) and len(warned) == 1
    assert "83." in warned[0] and "scale" in warned[0]
    assert p.pitch_check(markers, None) == ({}, [])
    plain = MarkerSequence(positions, tuple(f"m{k}" for k in range(len(names))), 100.0)  # no patch corners
    assert p.pitch_check(plain, 0.005) == ({}, [])
    assert p.pitch_check(MarkerSequence(positions[:1, :3], names[:3], 100.0), 0.005) == ({}, [])  # 2 distances
