"""An ordered set of calibrated cameras sharing one world frame, ``CameraRig``, read from and written to files.

Rigs are stored as anipose-style TOML (:func:`read_cameras_toml`,
:func:`write_cameras_toml`, ``CameraRig.save`` and ``CameraRig.load``); the
tables of that format are :mod:`handcap.core.camera_toml`, which
:mod:`handcap.io.cameras` describes for users beside the other formats. One
camera and the conventions of its frames and pixels are :mod:`handcap.core.camera`.
"""

from __future__ import annotations

import operator
from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np

from handcap.core.camera import Camera
from handcap.core.camera_toml import check_rig_suffix, read_camera_tables, write_camera_tables
from handcap.core.checks import check_pixels, check_points
from handcap.core.errors import HandcapError, merge_warnings


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
        """Undistort each camera's pixels (see :meth:`Camera.undistort_pixels`).

        Parameters
        ----------
        pixels : array_like (C, N, 2)
            Pixels in each camera's distorted image.
        normalised : bool
            Return normalised image coordinates (x/z, y/z) instead of pixels of the undistorted image.

        Returns
        -------
        ndarray (C, N, 2)
        """
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
    path, cameras, warnings = read_camera_tables(path)
    try:
        return CameraRig(cameras, warnings)
    except HandcapError as err:
        raise HandcapError(f"{path}: {err}") from None


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
    write_camera_tables(rig.cameras, path, warnings=merge_warnings(rig.warnings, warnings))


__all__ = ["CameraRig", "read_cameras_toml", "write_cameras_toml"]
