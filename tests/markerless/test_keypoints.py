"""Keypoint names and their model joints (issue 17)."""

import numpy as np
import pytest

from handcap import HandcapError
from handcap.hand import OpenHand
from handcap.hand.anatomy import JOINT_NAMES, TIP_NAMES
from handcap.markerless.keypoints import (KEYPOINT_NAMES, MODEL_JOINT, hand_names, is_keypoints,
                                          joints_from_keypoints, keypoints_from_joints, split_hand_name)

# The model joint each detector keypoint stands for, written out by name (MANO: thumb1 is the CMC joint).
EXPECTED = {"wrist": "wrist", "thumb_cmc": "thumb1", "thumb_mcp": "thumb2", "thumb_ip": "thumb3",
            "thumb_tip": "thumb_tip"}
for finger in ("index", "middle", "ring", "pinky"):
    EXPECTED.update({f"{finger}_mcp": f"{finger}1", f"{finger}_pip": f"{finger}2", f"{finger}_dip": f"{finger}3",
                     f"{finger}_tip": f"{finger}_tip"})


def test_order_is_the_detectors_and_maps_to_the_named_joints():
    assert len(KEYPOINT_NAMES) == 21 and KEYPOINT_NAMES[0] == "wrist" and KEYPOINT_NAMES[4] == "thumb_tip"
    assert KEYPOINT_NAMES[5:9] == ("index_mcp", "index_pip", "index_dip", "index_tip")
    assert KEYPOINT_NAMES[-1] == "pinky_tip"
    model_names = JOINT_NAMES + TIP_NAMES
    assert [model_names[j] for j in MODEL_JOINT] == [EXPECTED[k] for k in KEYPOINT_NAMES]


def test_round_trip_and_geometry():
    joints = OpenHand().rest_joints()
    kp = keypoints_from_joints(joints)
    np.testing.assert_array_equal(joints_from_keypoints(kp), joints)
    # base to tip, each finger's points get further from the wrist
    for f in range(5):
        d = np.linalg.norm(kp[1 + 4 * f:5 + 4 * f] - kp[0], axis=1)
        assert np.all(np.diff(d) > 0)
    with pytest.raises(HandcapError):
        keypoints_from_joints(np.zeros((20, 3)))


def test_names_and_prefixes():
    assert split_hand_name("left:index_tip") == ("left", "index_tip")
    assert split_hand_name("wrist") == ("", "wrist")
    assert hand_names("right")[0] == "right:wrist" and hand_names() == KEYPOINT_NAMES
    assert is_keypoints(hand_names("a") + hand_names("b")) and not is_keypoints(["wrist", "hand_top"])
    assert not is_keypoints([])
    with pytest.raises(HandcapError, match="no hand keypoint"):
        split_hand_name("left:knuckle")
