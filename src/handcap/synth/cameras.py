"""Synthetic camera rigs: industrial cameras on a capture cage, as in DexterCap.

DexterCap (see ``papers/dextercap-coded-marker-hand-object-capture.md``, Sec. 3.1.1
and 5) records with 13 synchronised 2448 x 2048 industrial cameras mounted on a
2 x 1 x 2 m cage around the hand. :func:`cage_rig` builds a rig like it, to
synthesise detections and test triangulation against known geometry.
"""

from __future__ import annotations

import operator

import numpy as np

from handcap.core.cameras import Camera, CameraRig
from handcap.core.errors import HandcapError
from handcap.core.checks import check_positive
from handcap.core.rotations import axis_angle_from_matrix

# Diameter of the work volume each camera frames by default, metres.
WORK_VOLUME_M = 0.5
# Fraction of the short image side the work volume fills by default (the rest
# keeps it in view despite the aim jitter, principal point offset and distortion).
_FILL = 0.95
_MOUNT_JITTER_M = 0.05           # cameras slide this far along their post or rail
_AIM_JITTER_RAD = np.deg2rad(1.0)  # largest angle between the optical axis and the target
_ROLL_JITTER_RAD = np.deg2rad(3.0)
_ASPECT_JITTER = 1e-3            # fy = fx (1 +- this)
_CENTER_JITTER = 0.01            # principal point within this fraction of the size of the centre
# Each distortion coefficient is distortion_scale times this at most (k1 k2 p1 p2 k3).
_DISTORTION_SPREAD = np.array([1.0, 0.5, 0.05, 0.05, 0.1])

# Mounting places on the cage frame, counterclockwise seen from above starting
# at +x: edge mid-points (even) and corners (odd), as multiples of the half sizes.
_SLOTS = np.array([[1, 0], [1, 1], [0, 1], [-1, 1], [-1, 0], [-1, -1], [0, -1], [1, -1]], dtype=np.float64)
_TOP, _HIGH, _MID, _LOW = 1.0, 0.8, 0.5, 0.2  # mounting heights, fractions of the cage height
# (slot, height) in the order cameras are added. Any prefix is spread out: two
# cameras face each other, one high and one low; four cover every quadrant; the
# default twelve have each corner high and low plus the top rail's mid-points.
_MOUNTS = (
    [(1, _HIGH), (5, _LOW), (3, _HIGH), (7, _LOW)]
    + [(1, _LOW), (5, _HIGH), (3, _LOW), (7, _HIGH)]
    + [(2, _TOP), (6, _TOP), (0, _TOP), (4, _TOP)]
    + [(0, _LOW), (4, _LOW), (2, _LOW), (6, _LOW)]
    + [(1, _MID), (5, _MID), (3, _MID), (7, _MID)]
    + [(0, _MID), (4, _MID), (2, _MID), (6, _MID)]
)
MAX_CAMERAS = len(_MOUNTS)


def cage_rig(n_cameras: int = 12, *, cage_size=(2.0, 1.0, 2.0), target=(0.0, 0.0, 1.0),
             resolution=(2448, 2048), focal_px=None, distortion_scale: float = 0.02,
             seed: int = 0) -> CameraRig:
    """A synthetic rig of cameras on a capture cage, all looking at the work volume.

    The world has z up and its origin on the floor at the cage's centre; the
    cage spans ``[-X/2, X/2] x [-Y/2, Y/2] x [0, Z]`` for ``cage_size = (X, Y, Z)``.
    Cameras sit on the cage's frame: on the four corner posts at 20 % and 80 %
    of its height, then at the mid-points of the top rail's edges, then (past
    twelve) mid-points of lower rails and mid-height posts. Each slides a few
    centimetres along its post or rail and looks at ``target`` within 1 degree,
    with a roll of up to 3 degrees. The principal point lies within 1 % of the
    image centre, ``fy`` within 0.1 % of ``fx``, and the lens has small random
    radial and tangential distortion.

    Parameters
    ----------
    n_cameras : int
        1 to 24. Cameras are added in a fixed order, so a smaller rig is the
        first cameras of a larger one with the same seed.
    cage_size : (float, float, float)
        Width (x), depth (y) and height (z) of the cage in metres.
    target : (float, float, float)
        Centre of the work volume in metres, strictly inside the cage.
    resolution : (int, int)
        Image width and height in pixels.
    focal_px : float, optional
        Focal length in pixels for every camera. By default each camera gets
        the one that fits a 0.5 m sphere around ``target`` into 95 % of the
        short side of its image (as if each had its own lens).
    distortion_scale : float
        Largest |k1|; |k2|, |p1|, |p2|, |k3| are at most 0.5, 0.05, 0.05, 0.1
        times it. 0 gives ideal pinhole cameras.
    seed : int
        Seed of :func:`numpy.random.default_rng`. Same seed, same rig.

    Returns
    -------
    CameraRig
        Cameras named ``cam_0``, ``cam_1``, ...

    Raises
    ------
    HandcapError
        For an argument out of range, or, when ``focal_px`` is computed, a
        camera too close to ``target`` to frame the work volume.
    """
    n_cameras = _count(n_cameras)
    cage = _triple(cage_size, "cage_size")
    if np.any(cage <= 0):
        raise HandcapError(f"cage_size must be positive metres (x, y, z), got {cage.tolist()}")
    target = _triple(target, "target")
    half = np.array([cage[0] / 2, cage[1] / 2])
    if np.any(np.abs(target[:2]) >= half) or not 0 < target[2] < cage[2]:
        raise HandcapError(f"target {target.tolist()} must lie inside the cage "
                           f"[-{half[0]:g}, {half[0]:g}] x [-{half[1]:g}, {half[1]:g}] x [0, {cage[2]:g}] m")
    width, height = _resolution(resolution)
    if focal_px is not None:
        focal_px = check_positive(focal_px, "focal_px")
    try:
        scale = float(distortion_scale)
    except (TypeError, ValueError):
        scale = np.nan
    if not np.isfinite(scale) or scale < 0:
        raise HandcapError(f"distortion_scale must be a finite number >= 0, got {distortion_scale!r}")

    # One draw of uniforms in [-1, 1), one row per camera; the columns are
    # mount slide, aim angle and azimuth, roll, aspect, cx, cy, then 5 distortions.
    draws = np.random.default_rng(seed).uniform(-1.0, 1.0, size=(n_cameras, 12))
    cameras = []
    for i, ((slot, level), u) in enumerate(zip(_MOUNTS[:n_cameras], draws)):
        center = _mount_position(slot, level, u[0], half, cage[2])
        rotation = _look_at(center, target, aim=(u[1], u[2]), roll=u[3])
        if focal_px is None:
            fx = _framing_focal(np.linalg.norm(target - center), min(width, height), i)
        else:
            fx = focal_px
        matrix = np.array([[fx, 0.0, (width - 1) / 2 + _CENTER_JITTER * width * u[5]],
                           [0.0, fx * (1 + _ASPECT_JITTER * u[4]), (height - 1) / 2 + _CENTER_JITTER * height * u[6]],
                           [0.0, 0.0, 1.0]])
        cameras.append(Camera(
            name=f"cam_{i}",
            size=(width, height),
            matrix=matrix,
            distortions=scale * _DISTORTION_SPREAD * u[7:12],
            rotation=axis_angle_from_matrix(rotation),
            translation=-rotation @ center,
        ))
    return CameraRig(cameras)


def _mount_position(slot: int, level: float, slide: float, half: np.ndarray, cage_height: float) -> np.ndarray:
    """World position of a mount; corners slide along their post, mid-points along their rail."""
    xy = _SLOTS[slot] * half
    z = level * cage_height
    if slot % 2:  # corner post: vertical
        z = np.clip(z + _MOUNT_JITTER_M * slide, 0.0, cage_height)
    else:  # rail: along x for the mid-points of the y = +-Y/2 edges, along y otherwise
        axis = 0 if _SLOTS[slot][0] == 0 else 1
        xy[axis] = np.clip(xy[axis] + _MOUNT_JITTER_M * slide, -half[axis], half[axis])
    return np.array([xy[0], xy[1], z])


def _look_at(center, target, *, aim, roll) -> np.ndarray:
    """World-to-camera rotation (3, 3) looking from ``center`` near ``target``, image up along +z.

    ``aim`` and ``roll`` are uniforms in [-1, 1): the optical axis is tilted
    off the target by up to ``_AIM_JITTER_RAD`` (uniformly over that disc of
    directions) and turned about itself by up to ``_ROLL_JITTER_RAD``.
    """
    forward = (target - center) / np.linalg.norm(target - center)
    right = np.cross(forward, [0.0, 0.0, 1.0])
    right /= np.linalg.norm(right)  # cameras sit on the cage's sides, never straight above
    down = np.cross(forward, right)
    tilt = _AIM_JITTER_RAD * np.sqrt((aim[0] + 1) / 2)
    azimuth = np.pi * aim[1]
    sideways = np.cos(azimuth) * right + np.sin(azimuth) * down
    forward = np.cos(tilt) * forward + np.sin(tilt) * sideways
    right = np.cross(forward, [0.0, 0.0, 1.0])
    right /= np.linalg.norm(right)
    down = np.cross(forward, right)
    angle = _ROLL_JITTER_RAD * roll
    right, down = np.cos(angle) * right + np.sin(angle) * down, np.cos(angle) * down - np.sin(angle) * right
    # Rows are the camera's x (right), y (down), z (forward) axes in the world.
    return np.stack([right, down, forward])


def _framing_focal(distance: float, short_side: int, index: int) -> float:
    """Focal length (px) fitting a WORK_VOLUME_M sphere, seen from ``distance``, in the short side."""
    radius = WORK_VOLUME_M / 2
    if distance <= 1.5 * radius:
        raise HandcapError(f"camera cam_{index} is {distance:.3f} m from the target, too close to frame "
                           f"a {WORK_VOLUME_M} m volume; move the target away from the cage's frame or give focal_px")
    # The sphere subtends a half-angle asin(r / d); keep it in view when the aim is off by the jitter.
    half_angle = np.arcsin(radius / distance) + _AIM_JITTER_RAD
    return float(_FILL * (short_side / 2) / np.tan(half_angle))


def _count(n_cameras) -> int:
    try:
        if isinstance(n_cameras, bool):
            raise TypeError
        n = operator.index(n_cameras)
    except TypeError:
        raise HandcapError(f"n_cameras must be a whole number, got {n_cameras!r}") from None
    if not 1 <= n <= MAX_CAMERAS:
        raise HandcapError(f"n_cameras must be between 1 and {MAX_CAMERAS}, got {n}")
    return n


def _triple(value, what: str) -> np.ndarray:
    try:
        array = np.array(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise HandcapError(f"{what} must be three numbers in metres, got {value!r}") from None
    if array.shape != (3,) or not np.isfinite(array).all():
        raise HandcapError(f"{what} must be three finite numbers in metres, got {value!r}")
    return array


def _resolution(value) -> tuple[int, int]:
    try:
        width, height = (operator.index(v) for v in value)
    except (TypeError, ValueError):
        raise HandcapError(f"resolution must be two whole numbers (width, height), got {value!r}") from None
    if width <= 0 or height <= 0:
        raise HandcapError(f"resolution must be positive pixels (width, height), got {value!r}")
    return width, height


__all__ = ["MAX_CAMERAS", "WORK_VOLUME_M", "cage_rig"]
