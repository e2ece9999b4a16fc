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
    """``Camera(**fields)``, its refusal prefixed with ``where`` (the file and its entry).

    Parameters
    ----------
    where : str
        Place in the file, for messages (``"rig.toml: [cameras.0]"``).
    **fields
        The :class:`~handcap.core.cameras.Camera` fields: ``size`` pixels, ``matrix`` pixels,
        ``rotation`` Rodrigues vector (radians), ``translation`` metres, world to camera.

    Returns
    -------
    Camera
    """
    try:
        return Camera(**fields)
    except HandcapError as err:
        raise HandcapError(f"{where} {err}") from None


def rig_from_cameras(path, cameras: list[Camera], what: str) -> CameraRig:
    """A :class:`~handcap.core.cameras.CameraRig` of ``cameras``, its refusal prefixed with ``path``.

    Parameters
    ----------
    path : str or Path
        For messages.
    cameras : list of Camera
    what : str
        What the file should have held (``"[cameras.N] tables"``), for the message when ``cameras`` is empty.

    Returns
    -------
    CameraRig

    Raises
    ------
    HandcapError
        No cameras, or the rig refuses them (repeated names, for one).
    """
    if not cameras:
        raise HandcapError(f"{path}: no cameras; expected {what}")
    try:
        return CameraRig(cameras)
    except HandcapError as err:
        raise HandcapError(f"{path}: {err}") from None


def rotation_vector(matrix, where: str) -> np.ndarray:
    """Rodrigues vector of a 3x3 rotation matrix, checked to be one.

    Parameters
    ----------
    matrix : array_like of shape (3, 3)
        A rotation: finite, ``|R R^T - I| <=`` :data:`ROTATION_TOLERANCE`, determinant positive.
    where : str
        Place in the file, for messages.

    Returns
    -------
    ndarray of shape (3,)
        Axis-angle vector, radians.

    Raises
    ------
    HandcapError
        Not numbers, not 3x3, not finite, or not a rotation.
    """
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
    """Refuse anything but a :class:`~handcap.core.cameras.CameraRig` given to a writer.

    Parameters
    ----------
    rig : object
        What the writer was given.
    verb : str
        The writer's name, for the message.

    Raises
    ------
    HandcapError
        ``rig`` is not a CameraRig.
    """
    if not isinstance(rig, CameraRig):
        raise HandcapError(f"{verb} needs a CameraRig, got {type(rig).__name__}")
