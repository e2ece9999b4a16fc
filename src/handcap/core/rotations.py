"""Rotation conversions shared by numpy and torch code.

Functions named ``<target>_from_<source>`` accept batches ``(..., 3)`` or
``(..., 3, 3)``. Those written with the array-API namespace
(:func:`array_api_compat.array_namespace`) run unchanged on numpy arrays and on
torch tensors, and are differentiable in torch; the inverses that need care
near 180 degrees use :class:`scipy.spatial.transform.Rotation` (numpy only).

Conventions (written down once)
-------------------------------
* Rotation matrices act on column vectors: ``x_world = R @ x_local``.
* Axis-angle vectors are ``angle * unit_axis`` in radians (MANO's layout).
* ``matrix_from_euler_zyx(bend, spread, twist) = Rz(bend) @ Ry(spread) @ Rx(twist)``:
  intrinsic z-y'-x'' angles, i.e. the first angle turns about the proximal
  (fixed) z axis, the last about the moved x axis. This is the joint coordinate
  system of Grood & Suntay (1983) recommended for the hand by the ISB
  (Wu et al. 2005, doi:10.1016/j.jbiomech.2004.05.042).
"""

from __future__ import annotations

import numpy as np
from array_api_compat import array_namespace
from scipy.spatial.transform import Rotation

# Below this squared angle the Taylor series is used (exact to float64 there).
_SMALL_SQ = 1e-12


def matrix_from_axis_angle(axis_angle):
    """Rotation matrices from axis-angle vectors (Rodrigues' formula).

    Parameters
    ----------
    axis_angle : array of shape (..., 3)
        Radians; numpy array or torch tensor.

    Returns
    -------
    matrices : array of shape (..., 3, 3)
    """
    xp = array_namespace(axis_angle)
    x, y, z = axis_angle[..., 0], axis_angle[..., 1], axis_angle[..., 2]
    theta_sq = x * x + y * y + z * z
    small = theta_sq < _SMALL_SQ
    # Gradient-safe: evaluate sin/cos only on a value that is never zero.
    theta = xp.sqrt(xp.where(small, xp.ones_like(theta_sq), theta_sq))
    a = xp.where(small, 1.0 - theta_sq / 6.0, xp.sin(theta) / theta)
    b = xp.where(small, 0.5 - theta_sq / 24.0, (1.0 - xp.cos(theta)) / (theta * theta))
    c = 1.0 - b * theta_sq
    rows = [
        [c + b * x * x, b * x * y - a * z, b * x * z + a * y],
        [b * x * y + a * z, c + b * y * y, b * y * z - a * x],
        [b * x * z - a * y, b * y * z + a * x, c + b * z * z],
    ]
    return xp.stack([xp.stack(r, axis=-1) for r in rows], axis=-2)


def axis_angle_from_matrix(matrices) -> np.ndarray:
    """Axis-angle vectors (..., 3) from rotation matrices (..., 3, 3), numpy only.

    The angle is in [0, pi]; robust near pi (via scipy's quaternion path).
    """
    matrices = np.asarray(matrices, dtype=np.float64)
    flat = matrices.reshape(-1, 3, 3)
    if flat.shape[0] == 0:
        return np.zeros(matrices.shape[:-2] + (3,))
    return Rotation.from_matrix(flat).as_rotvec().reshape(matrices.shape[:-2] + (3,))


def _axis_rotation(angle, axis: int):
    xp = array_namespace(angle)
    c, s = xp.cos(angle), xp.sin(angle)
    one, zero = xp.ones_like(angle), xp.zeros_like(angle)
    if axis == 0:
        rows = [[one, zero, zero], [zero, c, -s], [zero, s, c]]
    elif axis == 1:
        rows = [[c, zero, s], [zero, one, zero], [-s, zero, c]]
    else:
        rows = [[c, -s, zero], [s, c, zero], [zero, zero, one]]
    return xp.stack([xp.stack(r, axis=-1) for r in rows], axis=-2)


def matrix_from_euler_zyx(bend, spread, twist):
    """``Rz(bend) @ Ry(spread) @ Rx(twist)`` for arrays of angles (radians), shape (..., 3, 3).

    Works on numpy and torch arrays alike (through the array namespace).

    Parameters
    ----------
    bend : array of shape (...)
        Angle about z, radians.
    spread : array of shape (...)
        Angle about y, radians.
    twist : array of shape (...)
        Angle about x, radians.

    Returns
    -------
    array of shape (..., 3, 3)
        Rotation matrices, of the angles' array type; the three angle shapes are broadcast together.
    """
    xp = array_namespace(bend, spread, twist)
    return xp.matmul(xp.matmul(_axis_rotation(bend, 2), _axis_rotation(spread, 1)),
                     _axis_rotation(twist, 0))


def euler_zyx_from_matrix(matrices) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Inverse of :func:`matrix_from_euler_zyx` for |spread| < pi/2 (numpy).

    Returns
    -------
    bend, spread, twist : ndarrays of shape (...)
    """
    m = np.asarray(matrices, dtype=np.float64)
    spread = np.arcsin(np.clip(-m[..., 2, 0], -1.0, 1.0))
    bend = np.arctan2(m[..., 1, 0], m[..., 0, 0])
    twist = np.arctan2(m[..., 2, 1], m[..., 2, 2])
    return bend, spread, twist


def rotation_angle(matrices) -> np.ndarray:
    """Angle (radians, in [0, pi]) of rotation matrices (..., 3, 3)."""
    m = np.asarray(matrices, dtype=np.float64)
    return np.linalg.norm(axis_angle_from_matrix(m), axis=-1)
