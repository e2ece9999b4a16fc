"""Handedness repair: candidate hands of each view given to the hand the other views agree on (issue 17)."""

import numpy as np
import pytest

from handcap.markerless import hand_names, repair_handedness
from handcap.markerless.keypoints import split_hand_name
from handcap.markerless.synthetic import synthetic_hand, view_keypoints
from handcap.multiview import triangulate_detections
from handcap.synth.cameras import cage_rig


def _right_share(detections, truth, repair):
    """Share of true (camera, frame, hand) candidates whose keypoints all went to the hand of their true label."""
    out = {}
    key = {(int(f), int(c), tuple(xy)): split_hand_name(repair.detections.marker_names[m])[0]
           for f, c, m, xy in zip(repair.detections.frame, repair.detections.camera, repair.detections.marker,
                                  repair.detections.xy)}
    for f, c, xy, hand in zip(detections.frame, detections.camera, detections.xy, truth):
        out.setdefault((int(f), int(c), hand), []).append(key.get((int(f), int(c), tuple(xy))) == hand)
    return np.mean([all(v) for v in out.values()])


@pytest.fixture(scope="module")
def rig():
    return cage_rig(6, seed=1, resolution=(1920, 1080))


def test_two_hands_with_a_fifth_of_views_swapped(rig):
    rng = np.random.default_rng(1)
    hands = {"right": synthetic_hand(80, 30.0, rng, side="right").keypoints,
             "left": synthetic_hand(80, 30.0, rng, side="left", offset=(0, 0.3, 0)).keypoints}
    detections, truth = view_keypoints(rig, hands, noise_px=1.0, missing=0.1, wrong=0.02, swap=0.2, rng=rng)
    repair = repair_handedness(detections, rig)
    assert sorted(repair.hands) == ["left", "right"]
    assert _right_share(detections, truth, repair) >= 0.99
    assert 0.1 < repair.relabelled / repair.candidates < 0.3
    result = triangulate_detections(repair.detections, rig, min_views=2, threshold_px=12.0, workers=1)
    for label, points in hands.items():
        idx = [result.names.index(n) for n in hand_names(label)]
        err = np.linalg.norm(result.positions[:, idx] - points, axis=-1)
        assert np.nanmedian(err) < 2e-3 and np.isfinite(err).mean() > 0.98


def test_without_repair_the_labels_mix_the_hands(rig):
    """The check above can fail: triangulating by the detector's labels puts keypoints of the other hand in."""
    rng = np.random.default_rng(1)
    hands = {"right": synthetic_hand(80, 30.0, rng, side="right").keypoints,
             "left": synthetic_hand(80, 30.0, rng, side="left", offset=(0, 0.3, 0)).keypoints}
    detections, _ = view_keypoints(rig, hands, noise_px=1.0, missing=0.1, wrong=0.02, swap=0.3, rng=rng)
    result = triangulate_detections(detections, rig, min_views=2, threshold_px=12.0, workers=1)
    idx = [result.names.index(n) for n in hand_names("right")]
    err = np.linalg.norm(result.positions[:, idx] - hands["right"], axis=-1)
    assert np.nanmax(err) > 0.05  # somewhere a keypoint of the left hand


def test_one_hand_labelled_both_ways_is_one_hand(rig):
    rng = np.random.default_rng(2)
    hands = {"right": synthetic_hand(60, 30.0, rng, side="right").keypoints}
    detections, truth = view_keypoints(rig, hands, noise_px=1.0, missing=0.05, swap=0.25, rng=rng)
    assert {split_hand_name(n)[0] for n in detections.marker_names} == {"left", "right"}
    repair = repair_handedness(detections, rig)
    assert repair.hands == ("right",)
    assert _right_share(detections, truth, repair) >= 0.99
