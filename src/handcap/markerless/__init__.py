"""Markerless hand capture (issue 17, the markerless-grasp paper): 2D hand keypoints to hand motion.

    detections = import_keypoints(["left.npy", "right.npy"], "mediapipe-npy", rate=30)
    repaired = repair_handedness(detections, rig).detections       # left/right as the views agree
    hand3d = triangulate_detections(repaired, rig).to_markers()     # (T, 21, 3) per hand, metres
    motion = fit_keypoints(hand3d, label="right")                   # HandMotion: pose, shape, joints

Keypoint names and their model joints: :mod:`handcap.markerless.keypoints`.
"""

from handcap.markerless.fit import betas_from_keypoints, fit_keypoints, hand_labels, palm_similarity
from handcap.markerless.handedness import HandednessRepair, repair_handedness
from handcap.markerless.importers import FORMATS, import_keypoints, merge_keypoints
from handcap.markerless.keypoints import KEYPOINT_NAMES, hand_names, joints_from_keypoints, keypoints_from_joints

__all__ = ["FORMATS", "HandednessRepair", "KEYPOINT_NAMES", "betas_from_keypoints", "fit_keypoints", "hand_labels",
           "hand_names", "import_keypoints", "joints_from_keypoints", "keypoints_from_joints", "merge_keypoints",
           "palm_similarity", "repair_handedness"]
