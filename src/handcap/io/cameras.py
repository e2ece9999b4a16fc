"""Camera rig files in anipose's TOML layout.

One table per camera, keyed ``[cam_0]``, ``[cam_1]``, ... in rig order, as
aniposelib's ``CameraGroup.dump`` writes them::

    [cam_0]
    name = "A"
    size = [2448, 2048]                      # width, height in pixels
    matrix = [[fx, 0, cx], [0, fy, cy], [0, 0, 1]]
    distortions = [k1, k2, p1, p2, k3]       # OpenCV's order
    rotation = [rx, ry, rz]                  # Rodrigues, world to camera
    translation = [tx, ty, tz]               # metres, world to camera

Reading follows the file's order of tables (whatever their keys), skips
anipose's optional ``[metadata]`` table and ignores keys it does not know,
except ``fisheye = true``: anipose's fisheye model is a different lens model
and is refused. Distortions of 4 values are read with k3 = 0, and OpenCV's
8-value rational model only when its k4 = k5 = k6 = 0 (see
:class:`handcap.core.cameras.Camera`). Translations must be in metres: anipose
uses the unit of the calibration board, which may be millimetres.

Writing emits exactly the six keys above per camera, with floats in their
shortest round-trip form, so reading gives back the same numbers bit for bit
and identical rigs give identical bytes. The warnings of the calibration that
made the rig (``CameraRig.warnings``, one-line strings, File contract) go to
``[metadata]`` as ``warnings = [...]``, where anipose keeps its own notes, and
come back on the rig read (or alone with :func:`read_cameras_warnings`).

The code lives in :mod:`handcap.core.cameras` beside the rig it reads and
writes (``CameraRig.save`` and ``CameraRig.load`` use it, and the core depends
on nothing above it); this module names it for users, with the other formats.
"""

from handcap.core.cameras import CAMERA_KEYS, read_cameras_toml, read_cameras_warnings, write_cameras_toml

__all__ = ["CAMERA_KEYS", "read_cameras_toml", "read_cameras_warnings", "write_cameras_toml"]
