"""One calibrated pinhole camera, ``Camera``: its frames, and its lens model from world points to pixels and back.

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

The ordered set of cameras is :class:`handcap.core.camera_rig.CameraRig`; its
anipose-style TOML files are :mod:`handcap.core.camera_toml`.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from handcap.core.checks import check_finite, check_numbers, check_pixels, check_points, check_vector
from handcap.core.errors import HandcapError
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


__all__ = ["Camera"]
