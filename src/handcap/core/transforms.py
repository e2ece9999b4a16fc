"""Homogeneous 4x4 transforms (rigid poses) and averages of rotations, batched over leading axes.

A transform ``T`` (..., 4, 4) maps ``x`` to ``R @ x + t``; metres and radians.
"""

from __future__ import annotations

import numpy as np


def homogeneous(rotation: np.ndarray, translation: np.ndarray) -> np.ndarray:
    """Transforms (..., 4, 4) from rotations (..., 3, 3) and translations (..., 3), metres.

    Parameters
    ----------
    rotation : array_like of shape (..., 3, 3)
        Rotation matrices.
    translation : array_like of shape (..., 3)
        Translations, metres; broadcast to the rotations' leading shape.

    Returns
    -------
    ndarray of shape (..., 4, 4)
        Float64, last row ``[0, 0, 0, 1]``.
    """
    out = np.zeros(np.shape(rotation)[:-2] + (4, 4))
    out[..., :3, :3] = rotation
    out[..., :3, 3] = translation
    out[..., 3, 3] = 1.0
    return out


def invert_homogeneous(transform: np.ndarray) -> np.ndarray:
    """Inverses (..., 4, 4) of rigid transforms (..., 4, 4), without a general matrix inverse."""
    rotation = np.swapaxes(transform[..., :3, :3], -1, -2)
    return homogeneous(rotation, -np.einsum("...ij,...j->...i", rotation, transform[..., :3, 3]))


def mean_rotation(rotations: np.ndarray) -> np.ndarray:
    """Chordal L2 mean (3, 3) of rotations (n, 3, 3)."""
    u, _, vt = np.linalg.svd(rotations.sum(axis=0))
    fix = np.diag([1.0, 1.0, np.sign(np.linalg.det(u @ vt))])
    return u @ fix @ vt


def robust_mean_pose(transforms: np.ndarray) -> np.ndarray:
    """A pose (4, 4) summarising many estimates (n, 4, 4) of it, ignoring the wild ones.

    The medoid rotation (least total angle to the others) and the per-axis
    median translation pick the inliers: within 3 times the median deviation
    (at least 2 degrees and 2 cm) of both; the result is their mean.
    """
    rotations, translations = transforms[:, :3, :3], transforms[:, :3, 3]
    relative = np.einsum("aji,bjk->abik", rotations, rotations)
    cos = np.clip((np.trace(relative, axis1=-2, axis2=-1) - 1.0) / 2.0, -1.0, 1.0)
    angles = np.arccos(cos)
    medoid = rotations[np.argmin(angles.sum(axis=1))]
    angle = angles[np.argmin(angles.sum(axis=1))]
    distance = np.linalg.norm(translations - np.median(translations, axis=0), axis=1)
    keep = (angle <= max(3.0 * np.median(angle), np.radians(2.0))) & (distance <= max(3.0 * np.median(distance), 0.02))
    if not keep.any():
        return homogeneous(medoid, np.median(translations, axis=0))
    return homogeneous(mean_rotation(rotations[keep]), translations[keep].mean(axis=0))


__all__ = ["homogeneous", "invert_homogeneous", "mean_rotation", "robust_mean_pose"]
