"""Calibrated cameras: ``Camera`` (one pinhole camera) and ``CameraRig`` (an ordered set).

Conventions (written down once)
-------------------------------
* The world frame is in metres, z up (see DESIGN.md).
* The camera frame is OpenCV's: x to the right of the image, y down, z forward
  along the optical axis. ``depth`` is the z coordinate in that frame, metres.
* ``rotation`` (Rodrigues vector, radians) and ``translation`` (metres) map the
  world to the camera, as OpenCV's ``rvec``/``tvec`` and anipose's files do:
  ``x_camera = R @ x_world + t``. ``camera2world`` is the inverse, and the
  camera sits at ``center = -R.T @ t`` in the world.
* Pixels follow OpenCV: ``(u, v)`` with u to the right and v down, the centre of
  the top-left pixel at (0, 0). The sensor of a ``w x h`` image covers
  ``-0.5 <= u < w - 0.5`` and ``-0.5 <= v < h - 0.5``.
* Lens distortion is OpenCV's five-term model ``k1 k2 p1 p2 k3`` (radial and
  tangential, Brown-Conrady). The camera matrix has no skew, as in OpenCV's
  :func:`cv2.projectPoints`, which ignores it.

Rigs are stored as anipose-style TOML (:func:`read_cameras_toml`,
:func:`write_cameras_toml`, ``CameraRig.save`` and ``CameraRig.load``; the
format is described in :mod:`handcap.io.cameras`, which names these for
users beside the other formats).
"""

from __future__ import annotations

import operator
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
import tomli_w

from handcap.core.checks import all_numbers, check_finite, check_numbers, check_pixels, check_points, check_vector
from handcap.core.errors import HandcapError, merge_warnings
from handcap.core.files import atomic_output, existing_file, read_toml
from handcap.core.rotations import matrix_from_axis_angle
from handcap.core.transforms import homogeneous

# OpenCV's iterative undistortion stops when the point re-distorts to within
# this many pixels of the input (the EPS test of cvUndistortPointsInternal
# measures the error in pixels), or after this many iterations.
_UNDISTORT_EPS_PX = 1e-11
_UNDISTORT_MAX_ITER = 200


# -- validation of the camera model's own values (the generic checks are handcap.core.checks) --------------
def _distortions(value) -> np.ndarray:
    """Five OpenCV coefficients from 4, 5 or 8 (see :class:`Camera`)."""
    array = check_numbers(value, "distortions")
    if array.ndim == 2 and 1 in array.shape:
        array = array.ravel()
    if array.ndim != 1 or array.shape[0] not in (4, 5, 8):
        raise HandcapError(f"distortions must be 5 values k1 k2 p1 p2 k3 (4 or 8 accepted), "
                           f"got shape {array.shape}")
    check_finite(array, "distortions")
    if array.shape[0] == 8:
        if np.any(array[5:] != 0):
            raise HandcapError(f"distortions has OpenCV's rational terms k4 k5 k6 = {array[5:].tolist()}; "
                               f"handcap's model is k1 k2 p1 p2 k3 only, recalibrate without "
                               f"CALIB_RATIONAL_MODEL")
        array = array[:5]
    elif array.shape[0] == 4:
        array = np.append(array, 0.0)
    array = array.copy()
    array.setflags(write=False)
    return array


def _size(value) -> tuple[int, int]:
    try:
        w, h = value
    except (TypeError, ValueError):
        raise HandcapError(f"size must be [width, height] in pixels, got {value!r}") from None
    out = []
    for n in (w, h):
        whole = isinstance(n, (int, np.integer)) or (isinstance(n, (float, np.floating)) and float(n).is_integer())
        if isinstance(n, (bool, np.bool_)) or not whole or n <= 0:
            raise HandcapError(f"size must be two positive whole numbers [width, height], got {value!r}")
        out.append(int(n))
    return out[0], out[1]


def _matrix(value) -> np.ndarray:
    matrix = check_numbers(value, "matrix")
    if matrix.shape != (3, 3):
        raise HandcapError(f"matrix must be 3x3 [[fx, 0, cx], [0, fy, cy], [0, 0, 1]], got shape {matrix.shape}")
    check_finite(matrix, "matrix")
    if matrix[0, 0] <= 0 or matrix[1, 1] <= 0:
        raise HandcapError(f"matrix focal lengths fx, fy must be positive pixels, got {matrix[0, 0]}, {matrix[1, 1]}")
    if matrix[0, 1] != 0:
        raise HandcapError(f"matrix has skew {matrix[0, 1]} at [0][1]; OpenCV's model has none, it must be 0")
    if matrix[1, 0] != 0 or matrix[2].tolist() != [0.0, 0.0, 1.0]:
        raise HandcapError(f"matrix must be [[fx, 0, cx], [0, fy, cy], [0, 0, 1]], got {matrix.tolist()}")
    return matrix


# -- one camera ------------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class Camera:
    """A calibrated pinhole camera with OpenCV's radial and tangential distortion.

    Parameters
    ----------
    name : str
        Non-empty, unique within a rig.
    size : (int, int)
        Image width and height in pixels.
    matrix : array_like of shape (3, 3)
        Camera matrix ``[[fx, 0, cx], [0, fy, cy], [0, 0, 1]]`` in pixels; no skew.
    distortions : array_like of shape (5,)
        OpenCV's ``k1 k2 p1 p2 k3``. Four values (k1 k2 p1 p2) are read with
        k3 = 0; OpenCV's eight-value rational model is accepted only when its
        k4 = k5 = k6 = 0, where it equals the five-term one. Zero by default.
    rotation : array_like of shape (3,)
        Rodrigues vector (radians) of the world-to-camera rotation.
    translation : array_like of shape (3,)
        World-to-camera translation in metres.

    Raises
    ------
    HandcapError
        If a value has the wrong shape or type, or is not finite.

    Notes
    -----
    Instances are immutable and hold read-only float64 copies of the arrays.
    OpenCV's ``(3, 1)`` and ``(1, 5)`` vectors are accepted as they come.
    """

    name: str
    size: tuple[int, int]
    matrix: np.ndarray
    distortions: np.ndarray = (0.0, 0.0, 0.0, 0.0, 0.0)
    rotation: np.ndarray = (0.0, 0.0, 0.0)
    translation: np.ndarray = (0.0, 0.0, 0.0)

    def __post_init__(self):
        if not isinstance(self.name, str) or not self.name:
            raise HandcapError(f"camera name must be a non-empty string, got {self.name!r}")
        object.__setattr__(self, "size", _size(self.size))
        object.__setattr__(self, "matrix", _matrix(self.matrix))
        object.__setattr__(self, "distortions", _distortions(self.distortions))
        object.__setattr__(self, "rotation", check_vector(self.rotation, 3, "rotation"))
        object.__setattr__(self, "translation", check_vector(self.translation, 3, "translation"))
        rotation_matrix = np.asarray(matrix_from_axis_angle(self.rotation))
        rotation_matrix.setflags(write=False)
        object.__setattr__(self, "_rotation_matrix", rotation_matrix)

    def __eq__(self, other) -> bool:
        if not isinstance(other, Camera):
            return NotImplemented
        return (self.name == other.name and self.size == other.size
                and all(np.array_equal(getattr(self, key), getattr(other, key))
                        for key in ("matrix", "distortions", "rotation", "translation")))

    __hash__ = None

    def __repr__(self) -> str:
        (w, h), (x, y, z) = self.size, self.center
        return (f"Camera({self.name!r}, {w}x{h} px, f={self.matrix[0, 0]:.1f} px, "
                f"center=[{x:.3f}, {y:.3f}, {z:.3f}] m)")

    # -- frames ------------------------------------------------------------------------
    @property
    def rotation_matrix(self) -> np.ndarray:
        """World-to-camera rotation ``R`` (3, 3), read-only."""
        return self._rotation_matrix

    @property
    def center(self) -> np.ndarray:
        """Position of the camera (its optical centre) in the world, metres, shape (3,)."""
        return -self._rotation_matrix.T @ self.translation

    @property
    def world2camera(self) -> np.ndarray:
        """Homogeneous transform (4, 4) from world to camera coordinates."""
        return homogeneous(self._rotation_matrix, self.translation)

    @property
    def camera2world(self) -> np.ndarray:
        """Homogeneous transform (4, 4) from camera to world coordinates."""
        return homogeneous(self._rotation_matrix.T, self.center)

    @property
    def projection(self) -> np.ndarray:
        """Projection matrix ``K [R | t]`` (3, 4) to undistorted pixels."""
        return self.matrix @ self.world2camera[:3]

    # -- points and pixels -------------------------------------------------------------
    def project(self, points):
        """Project world points into the (distorted) image.

        Parameters
        ----------
        points : array_like of shape (..., 3)
            World positions in metres; NaN allowed.

        Returns
        -------
        pixels : ndarray of shape (..., 2)
            Pixel coordinates in the distorted image, NaN for points at or
            behind the camera's centre plane (depth <= 0) or NaN points.
        depth : ndarray of shape (...)
            Distance along the optical axis in metres; negative behind the camera.

        Raises
        ------
        HandcapError
            If ``points`` is not (..., 3).

        Notes
        -----
        This is OpenCV's model as :func:`cv2.projectPoints` evaluates it,
        vectorised: ``x = X / Z``, ``y = Y / Z``, ``r2 = x^2 + y^2``,
        ``x' = x (1 + k1 r2 + k2 r2^2 + k3 r2^3) + 2 p1 x y + p2 (r2 + 2 x^2)``,
        ``y' = y (...) + p1 (r2 + 2 y^2) + 2 p2 x y``, ``u = fx x' + cx``,
        ``v = fy y' + cy``. Like OpenCV it does not detect points so far off
        axis that a strong barrel distortion folds them back into the image.
        """
        camera_points = check_points(points) @ self._rotation_matrix.T + self.translation
        depth = camera_points[..., 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            normalised = camera_points[..., :2] / depth[..., None]
        pixels = self._pixels_from_normalised(self._distort(normalised))
        pixels[~(depth > 0)] = np.nan
        return pixels, depth

    def _distort(self, normalised: np.ndarray) -> np.ndarray:
        k1, k2, p1, p2, k3 = self.distortions
        x, y = normalised[..., 0], normalised[..., 1]
        r2 = x * x + y * y
        radial = 1.0 + r2 * (k1 + r2 * (k2 + r2 * k3))
        xy2 = 2.0 * x * y
        return np.stack([x * radial + p1 * xy2 + p2 * (r2 + 2.0 * x * x),
                         y * radial + p1 * (r2 + 2.0 * y * y) + p2 * xy2], axis=-1)

    def _pixels_from_normalised(self, normalised: np.ndarray) -> np.ndarray:
        return normalised * self.matrix[[0, 1], [0, 1]] + self.matrix[:2, 2]

    def undistort_pixels(self, pixels, *, normalised: bool = False):
        """Remove the lens distortion from pixel coordinates.

        Parameters
        ----------
        pixels : array_like of shape (..., 2)
            Pixel coordinates in the distorted image; NaN allowed.
        normalised : bool
            Return normalised image coordinates ``(X / Z, Y / Z)`` instead of pixels.

        Returns
        -------
        undistorted : ndarray of shape (..., 2)
            Pixels of the ideal pinhole camera with the same ``matrix`` (the ones
            :attr:`projection` maps to), or normalised coordinates; NaN where
            ``pixels`` is.

        Raises
        ------
        HandcapError
            If ``pixels`` is not (..., 2).

        See Also
        --------
        cv2.undistortPoints : the iterative inversion used here, run to
            convergence (the default stops after 5 iterations).
        """
        pixels = check_pixels(pixels)
        coords = self._undistort(pixels.reshape(-1, 2)).reshape(pixels.shape)
        return coords if normalised else self._pixels_from_normalised(coords)

    def _undistort(self, pixels: np.ndarray) -> np.ndarray:
        """Normalised coordinates (N, 2) of distorted pixels (N, 2)."""
        out = np.full(pixels.shape, np.nan)
        finite = np.isfinite(pixels).all(axis=1)
        if not finite.any():
            return out
        src = np.ascontiguousarray(pixels[finite].reshape(-1, 1, 2))
        criteria = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, _UNDISTORT_MAX_ITER, _UNDISTORT_EPS_PX)
        if hasattr(cv2, "undistortPointsIter"):  # OpenCV 4.x
            dst = cv2.undistortPointsIter(src, self.matrix, self.distortions, None, None, criteria)
        else:  # OpenCV 5 took the criteria into undistortPoints
            dst = cv2.undistortPoints(src, self.matrix, self.distortions, criteria=criteria)
        out[finite] = dst.reshape(-1, 2)
        return out

    def rays(self, pixels):
        """Viewing rays through pixels of the distorted image, in the world.

        Parameters
        ----------
        pixels : array_like of shape (..., 2)
            Pixel coordinates in the distorted image; NaN allowed.

        Returns
        -------
        origins : ndarray of shape (..., 3)
            The camera centre in metres, repeated.
        directions : ndarray of shape (..., 3)
            Unit vectors in the world pointing out of the camera through each
            pixel; NaN where ``pixels`` is.
        """
        coords = self.undistort_pixels(pixels, normalised=True)
        directions = np.concatenate([coords, np.ones(coords.shape[:-1] + (1,))], axis=-1)
        directions /= np.linalg.norm(directions, axis=-1, keepdims=True)
        directions = directions @ self._rotation_matrix  # R.T @ d for each row
        origins = np.broadcast_to(self.center, directions.shape).copy()
        return origins, directions

    def in_image(self, pixels) -> np.ndarray:
        """Whether pixels fall on the sensor.

        Parameters
        ----------
        pixels : array_like of shape (..., 2)

        Returns
        -------
        inside : ndarray of bool, shape (...)
            True where ``-0.5 <= u < w - 0.5`` and ``-0.5 <= v < h - 0.5``;
            False for NaN.
        """
        pixels = check_pixels(pixels)
        w, h = self.size
        u, v = pixels[..., 0], pixels[..., 1]
        return (u >= -0.5) & (u < w - 0.5) & (v >= -0.5) & (v < h - 0.5)


# -- a rig of cameras ------------------------------------------------------------------
@dataclass(frozen=True, eq=False)
class CameraRig:
    """Ordered, named, calibrated cameras sharing one world frame.

    Parameters
    ----------
    cameras : iterable of Camera
        At least one; names unique.
    warnings : tuple of str
        One-line warnings about the rig as read (a unit guessed from the camera
        positions); empty for a rig nobody doubted.

    Raises
    ------
    HandcapError
        If there is no camera, an item is not a :class:`Camera`, or names repeat.

    Examples
    --------
    >>> rig = CameraRig.load("rig.toml")            # doctest: +SKIP
    >>> pixels, depths = rig.project(points)        # (C, N, 2), (C, N)
    >>> rig["cam_3"].center                         # doctest: +SKIP
    """

    cameras: tuple[Camera, ...]
    warnings: tuple[str, ...] = ()

    def __post_init__(self):
        try:
            cameras = tuple(self.cameras)
        except TypeError:
            raise HandcapError(f"cameras must be a sequence of Camera, got {type(self.cameras).__name__}") from None
        if not cameras:
            raise HandcapError("a camera rig needs at least one camera")
        for camera in cameras:
            if not isinstance(camera, Camera):
                raise HandcapError(f"cameras must be Camera objects, got {type(camera).__name__}")
        names = [camera.name for camera in cameras]
        duplicates = sorted({n for n in names if names.count(n) > 1})
        if duplicates:
            raise HandcapError(f"camera names must be unique, repeated: {', '.join(duplicates)}")
        object.__setattr__(self, "cameras", cameras)
        object.__setattr__(self, "warnings", merge_warnings(self.warnings))

    def with_warnings(self, *messages) -> CameraRig:
        """The same rig with ``messages`` (one-line strings) added to its warnings."""
        return CameraRig(self.cameras, merge_warnings(self.warnings, messages))

    def scaled(self, factor: float) -> CameraRig:
        """The rig in a world scaled by ``factor`` (translations times ``factor``, e.g. 0.001 for mm to m).

        Rotations and intrinsics are unchanged; camera centres scale with the world.
        """
        factor = float(factor)
        if not np.isfinite(factor) or factor <= 0:
            raise HandcapError(f"a rig is scaled by a positive finite factor, got {factor}")
        return CameraRig([Camera(c.name, c.size, c.matrix, c.distortions, c.rotation, c.translation * factor)
                          for c in self.cameras], self.warnings)

    def __eq__(self, other) -> bool:
        if not isinstance(other, CameraRig):
            return NotImplemented
        return self.cameras == other.cameras

    __hash__ = None

    def __repr__(self) -> str:
        return f"CameraRig({len(self)} cameras: {', '.join(self.names)})"

    # -- access ------------------------------------------------------------------------
    def __len__(self) -> int:
        return len(self.cameras)

    def __iter__(self) -> Iterator[Camera]:
        return iter(self.cameras)

    def __getitem__(self, key: int | str) -> Camera:
        """Camera by position (negative counts from the end) or by name."""
        if isinstance(key, str):
            return self.cameras[self.index(key)]
        try:
            i = operator.index(key)
        except TypeError:
            raise HandcapError(f"cameras are looked up by index or name, got {key!r}") from None
        if not -len(self) <= i < len(self):
            raise HandcapError(f"camera index {i} is out of range for a rig of {len(self)} cameras")
        return self.cameras[i]

    def index(self, name: str) -> int:
        """Position of the camera called ``name``.

        Raises
        ------
        HandcapError
            If no camera has that name; the message lists the names.
        """
        names = self.names
        if name not in names:
            raise HandcapError(f"no camera named {name!r}; the rig has {', '.join(names)}")
        return names.index(name)

    @property
    def names(self) -> tuple[str, ...]:
        """Camera names in rig order, length C."""
        return tuple(camera.name for camera in self.cameras)

    @property
    def sizes(self) -> np.ndarray:
        """Image ``(width, height)`` of each camera in pixels, int array (C, 2)."""
        return np.array([camera.size for camera in self.cameras], dtype=np.int64)

    @property
    def projections(self) -> np.ndarray:
        """Projection matrices ``K [R | t]`` (C, 3, 4) to undistorted pixels."""
        return np.stack([camera.projection for camera in self.cameras])

    @property
    def centers(self) -> np.ndarray:
        """Camera positions in the world (C, 3), metres."""
        return np.stack([camera.center for camera in self.cameras])

    # -- verbs -------------------------------------------------------------------------
    def project(self, points):
        """Project world points into every camera.

        Parameters
        ----------
        points : array_like of shape (N, 3)
            World positions in metres, NaN allowed (any (..., 3) works too).

        Returns
        -------
        pixels : ndarray of shape (C, N, 2)
            Pixels in each distorted image, NaN behind camera c.
        depths : ndarray of shape (C, N)
            Metres along each optical axis, negative behind the camera.

        See Also
        --------
        Camera.project
        """
        points = check_points(points)
        results = [camera.project(points) for camera in self.cameras]
        return np.stack([r[0] for r in results]), np.stack([r[1] for r in results])

    def undistort_pixels(self, pixels, *, normalised: bool = False) -> np.ndarray:
        """Undistort each camera's pixels (C, N, 2); see :meth:`Camera.undistort_pixels`."""
        pixels = self._per_camera(pixels)
        return np.stack([camera.undistort_pixels(p, normalised=normalised)
                         for camera, p in zip(self.cameras, pixels)])

    def in_image(self, pixels) -> np.ndarray:
        """Whether each camera's pixels (C, N, 2) fall on its sensor, bool (C, N).

        See Also
        --------
        Camera.in_image : the sensor's extent.
        """
        pixels = self._per_camera(pixels)
        return np.stack([camera.in_image(p) for camera, p in zip(self.cameras, pixels)])

    def _per_camera(self, pixels) -> np.ndarray:
        pixels = check_pixels(pixels)
        if pixels.ndim < 2 or pixels.shape[0] != len(self):
            raise HandcapError(f"pixels must have shape (C, N, 2) with C = {len(self)} cameras, got {pixels.shape}")
        return pixels

    # -- files -------------------------------------------------------------------------
    def save(self, path) -> None:
        """Write the rig to ``path`` (``.toml``, anipose style), atomically.

        See Also
        --------
        write_cameras_toml
        """
        check_rig_suffix(path)
        write_cameras_toml(self, path)

    @classmethod
    def load(cls, path) -> CameraRig:
        """Read a rig from ``path`` (``.toml``, anipose style).

        See Also
        --------
        read_cameras_toml
        """
        check_rig_suffix(path)
        return read_cameras_toml(path)


def check_rig_suffix(path) -> None:
    """Refuse a rig file name that is not ``.toml`` (handcap's own rig files are anipose-style TOML)."""
    suffix = Path(path).suffix.lower()
    if suffix != ".toml":
        raise HandcapError(f"{path}: camera files are anipose-style .toml, got '{suffix or 'no extension'}'")


# -- anipose-style TOML rig files (handcap.io.cameras names them for users) ----------------------------------

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
        if not all_numbers(table[key]):
            raise HandcapError(f"{where} {key} must be an array of numbers, got {table[key]!r}")
    try:
        return Camera(**{key: table[key] for key in CAMERA_KEYS})
    except HandcapError as err:
        raise HandcapError(f"{where} {err}") from None


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


__all__ = ["CAMERA_KEYS", "Camera", "CameraRig", "check_rig_suffix", "read_cameras_toml", "read_cameras_warnings",
           "write_cameras_toml"]
