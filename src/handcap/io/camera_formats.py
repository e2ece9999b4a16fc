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

OpenCV FileStorage
------------------
Three layouts are read:

* handcap's rig layout, written by :func:`write_cameras_opencv` in the style of
  OpenCV's ``calibration.cpp`` sample (the comments are for this page; the file
  carries one header comment on the conventions)::

      %YAML 1.2
      ---
      camera_count: 2
      cameras:
         -
            name: "A"
            image_width: 2448                     # pixels
            image_height: 2048
            camera_matrix: !!opencv-matrix        # 3x3, pixels
            distortion_coefficients: !!opencv-matrix   # 5x1: k1 k2 p1 p2 k3
            rvec: !!opencv-matrix                 # 3x1 Rodrigues, world to camera
            tvec: !!opencv-matrix                 # 3x1 metres, world to camera
         -
            ...

  ``.xml`` holds the same nodes (``<cameras><_>...</_></cameras>``). Numbers are
  written with 17 significant digits, so a rig reads back equal (``-0.0``
  comes back as ``0.0``).
* one camera as OpenCV's ``calibration.cpp`` sample and its tutorial write it:
  ``camera_matrix``, ``distortion_coefficients``, ``image_width`` and
  ``image_height`` (keys in any case). The camera frame is the world: rotation
  and translation are zero. Per-view board poses (``extrinsic_parameters``) are
  not camera poses and are ignored.
* a stereo pair as OpenCV's ``stereo_calib.cpp`` sample writes it:
  ``M1 D1 M2 D2`` (its ``intrinsics.yml``), and ``R T`` (its
  ``extrinsics.yml``; in the same file or passed as ``extrinsics=``). The
  cameras are named ``cam_1`` and ``cam_2``; the world is camera 1's frame and
  ``x_2 = R @ x_1 + T``. ``T`` is in the unit of the board squares given to the
  sample, so say which with ``unit=``. That sample writes no image size: pass
  ``size=``.

Qualisys QCA
------------
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

caliscope TOML
--------------
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

import inspect
import re
import tomllib
import xml.etree.ElementTree as ET
from pathlib import Path

import cv2
import numpy as np
import tomli_w

from handcap.core.cameras import Camera, CameraRig
from handcap.core.errors import HandcapError
from handcap.core.rotations import axis_angle_from_matrix
from handcap.core.files import atomic_output, existing_file
from handcap.io._units import check_units, metres_per_unit, settle_rig_units
from handcap.core.cameras import read_cameras_toml, write_cameras_toml
from handcap.core.checks import all_numbers

OPENCV_SUFFIXES = (".yml", ".yaml", ".xml")
QCA_SUBPIXELS = 64  # QTM sensor coordinates per pixel
_ROTATION_TOLERANCE = 1e-6  # largest |R R^T - I| accepted as a rotation
# Qualisys' camera frame (x right, y up, looking along -z) to OpenCV's (x right, y down, z forward).
_OPENCV_FROM_QUALISYS = np.diag([1.0, -1.0, -1.0])


# -- shared helpers ----------------------------------------------------------------------
def _camera(where: str, **fields) -> Camera:
    try:
        return Camera(**fields)
    except HandcapError as err:
        raise HandcapError(f"{where} {err}") from None


def _rig(path, cameras: list[Camera], what: str) -> CameraRig:
    if not cameras:
        raise HandcapError(f"{path}: no cameras; expected {what}")
    try:
        return CameraRig(cameras)
    except HandcapError as err:
        raise HandcapError(f"{path}: {err}") from None


def _rotation_vector(matrix, where: str) -> np.ndarray:
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
    if not error <= _ROTATION_TOLERANCE or np.linalg.det(matrix) <= 0:
        raise HandcapError(f"{where} is not a rotation matrix (|R R^T - I| = {error:.2g}, "
                           f"det = {np.linalg.det(matrix):.6g})")
    return axis_angle_from_matrix(matrix)


def _check_rig(rig, verb: str) -> None:
    if not isinstance(rig, CameraRig):
        raise HandcapError(f"{verb} needs a CameraRig, got {type(rig).__name__}")


# -- OpenCV FileStorage ------------------------------------------------------------------
def read_cameras_opencv(path, *, size=None, extrinsics=None, unit: str = "m",
                        intrinsics_only: bool = False) -> CameraRig:
    """Read cameras from an OpenCV FileStorage file (``.yml``, ``.yaml``, ``.xml``).

    Parameters
    ----------
    path : str or Path
        handcap's rig layout, a one-camera calibration, or a stereo pair's
        ``M1 D1 M2 D2`` (see the module docstring).
    size : (int, int), optional
        Image ``(width, height)`` in pixels, for files that hold none (such as
        ``stereo_calib.cpp``'s ``intrinsics.yml``). Where the file has a size,
        it must agree.
    extrinsics : str or Path, optional
        The stereo extrinsics file (``R``, ``T``) of a stereo intrinsics file.
    unit : str
        Unit of the stereo translation ``T`` (``m``, ``cm`` or ``mm``): that of
        the square size given to the calibration. handcap's layout is in metres.
    intrinsics_only : bool
        Read the intrinsics only and put every camera at the world origin
        (rotation and translation zero); needed for a stereo file without ``R T``.

    Returns
    -------
    CameraRig
        Translations in metres.

    Raises
    ------
    HandcapError
        Missing or unreadable file, no camera calibration in it, a missing key,
        a value of the wrong shape, a non-finite number, no image size and no
        ``size=``, or a stereo pair without extrinsics. The message names the
        file and camera.
    """
    path = existing_file(path)
    scale = metres_per_unit(unit, f"{path}: unit=")
    storage = _filestorage(path)  # FileNodes point into it: keep it alive while they are used
    root = storage.root()
    keys = {key.lower(): key for key in root.keys()}
    stereo = {"m1", "d1", "m2", "d2"} <= set(keys) and "cameras" not in keys and "camera_matrix" not in keys
    if extrinsics is not None and intrinsics_only:
        raise HandcapError(f"{path}: extrinsics= and intrinsics_only=True contradict each other; pass one")
    if not stereo and extrinsics is not None:
        raise HandcapError(f"{path}: extrinsics= is for a stereo intrinsics file (M1 D1 M2 D2)")
    if not (stereo and not intrinsics_only) and scale != 1.0:
        raise HandcapError(f"{path}: unit= is the unit of a stereo translation T, which is not read from this file")
    if "cameras" in keys:
        cameras = [_opencv_camera(node, f"{path}: cameras[{i}]", size, intrinsics_only)
                   for i, node in enumerate(_sequence(root.getNode(keys["cameras"]), f"{path}: cameras"))]
    elif "camera_matrix" in keys:
        cameras = [_opencv_camera(root, f"{path}:", size, True, name=path.stem)]
    elif stereo:
        cameras = _opencv_stereo(path, root, keys, size, extrinsics, scale, intrinsics_only)
    else:
        raise HandcapError(f"{path}: holds no camera calibration (it has {', '.join(root.keys()) or 'nothing'}); "
                           f"expected 'cameras', 'camera_matrix' or M1 D1 M2 D2")
    return _rig(path, cameras, "'cameras', 'camera_matrix' or M1 D1 M2 D2")


def _filestorage(path: Path) -> cv2.FileStorage:
    try:
        text = path.read_text(encoding="utf-8")
    except UnicodeDecodeError:
        raise HandcapError(f"{path}: not an OpenCV YAML/XML file (not UTF-8 text)") from None
    try:
        storage = cv2.FileStorage(text, cv2.FILE_STORAGE_READ | cv2.FILE_STORAGE_MEMORY)
    except (cv2.error, SystemError) as err:
        # In memory mode OpenCV names the text as the file; keep its line and reason only.
        message = str(err.__cause__ or err)
        found = re.search(r"\((\d+)\): ([^\n]*?)'?\s*$", message)
        reason = f"line {found[1]}: {found[2]}" if found else message.strip().splitlines()[-1]
        raise HandcapError(f"{path}: not an OpenCV YAML/XML file ({reason})") from None
    if not storage.root().isMap():
        raise HandcapError(f"{path}: not an OpenCV YAML/XML file with named nodes (is it empty?)")
    return storage


def _sequence(node: cv2.FileNode, where: str) -> list[cv2.FileNode]:
    if not node.isSeq():
        raise HandcapError(f"{where} must be a sequence of camera maps")
    return [node.at(i) for i in range(node.size())]


def _node(parent: cv2.FileNode, where: str, *names: str) -> cv2.FileNode:
    """The child called any of ``names`` (any case)."""
    keys = {key.lower(): key for key in parent.keys()}
    for name in names:
        if name.lower() in keys:
            return parent.getNode(keys[name.lower()])
    raise HandcapError(f"{where} lacks {names[0]}")


def _has(parent: cv2.FileNode, *names: str) -> bool:
    keys = {key.lower() for key in parent.keys()}
    return any(name.lower() in keys for name in names)


def _array(node: cv2.FileNode, where: str) -> np.ndarray:
    """Numbers of an ``!!opencv-matrix``, a sequence or a single number, float64."""
    if node.isMap():
        array = _opencv_matrix(node, where)
    elif node.isSeq():
        array = _numbers_of(node, where)
    elif node.isInt() or node.isReal():
        array = np.array([node.real()])
    else:
        raise HandcapError(f"{where} must be numbers")
    if not np.isfinite(array).all():
        raise HandcapError(f"{where} must be finite, got {array.ravel().tolist()}")
    return array


def _numbers_of(node: cv2.FileNode, where: str) -> np.ndarray:
    items = [node.at(i) for i in range(node.size())]
    if not all(item.isInt() or item.isReal() for item in items):
        raise HandcapError(f"{where} must be numbers")
    return np.array([item.real() for item in items], dtype=np.float64)


def _opencv_matrix(node: cv2.FileNode, where: str) -> np.ndarray:
    """The values of an ``!!opencv-matrix`` map (rows, cols, dt, data), read here rather than by
    ``FileNode.mat()``: OpenCV 5 writes past its buffer when ``rows``/``cols`` are missing or disagree with
    ``data`` (found by tests/io/test_fuzz_readers.py), which corrupts the heap of the whole process."""
    keys = {key.lower(): key for key in node.keys()}
    missing = [key for key in ("rows", "cols", "dt", "data") if key not in keys]
    if missing:
        raise HandcapError(f"{where} must be an opencv-matrix (rows, cols, dt, data); it lacks {', '.join(missing)}")
    rows, cols = (node.getNode(keys[key]) for key in ("rows", "cols"))
    if not (rows.isInt() and cols.isInt()) or not (0 < rows.real() <= 64 and 0 < cols.real() <= 64):
        raise HandcapError(f"{where} rows and cols must be whole numbers from 1 to 64")
    dt = node.getNode(keys["dt"])
    if not dt.isString() or dt.string() not in ("d", "f", "i", "u", "s", "w", "c", "1d", "1f", "1i"):
        raise HandcapError(f"{where} dt must name a one-channel number type (d, f, i, ...)")
    data = node.getNode(keys["data"])
    values = _numbers_of(data, f"{where} data") if data.isSeq() else None
    shape = (int(rows.real()), int(cols.real()))
    if values is None or values.size != shape[0] * shape[1]:
        raise HandcapError(f"{where} data must hold rows x cols = {shape[0] * shape[1]} numbers")
    return values.reshape(shape)


def _distortions(node: cv2.FileNode, where: str) -> np.ndarray:
    array = _array(node, where).ravel()
    # OpenCV's 12- and 14-term models equal the 5-term one when the extra terms are zero.
    if array.shape[0] in (12, 14) and not np.any(array[5:]):
        array = array[:5]
    return array


def _integer(node: cv2.FileNode, where: str) -> int:
    if not node.isInt():
        raise HandcapError(f"{where} must be a whole number of pixels")
    return int(node.real())


def _opencv_size(node: cv2.FileNode, where: str, size) -> tuple:
    if _has(node, "image_width") or _has(node, "image_height"):
        found = (_integer(_node(node, where, "image_width"), f"{where} image_width"),
                 _integer(_node(node, where, "image_height"), f"{where} image_height"))
        if size is not None and tuple(size) != found:
            raise HandcapError(f"{where} image is {found[0]}x{found[1]} pixels, but size= says {tuple(size)}")
        return found
    if size is None:
        raise HandcapError(f"{where} holds no image size (image_width, image_height); pass "
                           f"size=(width, height) of the images it was calibrated on")
    return tuple(size)


def _opencv_camera(node: cv2.FileNode, where: str, size, intrinsics_only: bool, name: str | None = None) -> Camera:
    if not node.isMap():
        raise HandcapError(f"{where} must be a map with name, image_width, image_height, camera_matrix, "
                           f"distortion_coefficients, rvec, tvec")
    if name is None:
        name_node = _node(node, where, "name")
        if not name_node.isString():
            raise HandcapError(f"{where} name must be a string")
        name = name_node.string()
        where = f"{where} ({name})"
    fields = {
        "name": name,
        "size": _opencv_size(node, where, size),
        "matrix": _array(_node(node, where, "camera_matrix"), f"{where} camera_matrix"),
        "distortions": _distortions(_node(node, where, "distortion_coefficients"),
                                    f"{where} distortion_coefficients"),
    }
    if not intrinsics_only:
        fields["rotation"] = _array(_node(node, where, "rvec"), f"{where} rvec")
        fields["translation"] = _array(_node(node, where, "tvec"), f"{where} tvec")
    return _camera(where, **fields)


def _opencv_stereo(path, root, keys, size, extrinsics, scale, intrinsics_only):
    where = f"{path}:"
    rt_root, rt_where = root, where
    if extrinsics is not None:
        extrinsics = existing_file(extrinsics)
        rt_storage = _filestorage(extrinsics)  # kept alive while rt_root is used
        rt_root, rt_where = rt_storage.root(), f"{extrinsics}:"
    missing = []
    if size is None and not _has(root, "image_width", "image_height"):
        missing.append("no image size (pass size=(width, height) of the images it was calibrated on)")
    if extrinsics is None and not intrinsics_only and not {"r", "t"} <= set(keys):
        missing.append("no stereo extrinsics R, T (pass extrinsics= the file they were saved to, "
                       "stereo_calib's extrinsics.yml, or intrinsics_only=True to put both cameras "
                       "at the world origin)")
    if missing:
        raise HandcapError(f"{path}: holds the intrinsics of two cameras (M1 D1 M2 D2) but {' and '.join(missing)}")
    shape_size = _opencv_size(root, where, size)
    cameras = []
    for i in (1, 2):
        fields = {
            "name": f"cam_{i}",
            "size": shape_size,
            "matrix": _array(root.getNode(keys[f"m{i}"]), f"{where} M{i}"),
            "distortions": _distortions(root.getNode(keys[f"d{i}"]), f"{where} D{i}"),
        }
        if i == 2 and not intrinsics_only:
            rotation = _array(_node(rt_root, rt_where, "R"), f"{rt_where} R")
            if rotation.size == 9:
                rotation = _rotation_vector(rotation.reshape(3, 3), f"{rt_where} R")
            fields["rotation"] = rotation
            fields["translation"] = _array(_node(rt_root, rt_where, "T"), f"{rt_where} T") * scale
        cameras.append(_camera(f"{path}: cam_{i}", **fields))
    return cameras


def write_cameras_opencv(rig: CameraRig, path) -> None:
    """Write a rig in handcap's OpenCV FileStorage layout, atomically.

    Parameters
    ----------
    rig : CameraRig
    path : str or Path
        ``.yml`` or ``.yaml`` for YAML, ``.xml`` for XML; written through a
        temporary file renamed into place.

    Raises
    ------
    HandcapError
        If ``rig`` is not a :class:`CameraRig`, the extension is none of
        those, or the folder does not exist.

    See Also
    --------
    read_cameras_opencv : reads it back (equal numbers, names and sizes).
    """
    _check_rig(rig, "write_cameras_opencv")
    suffix = Path(path).suffix.lower()
    if suffix not in OPENCV_SUFFIXES:
        raise HandcapError(f"{path}: OpenCV camera files are {', '.join(OPENCV_SUFFIXES)}, "
                           f"got '{suffix or 'no extension'}'")
    fmt = cv2.FILE_STORAGE_FORMAT_XML if suffix == ".xml" else cv2.FILE_STORAGE_FORMAT_YAML
    storage = cv2.FileStorage("", cv2.FILE_STORAGE_WRITE | cv2.FILE_STORAGE_MEMORY | fmt)
    storage.writeComment("handcap camera rig: x_camera = Rodrigues(rvec) @ x_world + tvec; tvec in metres; "
                         "OpenCV camera axes (x right, y down, z forward); distortion k1 k2 p1 p2 k3")
    storage.write("camera_count", len(rig))
    storage.startWriteStruct("cameras", cv2.FileNode_SEQ)
    for camera in rig:
        storage.startWriteStruct("", cv2.FileNode_MAP)
        storage.write("name", camera.name)
        storage.write("image_width", camera.size[0])
        storage.write("image_height", camera.size[1])
        storage.write("camera_matrix", np.array(camera.matrix))
        storage.write("distortion_coefficients", camera.distortions.reshape(5, 1))
        storage.write("rvec", camera.rotation.reshape(3, 1))
        storage.write("tvec", camera.translation.reshape(3, 1))
        storage.endWriteStruct()
    storage.endWriteStruct()
    text = storage.releaseAndGetString()
    with atomic_output(path, "wb") as fh:
        fh.write(text.encode("utf-8"))


# -- Qualisys QCA ------------------------------------------------------------------------
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
    return _rig(path, cameras, "<cameras><camera ...> elements")


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
    rotation = _rotation_vector(world2camera, f"{where} <transform> r11..r33")
    return _camera(where, name=serial, size=size, matrix=matrix, distortions=[k1, k2, p1, p2, k3],
                   rotation=rotation, translation=-world2camera @ position)


# -- caliscope TOML ----------------------------------------------------------------------
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
    document = _toml(path)
    tables = document.get("cameras")
    if not _is_caliscope(document):
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
        rotation = _rotation_vector(table["rotation"], f"{where} rotation")
        cameras.append(_camera(where, name=f"cam_{int(port)}", size=table["size"], matrix=table["matrix"],
                               distortions=table["distortions"], rotation=rotation,
                               translation=table["translation"]))
    return _rig(path, cameras, "[cameras.N] tables that are not ignored")


def _toml(path: Path) -> dict:
    try:
        with open(path, "rb") as fh:
            return tomllib.load(fh)
    except tomllib.TOMLDecodeError as err:
        raise HandcapError(f"{path}: not valid TOML ({err})") from None
    except UnicodeDecodeError:
        raise HandcapError(f"{path}: not valid TOML (not UTF-8 text)") from None


def _is_caliscope(document: dict) -> bool:
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
    _check_rig(rig, "write_cameras_caliscope")
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


# -- choosing the format -----------------------------------------------------------------
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
        return "caliscope" if _is_caliscope(_toml(path)) else "anipose"
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
