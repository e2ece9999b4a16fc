"""Camera rig files of other tools: OpenCV FileStorage, Qualisys QCA, caliscope TOML.

handcap's own rig file is the anipose-style TOML of :mod:`handcap.io.cameras`.
This module reads (and where possible writes) the other common layouts into the
same :class:`~handcap.core.cameras.CameraRig`, whose conventions are OpenCV's:
``x_camera = R @ x_world + t`` with ``R`` a Rodrigues vector, ``t`` in metres,
camera x right, y down, z forward, distortions ``k1 k2 p1 p2 k3``.

==================  ====================================================  ============
format              files                                                 read / write
==================  ====================================================  ============
anipose TOML        ``.toml`` with ``[cam_0]``... tables                  read, write
caliscope TOML      ``.toml`` with ``[cameras.0]``... tables              read, write
OpenCV FileStorage  ``.yml`` ``.yaml`` ``.xml``                           read, write
Qualisys QCA        ``.qca``, ``.qca.txt``, ``.xml`` (``<calibration>``)  read
==================  ====================================================  ============

:func:`read_rig` and :func:`write_rig` choose the format from the extension
and, where an extension is shared, from the content.

Each format has its module (:mod:`handcap.io.opencv_rig`, :mod:`handcap.io.qca`,
:mod:`handcap.io.caliscope`; anipose: :mod:`handcap.io.cameras`), with what its fields mean.
"""

from __future__ import annotations

import inspect
import xml.etree.ElementTree as ET
from pathlib import Path

from handcap.core.cameras import CameraRig, read_cameras_toml, write_cameras_toml
from handcap.core.errors import HandcapError
from handcap.core.files import existing_file, read_toml
from handcap.io._units import check_units, metres_per_unit, settle_rig_units
from handcap.io.caliscope import CALISCOPE_KEYS, is_caliscope, read_cameras_caliscope, write_cameras_caliscope
from handcap.io.opencv_rig import OPENCV_SUFFIXES, read_cameras_opencv, write_cameras_opencv
from handcap.io.qca import QCA_SUBPIXELS, read_cameras_qca


def camera_format(path) -> str:
    """Name the rig format of ``path``: ``anipose``, ``caliscope``, ``opencv`` or ``qca``.

    ``.toml`` files are caliscope's when their cameras are ``[cameras.N]``
    tables, anipose's otherwise; ``.qca`` and ``.qca.txt`` files are QCA, as is
    an ``.xml`` file whose root element is ``<calibration>``; other ``.yml``,
    ``.yaml`` and ``.xml`` files are OpenCV's.

    Raises
    ------
    HandcapError
        An extension handcap does not read cameras from, a missing file, or
        invalid TOML.
    """
    name = Path(path).name.lower()
    suffix = Path(path).suffix.lower()
    if name.endswith((".qca", ".qca.txt")):
        return "qca"
    if suffix not in (".toml", *OPENCV_SUFFIXES):
        raise HandcapError(f"{path}: cannot tell the camera file format from '{suffix or 'no extension'}'; "
                           f"use .toml (anipose, caliscope), .yml/.yaml/.xml (OpenCV) or .qca/.qca.txt (Qualisys)")
    path = existing_file(path)
    if suffix == ".toml":
        return "caliscope" if is_caliscope(read_toml(path)) else "anipose"
    if suffix == ".xml" and _xml_root_tag(path) == "calibration":
        return "qca"
    return "opencv"


def _xml_root_tag(path: Path) -> str | None:
    try:
        for _, element in ET.iterparse(path, events=("start",)):
            return element.tag
    except ET.ParseError:
        return None
    return None


READERS = {"anipose": read_cameras_toml, "caliscope": read_cameras_caliscope,
           "opencv": read_cameras_opencv, "qca": read_cameras_qca}


def read_rig(path, *, units: str | None = None, positions: bool = True, **options) -> CameraRig:
    """Read a camera rig from any supported file (format from extension and content).

    Parameters
    ----------
    path : str or Path
    units : {"mm", "cm", "m"}, optional
        The unit of the file's camera positions, overriding the format's
        (metres for TOML and OpenCV files, millimetres for QCA, ``unit=`` for an
        OpenCV stereo pair). Without it, a rig whose cameras lie implausibly
        far apart in the format's unit (2000 "m") is read in the one unit that
        fits, with a warning in ``warnings`` (see :mod:`handcap.io._units`).
    positions : bool
        False when only the intrinsics will be used (known intrinsics for a
        rig calibration): the camera positions, and so their unit, are not
        checked.
    **options
        Options of the format's reader: ``size``, ``extrinsics``, ``unit``,
        ``intrinsics_only`` for OpenCV (:func:`read_cameras_opencv`);
        ``ignore_viewrotation`` for QCA (:func:`read_cameras_qca`).

    Returns
    -------
    CameraRig
        Translations in metres.

    Raises
    ------
    HandcapError
        Unknown format, an option the format does not take, anything its
        reader refuses, or camera positions that fit no unit (or several,
        when the format's does not).

    See Also
    --------
    camera_format : how the format is chosen.
    """
    units = check_units(units)
    fmt = camera_format(path)
    reader = READERS[fmt]
    accepted = [name for name, p in inspect.signature(reader).parameters.items() if p.kind is p.KEYWORD_ONLY]
    unknown = sorted(set(options) - set(accepted))
    if unknown:
        raise HandcapError(f"{path}: {fmt} camera files take no option {', '.join(unknown)}; "
                           f"they take {', '.join(accepted) or 'none'}")
    rig = reader(path, **options)
    if not positions:
        return rig
    declared = "mm" if fmt == "qca" else options.get("unit", "m")
    if units is not None:
        rig = rig.scaled(metres_per_unit(units, "units") / metres_per_unit(declared, f"{path}: unit="))
    return settle_rig_units(rig, declared=declared, units=units, where=path)


def write_rig(rig: CameraRig, path) -> None:
    """Write a camera rig, atomically: ``.toml`` anipose style, ``.yml``/``.yaml``/``.xml`` OpenCV.

    caliscope's TOML is written by :func:`write_cameras_caliscope`; QCA files
    are read only.

    Parameters
    ----------
    rig : CameraRig
        Intrinsics in pixels, rotations as Rodrigues vectors (radians), translations in metres.
    path : str or Path
        The extension picks the format.

    Raises
    ------
    HandcapError
        Another extension, or anything the writer refuses.
    """
    name = Path(path).name.lower()
    suffix = Path(path).suffix.lower()
    if name.endswith((".qca", ".qca.txt")):
        raise HandcapError(f"{path}: handcap reads Qualisys QCA files but does not write them; "
                           f"use .toml or .yml/.yaml/.xml")
    if suffix == ".toml":
        write_cameras_toml(rig, path)
    elif suffix in OPENCV_SUFFIXES:
        write_cameras_opencv(rig, path)
    else:
        raise HandcapError(f"{path}: cannot write cameras as '{suffix or 'no extension'}'; "
                           f"use .toml (anipose) or .yml/.yaml/.xml (OpenCV)")


__all__ = [
    "CALISCOPE_KEYS", "OPENCV_SUFFIXES", "QCA_SUBPIXELS", "READERS", "camera_format", "read_cameras_caliscope",
    "read_cameras_opencv", "read_cameras_qca", "read_rig", "write_cameras_caliscope", "write_cameras_opencv",
    "write_rig",
]
