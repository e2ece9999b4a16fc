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
"""

from __future__ import annotations

import tomllib

import tomli_w

from handcap.core.cameras import Camera, CameraRig
from handcap.core.errors import HandcapError, merge_warnings
from handcap.io._files import atomic_output, existing_file

CAMERA_KEYS = ("name", "size", "matrix", "distortions", "rotation", "translation")
_METADATA = "metadata"


def read_cameras_toml(path) -> CameraRig:
    """Read a camera rig from an anipose-style TOML file.

    Parameters
    ----------
    path : str or Path

    Returns
    -------
    CameraRig
        Cameras in the order of the file's tables; translations in metres.

    Raises
    ------
    HandcapError
        Missing or unreadable file, invalid TOML, no camera table, a missing
        key, a value of the wrong shape or type, a non-finite number, a fisheye
        camera, or repeated camera names. The message names the file and table.
    """
    path = existing_file(path)
    try:
        with open(path, "rb") as fh:
            document = tomllib.load(fh)
    except tomllib.TOMLDecodeError as err:
        raise HandcapError(f"{path}: not valid TOML ({err})") from None
    except UnicodeDecodeError:
        raise HandcapError(f"{path}: not valid TOML (not UTF-8 text)") from None
    cameras = []
    for key, table in document.items():
        if key == _METADATA:
            continue
        if not isinstance(table, dict):
            raise HandcapError(f"{path}: top-level key '{key}' is not a camera table; "
                               f"expected tables [cam_0], [cam_1], ... (and optionally [metadata])")
        cameras.append(_camera_from_table(table, f"{path}: [{key}]"))
    if not cameras:
        raise HandcapError(f"{path}: no camera tables; expected [cam_0], [cam_1], ... "
                           f"with keys {', '.join(CAMERA_KEYS)}")
    try:
        return CameraRig(cameras, _stored_warnings(document.get(_METADATA)))
    except HandcapError as err:
        raise HandcapError(f"{path}: {err}") from None


def _stored_warnings(metadata) -> tuple[str, ...]:
    """The ``warnings`` list of a ``[metadata]`` table (anything else there is anipose's and ignored)."""
    found = metadata.get("warnings", []) if isinstance(metadata, dict) else []
    return tuple(str(w) for w in found) if isinstance(found, list) else ()


def _camera_from_table(table: dict, where: str) -> Camera:
    missing = [key for key in CAMERA_KEYS if key not in table]
    if missing:
        raise HandcapError(f"{where} lacks {', '.join(missing)}; each camera table needs "
                           f"{', '.join(CAMERA_KEYS)}")
    if table.get("fisheye", False):
        raise HandcapError(f"{where} is a fisheye camera; handcap supports OpenCV's pinhole model only")
    for key in CAMERA_KEYS[1:]:
        # tomllib gives str, bool, dates and tables as they are; numpy would turn
        # some of them into numbers (True -> 1.0, "1" -> 1.0), so refuse them here.
        if not _all_numbers(table[key]):
            raise HandcapError(f"{where} {key} must be an array of numbers, got {table[key]!r}")
    try:
        return Camera(**{key: table[key] for key in CAMERA_KEYS})
    except HandcapError as err:
        raise HandcapError(f"{where} {err}") from None


def _all_numbers(value) -> bool:
    if isinstance(value, list):
        return all(_all_numbers(item) for item in value)
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def write_cameras_toml(rig: CameraRig, path, *, warnings=()) -> None:
    """Write a camera rig as an anipose-style TOML file, atomically.

    Parameters
    ----------
    rig : CameraRig
    path : str or Path
        Written through a temporary file renamed into place.
    warnings : sequence of str
        One-line warnings of the calibration, stored in ``[metadata]`` after the rig's own
        (``rig.warnings``); with none at all, no metadata table is written.

    Raises
    ------
    HandcapError
        If ``rig`` is not a :class:`CameraRig` or the folder does not exist.
    """
    if not isinstance(rig, CameraRig):
        raise HandcapError(f"write_cameras_toml needs a CameraRig, got {type(rig).__name__}")
    document = {f"cam_{i}": _table_from_camera(camera) for i, camera in enumerate(rig)}
    warnings = merge_warnings(rig.warnings, warnings)
    if warnings:
        document[_METADATA] = {"warnings": list(warnings)}
    text = tomli_w.dumps(document)
    with atomic_output(path, "wb") as fh:
        fh.write(text.encode("utf-8"))


def read_cameras_warnings(path) -> tuple[str, ...]:
    """The warnings stored in an anipose-style TOML file's ``[metadata]`` (empty when there are none).

    Raises
    ------
    HandcapError
        Missing, unreadable or invalid TOML file.
    """
    path = existing_file(path)
    try:
        with open(path, "rb") as fh:
            return _stored_warnings(tomllib.load(fh).get(_METADATA))
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as err:
        raise HandcapError(f"{path}: not valid TOML ({err})") from None


def _table_from_camera(camera: Camera) -> dict:
    # tolist() gives Python floats, which tomli_w writes with repr: shortest round trip.
    return {
        "name": camera.name,
        "size": list(camera.size),
        "matrix": camera.matrix.tolist(),
        "distortions": camera.distortions.tolist(),
        "rotation": camera.rotation.tolist(),
        "translation": camera.translation.tolist(),
    }


__all__ = ["CAMERA_KEYS", "read_cameras_toml", "write_cameras_toml"]
