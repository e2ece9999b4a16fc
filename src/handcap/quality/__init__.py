"""Smoothing and quality metrics of captured motion."""

from handcap.quality.filters import lowpass, smooth_hand_motion, smooth_object_motion, smooth_rotations
from handcap.quality.metrics import (
    Stat,
    diversity_coherence,
    jerk,
    joint_position_error,
    marker_reconstruction_error,
    msnr,
    penetration,
    pose_features,
)

__all__ = ["Stat", "diversity_coherence", "jerk", "joint_position_error", "lowpass",
           "marker_reconstruction_error", "msnr", "penetration", "pose_features", "smooth_hand_motion",
           "smooth_object_motion", "smooth_rotations"]
