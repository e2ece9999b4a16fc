"""Data model: marker, point-cloud and motion containers, errors, checks of inputs, rotations."""

from handcap.core.checks import check_positions
from handcap.core.errors import HandcapError, HandcapWarning, warn
from handcap.core.markers import MarkerGaps, MarkerSequence, marker_gaps
from handcap.core.motion import HandMotion, ObjectMotion
from handcap.core.points import PointCloudSequence

__all__ = [
    "HandcapError",
    "HandcapWarning",
    "HandMotion",
    "MarkerGaps",
    "MarkerSequence",
    "ObjectMotion",
    "PointCloudSequence",
    "check_positions",
    "marker_gaps",
    "warn",
]

from handcap.core.cameras import Camera, CameraRig  # noqa: E402

__all__ += ["Camera", "CameraRig"]
