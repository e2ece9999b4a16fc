"""Data model: marker, point-cloud and motion containers, errors, rotations."""

from handcap.core.errors import HandcapError, HandcapWarning, warn
from handcap.core.markers import MarkerGaps, MarkerSequence, as_positions, marker_gaps
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
    "as_positions",
    "marker_gaps",
    "warn",
]

from handcap.core.cameras import Camera, CameraRig  # noqa: E402

__all__ += ["Camera", "CameraRig"]
