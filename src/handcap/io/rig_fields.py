"""What the camera rig readers of other tools share: cameras and rigs built with the file's place in the
message, and rotation matrices checked to be rotations."""

from __future__ import annotations

import numpy as np

from handcap.core.cameras import Camera, CameraRig
from handcap.core.errors import HandcapError
from handcap.core.rotations import axis_angle_from_matrix


#: Largest |R R^T - I| accepted as a rotation.
ROTATION_TOLERANCE = 1e-6


def camera_from_fields(where: str, **fields) -> Camera:
    try:
        return Camera(**fields)
    except HandcapError as err:
        raise HandcapError(f"{where} {err}") from None


def rig_from_cameras(path, cameras: list[Camera], what: str) -> CameraRig:
    if not cameras:
        raise HandcapError(f"{path}: no cameras; expected {what}")
    try:
        return CameraRig(cameras)
    except HandcapError as err:
        raise HandcapError(f"{path}: {err}") from None


def rotation_vector(matrix, where: str) -> np.ndarray:
    """Rodrigues vector of a 3x3 rotation matrix, checked to be one."""
    try:
        matrix = np.asarray(matrix, dtype=np.float64)
    except (TypeError, ValueError):  # ragged rows
        raise HandcapError(f"{where} must be a 3x3 rotation matrix of numbers") from None
    if matrix.shape != (3, 3):
        raise HandcapError(f"{where} must be a 3x3 rotation matrix, got shape {matrix.shape}")
    if not np.isfinite(matrix).all():
        raise HandcapError(f"{where} must be finite, got {matrix.ravel().tolist()}")
    with np.errstate(over="ignore", invalid="ignore"):  # huge entries: refused just below, no warning
        error = np.abs(matrix @ matrix.T - np.eye(3)).max()
    if not error <= ROTATION_TOLERANCE or np.linalg.det(matrix) <= 0:
        raise HandcapError(f"{where} is not a rotation matrix (|R R^T - I| = {error:.2g}, "
                           f"det = {np.linalg.det(matrix):.6g})")
    return axis_angle_from_matrix(matrix)


def check_rig_to_write(rig, verb: str) -> None:
    if not isinstance(rig, CameraRig):
        raise HandcapError(f"{verb} needs a CameraRig, got {type(rig).__name__}")
