"""Calibrated cameras, one import away: ``Camera`` (one pinhole camera), ``CameraRig`` (an ordered set) and the
anipose-style TOML rig files.

The code lives in three modules, each owning one idea; this one only gathers their names:

* :mod:`handcap.core.camera`: ``Camera``, its frames and lens model, and the conventions (world in metres, OpenCV's
  camera frame, pixels and five-term distortion) written down once;
* :mod:`handcap.core.camera_rig`: ``CameraRig`` and :func:`read_cameras_toml`, :func:`write_cameras_toml`
  (``CameraRig.save`` and ``CameraRig.load``);
* :mod:`handcap.core.camera_toml`: the file format's tables and ``[metadata]`` warnings (``CAMERA_KEYS``,
  :func:`read_cameras_warnings`, :func:`check_rig_suffix`), described for users in :mod:`handcap.io.cameras`.
"""

from handcap.core.camera import Camera
from handcap.core.camera_rig import CameraRig, read_cameras_toml, write_cameras_toml
from handcap.core.camera_toml import CAMERA_KEYS, check_rig_suffix, read_cameras_warnings

__all__ = ["CAMERA_KEYS", "Camera", "CameraRig", "check_rig_suffix", "read_cameras_toml", "read_cameras_warnings",
           "write_cameras_toml"]
