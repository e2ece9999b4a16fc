"""Camera rigs in OpenCV FileStorage files (``.yml``, ``.yaml``, ``.xml``).

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
"""

from __future__ import annotations

import re
from pathlib import Path

import cv2
import numpy as np

from handcap.core.cameras import Camera, CameraRig
from handcap.core.errors import HandcapError
from handcap.core.files import atomic_output, existing_file
from handcap.io._units import metres_per_unit
from handcap.io.rig_fields import camera_from_fields, check_rig_to_write, rig_from_cameras, rotation_vector

OPENCV_SUFFIXES = (".yml", ".yaml", ".xml")


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
    return rig_from_cameras(path, cameras, "'cameras', 'camera_matrix' or M1 D1 M2 D2")


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
    return camera_from_fields(where, **fields)


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
                rotation = rotation_vector(rotation.reshape(3, 3), f"{rt_where} R")
            fields["rotation"] = rotation
            fields["translation"] = _array(_node(rt_root, rt_where, "T"), f"{rt_where} T") * scale
        cameras.append(camera_from_fields(f"{path}: cam_{i}", **fields))
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
    check_rig_to_write(rig, "write_cameras_opencv")
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
