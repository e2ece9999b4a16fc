"""Camera rigs in Qualisys QCA calibration files (read only).

A QTM calibration exported as XML (root ``<calibration>``, one ``<camera>`` per
camera, named by its ``serial``; cameras with ``active="0"`` are skipped). What
each field means, and the evidence:

* ``<intrinsic>``: ``focalLengthU/V`` and ``centerPointU/V`` are in sensor
  sub-pixels, 64 to the pixel (``sensorMaxU = 69568 = 1087 * 64`` for a
  1088 pixel wide image). The principal point is shifted by the crop
  ``fov_video`` ``left``/``top``; the image size is ``right - left + 1`` by
  ``bottom - top + 1``. The pixel grid is taken to be OpenCV's (pixel centres
  on whole numbers); the QCA does not say, so ``c`` may be off by half a pixel.
* ``radialDistortion1..3`` and ``tangentalDistortion1..2`` are OpenCV's
  ``k1 k2 k3 p1 p2`` on normalised coordinates, as they stand. Pose2Sim divides
  them by 64; but a checkerboard calibration of the Pose2Sim demo's own photos
  gives ``k1 ~ -0.05, k2 ~ 0.15`` where the QCA says ``-0.046, 0.140``, and
  ``k1`` refitted to them with everything else as read here comes within 0.008
  of the QCA's for all four cameras (``tests/io/test_camera_formats.py``). The
  order of ``p1 p2`` could not be confirmed: they are tiny and poorly
  determined by those photos.
* ``<transform>``: ``x y z`` is the camera's position in the world in
  millimetres, and the matrix of rows ``r11 r12 r13 / r21 r22 r23 / r31 r32 r33``
  maps world vectors into Qualisys' camera frame (its rows are the camera axes
  in the world), as Pose2Sim's ``read_qca`` reads it. Qualisys' camera frame
  has x right, y up and looks along -z (OpenGL's), so OpenCV's rotation is
  ``diag(1, -1, -1) @ M``. With that reading, the four optical axes of the
  Pose2Sim demo meet within 0.12 m at a point 3.3 to 3.8 m in front of every
  camera, and up in the world is up in every (``viewrotation="0"``) image;
  reading ``x y z`` as a translation or the matrix by columns does neither.
* ``viewrotation`` (0, 90, 180, 270) says how QTM turns the camera's image
  for display. Whether exported videos are turned too is not known here, so a
  camera with a non-zero ``viewrotation`` is refused unless
  ``ignore_viewrotation=True`` (then its calibration is that of the unturned
  sensor image).
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np

from handcap.core.cameras import Camera, CameraRig
from handcap.core.errors import HandcapError
from handcap.core.files import existing_file
from handcap.io.rig_fields import camera_from_fields, rig_from_cameras, rotation_vector

QCA_SUBPIXELS = 64  # QTM sensor coordinates per pixel
# Qualisys' camera frame (x right, y up, looking along -z) to OpenCV's (x right, y down, z forward).
_OPENCV_FROM_QUALISYS = np.diag([1.0, -1.0, -1.0])


def read_cameras_qca(path, *, ignore_viewrotation: bool = False) -> CameraRig:
    """Read a Qualisys QTM calibration exported as XML (``.qca``, ``.qca.txt``).

    Parameters
    ----------
    path : str or Path
    ignore_viewrotation : bool
        Read cameras with a non-zero ``viewrotation`` in their sensor's
        orientation instead of refusing them (see the module docstring).

    Returns
    -------
    CameraRig
        Active cameras in file order, named by serial; translations in metres,
        OpenCV's camera axes; image size and principal point of ``fov_video``.

    Raises
    ------
    HandcapError
        Missing file, not XML, root not ``<calibration>``, no camera, a camera
        lacking an element or attribute, a non-finite number, a skewed sensor,
        a video field of view outside the sensor, a non-zero ``viewrotation``.
        The message names the file and camera.
    """
    path = existing_file(path)
    root = _qca_root(path)
    cameras = []
    elements = root.findall("cameras/camera")
    for i, element in enumerate(elements):
        serial = element.get("serial") or f"#{i + 1}"
        where = f"{path}: camera {serial!r}"
        if element.get("active", "1").strip() == "0":
            continue
        cameras.append(_qca_camera(element, serial, where, ignore_viewrotation))
    if elements and not cameras:
        raise HandcapError(f"{path}: every camera is inactive (active=\"0\")")
    return rig_from_cameras(path, cameras, "<cameras><camera ...> elements")


def _qca_root(path: Path) -> ET.Element:
    try:
        root = ET.parse(path).getroot()
    except ET.ParseError as err:
        raise HandcapError(f"{path}: not a Qualisys calibration (not valid XML: {err})") from None
    if root.tag != "calibration":
        raise HandcapError(f"{path}: not a Qualisys calibration (its XML root is <{root.tag}>, "
                           f"expected <calibration>)")
    return root


def _child(element: ET.Element, tag: str, where: str) -> ET.Element:
    child = element.find(tag)
    if child is None:
        raise HandcapError(f"{where} lacks <{tag}>")
    return child


def _attribute(element: ET.Element, names, where: str) -> float:
    """A finite number from the first of ``names`` present on ``element``."""
    names = (names,) if isinstance(names, str) else names
    for name in names:
        if name in element.attrib:
            text = element.attrib[name]
            try:
                value = float(text)
            except ValueError:
                raise HandcapError(f"{where} <{element.tag}> {name} must be a number, got {text!r}") from None
            if not np.isfinite(value):
                raise HandcapError(f"{where} <{element.tag}> {name} must be finite, got {text!r}")
            return value
    raise HandcapError(f"{where} <{element.tag}> lacks {names[0]}")


def _qca_camera(element: ET.Element, serial: str, where: str, ignore_viewrotation: bool) -> Camera:
    rotation_text = element.get("viewrotation", "0").strip()
    if rotation_text not in ("0", "90", "180", "270"):
        raise HandcapError(f"{where} viewrotation must be 0, 90, 180 or 270, got {rotation_text!r}")
    if rotation_text != "0" and not ignore_viewrotation:
        raise HandcapError(f"{where} has viewrotation={rotation_text}: QTM turns its image for display, and "
                           f"handcap cannot tell whether the videos were saved turned; pass "
                           f"ignore_viewrotation=True to read it for the unturned sensor image")
    fov = _child(element, "fov_video", where)
    left, top, right, bottom = (_attribute(fov, key, where) for key in ("left", "top", "right", "bottom"))
    intrinsic = _child(element, "intrinsic", where)
    a = {key: _attribute(intrinsic, key, where) for key in (
        "focalLengthU", "focalLengthV", "centerPointU", "centerPointV", "skew",
        "sensorMinU", "sensorMaxU", "sensorMinV", "sensorMaxV")}
    if a["skew"] != 0:
        raise HandcapError(f"{where} <intrinsic> skew is {a['skew']}; handcap's camera model has none")
    sensor = np.array([a["sensorMinU"], a["sensorMinV"], a["sensorMaxU"], a["sensorMaxV"]]) / QCA_SUBPIXELS
    if left < sensor[0] - 1 or top < sensor[1] - 1 or right > sensor[2] + 1 or bottom > sensor[3] + 1:
        raise HandcapError(f"{where} <fov_video> {left:g} {top:g} {right:g} {bottom:g} (left top right bottom) "
                           f"lies outside the sensor {' '.join(f'{s:g}' for s in sensor)} pixels; binned or "
                           f"scaled video is not supported")
    size = (right - left + 1, bottom - top + 1)
    matrix = [[a["focalLengthU"] / QCA_SUBPIXELS, 0.0, a["centerPointU"] / QCA_SUBPIXELS - left],
              [0.0, a["focalLengthV"] / QCA_SUBPIXELS, a["centerPointV"] / QCA_SUBPIXELS - top],
              [0.0, 0.0, 1.0]]
    k1, k2, k3 = (_attribute(intrinsic, f"radialDistortion{n}", where) for n in (1, 2, 3))
    p1, p2 = (_attribute(intrinsic, (f"tangentalDistortion{n}", f"tangentialDistortion{n}"), where)
              for n in (1, 2))
    transform = _child(element, "transform", where)
    world2qualisys = np.array([[_attribute(transform, f"r{i}{j}", where) for j in (1, 2, 3)] for i in (1, 2, 3)])
    position = np.array([_attribute(transform, key, where) for key in ("x", "y", "z")]) * 1e-3
    world2camera = _OPENCV_FROM_QUALISYS @ world2qualisys
    rotation = rotation_vector(world2camera, f"{where} <transform> r11..r33")
    return camera_from_fields(where, name=serial, size=size, matrix=matrix, distortions=[k1, k2, p1, p2, k3],
                   rotation=rotation, translation=-world2camera @ position)
