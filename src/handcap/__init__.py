"""handcap: optical motion capture of hands and the objects they manipulate.

Units inside handcap are metres, seconds and radians; marker arrays have shape
``(T, M, 3)`` with NaN where a marker is missing.
"""

from handcap.core import (
    HandcapError,
    HandcapWarning,
    HandMotion,
    MarkerSequence,
    ObjectMotion,
    PointCloudSequence,
)

__version__ = "0.1.0"

__all__ = [
    "HandcapError",
    "HandcapWarning",
    "HandMotion",
    "MarkerSequence",
    "ObjectMotion",
    "PointCloudSequence",
    "__version__",
]
