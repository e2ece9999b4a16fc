"""Anipose-style TOML camera files: a file's ``[cam_i]`` tables to :class:`~handcap.core.camera.Camera` objects and
back, the rig's warnings in its ``[metadata]`` table, and the ``.toml`` name rig files must have.

This module knows the file format and nothing of the rig: :mod:`handcap.core.camera_rig` builds its
``CameraRig`` from what :func:`read_camera_tables` returns (``read_cameras_toml``) and writes one with
:func:`write_camera_tables` (``write_cameras_toml``). The format is described for users in
:mod:`handcap.io.cameras`.
"""

from __future__ import annotations

from pathlib import Path

import tomli_w

from handcap.core.camera import Camera
from handcap.core.checks import all_numbers
from handcap.core.errors import HandcapError, merge_warnings
from handcap.core.files import atomic_output, existing_file, read_toml

CAMERA_KEYS = ("name", "size", "matrix", "distortions", "rotation", "translation")
_METADATA = "metadata"


def check_rig_suffix(path) -> None:
    """Refuse a rig file name that is not ``.toml`` (handcap's own rig files are anipose-style TOML)."""
    suffix = Path(path).suffix.lower()
    if suffix != ".toml":
        raise HandcapError(f"{path}: camera files are anipose-style .toml, got '{suffix or 'no extension'}'")


def read_camera_tables(path) -> tuple[Path, list[Camera], tuple[str, ...]]:
    """Read the camera tables and stored warnings of an anipose-style TOML file.

    Parameters
    ----------
    path : str or Path

    Returns
    -------
    path : Path
        The file, as checked to exist (error messages about the rig start with it).
    cameras : list of Camera
        One per camera table, in the order of the file's tables; translations in metres.
        Names are not checked to be unique here (the rig does it).
    warnings : tuple of str
        The ``warnings`` list of the ``[metadata]`` table; empty without one.

    Raises
    ------
    HandcapError
        Missing or unreadable file, invalid TOML, no camera table, a missing
        key, a value of the wrong shape or type, a non-finite number or a fisheye
        camera. The message names the file and table.
    """
    path = existing_file(path)
    document = read_toml(path)
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
    return path, cameras, _stored_warnings(document.get(_METADATA))


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
        if not all_numbers(table[key]):
            raise HandcapError(f"{where} {key} must be an array of numbers, got {table[key]!r}")
    try:
        return Camera(**{key: table[key] for key in CAMERA_KEYS})
    except HandcapError as err:
        raise HandcapError(f"{where} {err}") from None


def write_camera_tables(cameras, path, *, warnings=()) -> None:
    """Write cameras as the ``[cam_0]``, ``[cam_1]``, ... tables of an anipose-style TOML file, atomically.

    Parameters
    ----------
    cameras : sequence of Camera
        Written in order; sizes in pixels, translations in metres.
    path : str or Path
        Written through a temporary file renamed into place.
    warnings : sequence of str
        One-line warnings stored in ``[metadata]`` (repeats and empty lines dropped); with none,
        no metadata table is written.

    Raises
    ------
    HandcapError
        If the folder does not exist or cannot be written in.
    """
    document = {f"cam_{i}": _table_from_camera(camera) for i, camera in enumerate(cameras)}
    warnings = merge_warnings(warnings)
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
    return _stored_warnings(read_toml(path).get(_METADATA))


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


__all__ = ["CAMERA_KEYS", "check_rig_suffix", "read_camera_tables", "read_cameras_warnings", "write_camera_tables"]
