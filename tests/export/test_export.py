"""Exports read back by independent readers: BVH by bvhio (its own hierarchy and Euler composition), C3D by
ezc3d, CSV by the csv module; against handcap's forward kinematics and the motion's own angles."""

import csv

import ezc3d
import numpy as np
import pytest

from handcap.cli import main
from handcap.core.motion import HandMotion
from handcap.export import bvh_text, export_motion, write_bvh
from handcap.hand import OpenHand
from handcap.hand.anatomy import JOINT_NAMES, PHI_NAMES, TIP_NAMES
from handcap.io import write_hand_motion
from handcap.synth.scene import SynthConfig, synthesize

bvhio = pytest.importorskip("bvhio", reason="bvhio (the test extra) reads the BVH files back")


@pytest.fixture(scope="module")
def motion():
    capture = synthesize(SynthConfig(motion="random", frames=80, rate=60.0, seed=3, cameras=4), progress=False)
    return capture.hand_motion


def _bvh_positions(path, frames):
    root = bvhio.readAsHierarchy(str(path))
    out = []
    for f in frames:
        root.loadPose(f)
        where = {j.Name: np.array(j.PositionWorld) for j, _, _ in root.layout()}
        out.append([where[n] for n in JOINT_NAMES])
    return np.array(out)


def test_bvh_read_by_bvhio_gives_the_models_joints(motion, tmp_path):
    hand = OpenHand(motion.side)
    assert write_bvh(motion, hand, tmp_path / "hand.bvh") == []
    frames = range(0, motion.n_frames, 7)
    got = _bvh_positions(tmp_path / "hand.bvh", frames) / 100  # centimetres
    assert np.abs(got - motion.joints[list(frames), :16]).max() < 1e-4  # 0.1 mm
    text = (tmp_path / "hand.bvh").read_text()
    assert f"Frames: {motion.n_frames}" in text and f"Frame Time: {1 / 60:.8f}" in text
    assert text.count("End Site") == 5 and text.count("JOINT") == 15
    mm = bvh_text(motion, hand, units="mm")[0]
    (tmp_path / "mm.bvh").write_text(mm)
    assert np.allclose(_bvh_positions(tmp_path / "mm.bvh", [5]) / 1000, motion.joints[[5], :16], atol=1e-6)


def test_bvh_fills_frames_without_a_pose_and_says_so(motion, tmp_path):
    hand = OpenHand(motion.side)
    lost = HandMotion(motion.betas, motion.global_orient.copy(), motion.hand_pose, motion.transl.copy(), motion.rate,
                      motion.side)
    lost.global_orient[10:13] = np.nan
    lost.transl[10:13] = np.nan
    warnings = write_bvh(lost, hand, tmp_path / "lost.bvh")
    assert warnings and "3 of 80 frames have no pose" in warnings[0]
    got = _bvh_positions(tmp_path / "lost.bvh", [9, 10, 12, 13]) / 100
    assert np.abs(got[1] - motion.joints[9, :16]).max() < 1e-4 and np.abs(got[2] - motion.joints[13, :16]).max() < 1e-4


def test_csv_c3d_and_mano(motion, tmp_path):
    hand = OpenHand(motion.side)
    export_motion(motion, hand, tmp_path / "angles.csv")
    with open(tmp_path / "angles.csv", newline="") as fh:
        rows = list(csv.reader(fh))
    assert rows[0][:3] == ["frame", "time_s", f"{PHI_NAMES[0]}_deg"] and len(rows) == motion.n_frames + 1
    table = np.array(rows[1:], dtype=float)
    assert np.allclose(table[:, 1], np.arange(motion.n_frames) / 60.0, atol=1e-6)
    assert np.allclose(table[:, 2:], np.rad2deg(motion.phi), atol=1e-3)
    export_motion(motion, hand, tmp_path / "joints.c3d")
    c3d = ezc3d.c3d(str(tmp_path / "joints.c3d"))
    labels = c3d["parameters"]["POINT"]["LABELS"]["value"]
    assert labels[:21] == list(JOINT_NAMES + TIP_NAMES) and labels[21] == f"fit:{motion.marker_names[0]}"
    unit = c3d["parameters"]["POINT"]["UNITS"]["value"][0]
    points = c3d["data"]["points"][:3, :21].transpose(2, 1, 0) * {"mm": 0.001, "m": 1.0}[unit]
    assert np.abs(points - motion.joints).max() < 1e-5
    warnings = export_motion(motion, hand, tmp_path / "mano.npz")
    assert "not MANO's shape values" in warnings[0]
    with np.load(tmp_path / "mano.npz") as data:
        assert np.array_equal(data["hand_pose"], motion.hand_pose) and data["betas"].shape == (10,)
        assert str(data["side"]) == motion.side


def test_export_verb_and_its_bad_inputs(motion, tmp_path, capsys):
    write_hand_motion(motion, tmp_path / "motion.npz")
    before = (tmp_path / "motion.npz").read_bytes()
    assert main(["export", str(tmp_path / "motion.npz"), "--to", str(tmp_path / "hand.bvh"), "--units", "mm"]) == 0
    assert "80 frames at 60 Hz, BVH" in capsys.readouterr().out
    for to, message in (("hand.usdz", "the suffix chooses the format"), ("motion.npz", "overwrite the input")):
        assert main(["export", str(tmp_path / "motion.npz"), "--to", str(tmp_path / to)]) == 2
        err = capsys.readouterr().err
        assert message in err and len(err.strip().splitlines()) == 1, err
    (tmp_path / "broken.npz").write_bytes(b"not a zip")
    assert main(["export", str(tmp_path / "broken.npz"), "--to", str(tmp_path / "x.bvh")]) == 2
    assert (tmp_path / "motion.npz").read_bytes() == before and not (tmp_path / "x.bvh").exists()
