"""handcap keypoints import, triangulate (with handedness repair) and fit-keypoints from the command line."""

import hashlib

import numpy as np
import pytest

from handcap.cli import main
from handcap.io import read_markers
from handcap.markerless import KEYPOINT_NAMES, hand_names, keypoints_from_joints
from handcap.markerless.keypoints import split_hand_name
from handcap.markerless.synthetic import synthetic_hand, view_keypoints
from handcap.synth.cameras import cage_rig


@pytest.fixture(scope="module")
def take(tmp_path_factory):
    """MediaPipe-style files (a file per label, cameras first) of two hands seen by 5 cameras, 20 % swapped."""
    folder = tmp_path_factory.mktemp("kp")
    rng = np.random.default_rng(7)
    rig = cage_rig(5, seed=3, resolution=(1920, 1080))
    rig.save(folder / "rig.toml")
    hands = {"right": synthetic_hand(40, 30.0, rng, side="right"),
             "left": synthetic_hand(40, 30.0, rng, side="left", offset=(0, 0.3, 0))}
    det, _ = view_keypoints(rig, {k: h.keypoints for k, h in hands.items()}, noise_px=1.0, missing=0.05,
                            swap=0.2, rng=rng)
    for label in hands:
        array = np.full((len(rig), det.n_frames, 21, 2), -1.0)
        for f, c, m, xy in zip(det.frame, det.camera, det.marker, det.xy):
            given, point = split_hand_name(det.marker_names[m])
            if given == label:
                array[c, f, KEYPOINT_NAMES.index(point)] = xy
        np.save(folder / f"{label}.npy", array)
    return folder, rig, hands


def _hash(path):
    return hashlib.sha256(path.read_bytes()).hexdigest()


def test_import_triangulate_fit(take, capsys):
    folder, rig, hands = take
    cams = ",".join(rig.names)
    assert main(["keypoints", "import", str(folder / "left.npy"), str(folder / "right.npy"), "--format",
                 "mediapipe-npy", "--rate", "30", "--cameras", cams, "--out", str(folder / "kp.npz")]) == 0
    assert main(["triangulate", str(folder / "kp.npz"), "--cameras", str(folder / "rig.toml"), "--out",
                 str(folder / "hand3d.npz")]) == 0
    out = capsys.readouterr().out
    assert "handedness:" in out and "relabelled" in out
    markers = read_markers(folder / "hand3d.npz")
    for label, hand in hands.items():
        idx = [markers.names.index(n) for n in hand_names(label)]
        err = np.linalg.norm(markers.positions[:, idx] - hand.keypoints, axis=-1)
        assert np.nanmedian(err) < 2e-3
    before = _hash(folder / "hand3d.npz")
    assert main(["fit-keypoints", str(folder / "hand3d.npz"), "--hand", "left", "--out",
                 str(folder / "left_motion.npz")]) == 0
    motion = np.load(folder / "left_motion.npz")
    assert str(motion["side"]) == "left"
    err = np.linalg.norm(keypoints_from_joints(motion["joints"]) - hands["left"].keypoints, axis=-1)
    assert err.mean() < 3e-3
    assert _hash(folder / "hand3d.npz") == before


def test_bad_input_exits_2(take, capsys):
    folder, rig, _ = take
    before = _hash(folder / "left.npy")
    # its own triangulated file: under pytest-xdist the test above may run in another process
    assert main(["keypoints", "import", str(folder / "left.npy"), str(folder / "right.npy"), "--format",
                 "mediapipe-npy", "--rate", "30", "--cameras", ",".join(rig.names), "--out",
                 str(folder / "kp_two.npz")]) == 0
    assert main(["triangulate", str(folder / "kp_two.npz"), "--cameras", str(folder / "rig.toml"), "--out",
                 str(folder / "two_hands.npz")]) == 0
    capsys.readouterr()
    assert main(["fit-keypoints", str(folder / "two_hands.npz"), "--out", str(folder / "x.npz")]) == 2
    assert "several hands" in capsys.readouterr().err
    assert main(["keypoints", "import", str(folder / "left.npy"), "--format", "mediapipe-npy", "--rate", "30",
                 "--cameras", "a,b", "--out", str(folder / "y.npz")]) == 2
    assert main(["keypoints", "import", str(folder / "left.npy"), "--format", "mediapipe-npy", "--rate", "30",
                 "--out", str(folder / "left.npy")]) == 2
    assert _hash(folder / "left.npy") == before
    err = capsys.readouterr().err
    assert err.count("error:") == 2 and "Traceback" not in err
