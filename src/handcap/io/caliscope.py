"""Camera rigs in caliscope's ``camera_array.toml``.

caliscope's ``camera_array.toml`` holds one ``[cameras.N]`` table per camera
port ``N``: ``size = [w, h]``, ``matrix`` (3x3), ``distortions`` (k1 k2 p1 p2
k3), ``rotation`` (a 3x3 matrix) and ``translation`` (metres). caliscope
projects with ``cv2.projectPoints(points, Rodrigues(rotation), translation,
matrix, distortions)`` (``xy_reprojection_error`` in its
``capture_volume.py``), so the pair maps the world to the camera, as handcap's
does. Read so, the sample session's cameras triangulate caliscope's own ChArUco
detections (``xy.csv``) to 0.8 pixel RMS and keep the board's 5.4 cm spacing
to 1 mm; read as camera-to-world, they miss by some 300 pixels. Cameras are
named ``cam_N`` and ordered by port; ``ignore = true`` cameras are skipped;
``rotation_count`` only turns caliscope's preview (its ``Camera`` says so) and
is ignored, as are other keys.
"""

from __future__ import annotations

import re

import tomli_w

from handcap.core.cameras import CameraRig
from handcap.core.checks import all_numbers
from handcap.core.errors import HandcapError
from handcap.core.files import atomic_output, existing_file, read_toml
from handcap.io.rig_fields import camera_from_fields, check_rig_to_write, rig_from_cameras, rotation_vector

CALISCOPE_KEYS = ("size", "matrix", "distortions", "rotation", "translation")
_CALISCOPE_NAME = re.compile(r"cam_(\d+)")


def read_cameras_caliscope(path) -> CameraRig:
    """Read caliscope's ``camera_array.toml`` (``[cameras.N]`` tables).

    Parameters
    ----------
    path : str or Path

    Returns
    -------
    CameraRig
        Cameras ``cam_N`` by port ``N``, ``ignore = true`` ones left out;
        rotation and translation (metres) from the world to each camera.

    Raises
    ------
    HandcapError
        Missing file, invalid TOML, no ``[cameras.N]`` table, a port that is
        not a whole number, a missing key (a camera not calibrated yet), a value
        of the wrong shape or type, a non-finite number, or a ``rotation`` that
        is no rotation matrix. The message names the file and table.
    """
    path = existing_file(path)
    document = read_toml(path)
    tables = document.get("cameras")
    if not is_caliscope(document):
        raise HandcapError(f"{path}: not a caliscope camera array; expected [cameras.0], [cameras.1], ... tables")
    cameras = []
    for port, table in sorted(tables.items(), key=lambda item: int(item[0])):
        where = f"{path}: [cameras.{port}]"
        if table.get("ignore", False) is True:
            continue
        missing = [key for key in CALISCOPE_KEYS if key not in table]
        if missing:
            raise HandcapError(f"{where} lacks {', '.join(missing)}; each camera needs {', '.join(CALISCOPE_KEYS)} "
                               f"(is its calibration finished?)")
        for key in CALISCOPE_KEYS:
            if not all_numbers(table[key]):
                raise HandcapError(f"{where} {key} must be an array of numbers, got {table[key]!r}")
        rotation = rotation_vector(table["rotation"], f"{where} rotation")
        cameras.append(camera_from_fields(where, name=f"cam_{int(port)}", size=table["size"], matrix=table["matrix"],
                               distortions=table["distortions"], rotation=rotation,
                               translation=table["translation"]))
    return rig_from_cameras(path, cameras, "[cameras.N] tables that are not ignored")


def is_caliscope(document: dict) -> bool:
    """Whether a parsed TOML document looks like caliscope's camera array.

    True when it has a non-empty ``cameras`` table whose keys are all port numbers
    (digit strings) and whose values are all tables; the cameras' fields are not checked.

    Parameters
    ----------
    document : dict
        A parsed TOML document.

    Returns
    -------
    bool
    """
    tables = document.get("cameras")
    return (isinstance(tables, dict) and bool(tables)
            and all(isinstance(key, str) and key.isdigit() and isinstance(value, dict)
                    for key, value in tables.items()))


def write_cameras_caliscope(rig: CameraRig, path) -> None:
    """Write a rig as caliscope's ``camera_array.toml``, atomically.

    Each camera must be named ``cam_N`` (``N`` its caliscope port). Rotations
    are written as 3x3 matrices, so they read back equal to about 1e-15.

    Parameters
    ----------
    rig : CameraRig
    path : str or Path

    Raises
    ------
    HandcapError
        If ``rig`` is not a :class:`CameraRig`, a camera name is not
        ``cam_N``, or the folder does not exist.
    """
    check_rig_to_write(rig, "write_cameras_caliscope")
    document = {}
    for camera in rig:
        found = _CALISCOPE_NAME.fullmatch(camera.name)
        if found is None:
            raise HandcapError(f"{path}: caliscope names cameras by port, so camera {camera.name!r} must be "
                               f"renamed cam_0, cam_1, ...")
        port = int(found[1])
        if str(port) in document:
            raise HandcapError(f"{path}: cameras {camera.name!r} and another one share caliscope port {port}")
        document[str(port)] = {
            "cam_id": port, "size": list(camera.size), "rotation_count": 0, "ignore": False,
            "matrix": camera.matrix.tolist(), "distortions": camera.distortions.tolist(),
            "translation": camera.translation.tolist(), "rotation": camera.rotation_matrix.tolist(),
        }
    text = tomli_w.dumps({"cameras": document})
    with atomic_output(path, "wb") as fh:
        fh.write(text.encode("utf-8"))
