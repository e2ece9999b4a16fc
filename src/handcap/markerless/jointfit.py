"""Eq. 2 of single-video capture: the hand model's pose and shape, and the camera poses, from the pixels.

The joint fit of :mod:`handcap.markerless.sfm` (see there): the reprojection
error of the model's keypoints plus a learned constant offset of each, under a
Cauchy loss whose scale falls in stages, with the solver's anatomical priors,
a shape prior and the palm size held to the two-stage structure's. Solved by
scipy's ``least_squares`` with a sparse Jacobian whose forward differences are
all taken in one batched pass of the hand model and the projections
(:func:`~handcap.markerless.numdiff.sparse_differences`).
"""

from __future__ import annotations

import numpy as np
from scipy.sparse import lil_matrix

from handcap.markerless.fit import ROBUST_SCALE as KEYPOINT_ROBUST_SCALE
from handcap.markerless.joint_model import KeypointModel
from handcap.markerless.keypoints import PALM
from handcap.markerless.sfm import ROBUST_PX, VideoStructure, graduated_fit, palm_size, project_points, video_structure
from handcap.solve.lm import Priors, prior_terms

#: Weight of the shape prior of eq. 2, pixels per shape unit.
SHAPE_WEIGHT = 3.0
#: Prior standard deviation of a keypoint's constant offset from its model joint in eq. 2, metres (where a
#: detector puts a joint is not its centre of rotation: 2-3 mm on each axis).
OFFSET_SIGMA = 0.003
#: Pixels per relative error of the keypoints' palm size against the two-stage structure's (the template's):
#: with offsets the overall size is no longer held by the first shape value, and the scale of the whole scene
#: drifted by 5-8 %; quadratic (outside the robust loss), so it holds.
OFFSET_SIZE_WEIGHT = 1000.0


def joint_fit(pixels, matrix, hand, structure: VideoStructure, phi, betas, rotation, translation, *,
              robust_px: float = ROBUST_PX, fit_scale: bool = False, priors: Priors | None = None,
              max_nfev: int = 40, offsets: bool = True):
    """Eq. 2: hand pose, shape and camera poses from the reprojection error of the model's keypoints.

    Parameters
    ----------
    pixels : ndarray (T, 21, 2)
        Undistorted pixels, NaN where not given.
    matrix : ndarray (3, 3)
    hand : HandModel
    structure : VideoStructure
        The two-stage result: which frames are placed, and their start.
    phi : ndarray (27,)
        Starting pose, radians.
    betas : ndarray (10,)
        Starting shape.
    rotation, translation : ndarray (T, 3)
        Starting camera-from-hand poses of the model's frame (NaN for frames not placed).
    robust_px : float
    fit_scale : bool
        Fit the first shape value (overall size) too; off by default, as one camera cannot see it.
    priors : Priors, optional
        The anatomical priors of :func:`handcap.solve.lm.prior_terms` (default: the solver's).
    max_nfev : int
    offsets : bool
        Learn each keypoint's constant offset from its model joint (hand frame, a Gaussian prior of
        :data:`OFFSET_SIGMA`): the hand is still, so the offset is the same in every frame.

    Returns
    -------
    phi : ndarray (27,)
    betas : ndarray (10,)
    structure : VideoStructure
        The model's keypoints (plus the learned offsets) and the camera poses.
    """
    frames = np.flatnonzero(np.isfinite(rotation).all(axis=1))
    obs = pixels[frames]
    seen = np.isfinite(obs).all(axis=2)
    t_idx, k_idx = np.nonzero(seen)
    shape_free = np.arange(10) if fit_scale else np.arange(1, 10)
    n_shape = len(shape_free)
    n_off = 63 if offsets else 0
    n_head = 27 + n_shape + n_off

    models = {}  # the keypoint model of each shape, while the shapes seen stay few (a derivative's steps)

    def model_points(p):
        """Keypoints (B, 21, 3) and shapes (B, 10) of parameter vectors p (B, n)."""
        b = np.array(np.broadcast_to(np.asarray(betas, dtype=np.float64), (len(p), 10)))
        b[:, shape_free] = p[:, 27:27 + n_shape]
        x = np.empty((len(p), 21, 3))
        keys = [row.tobytes() for row in b]
        for key in dict.fromkeys(keys):
            if key not in models and len(models) > 2 * n_shape:
                models.clear()
            rows = [i for i, k in enumerate(keys) if k == key]
            model = models.setdefault(key, KeypointModel(hand, b[rows[0]]))
            x[rows] = model.positions(np.zeros((len(rows), 3)), np.broadcast_to(np.eye(3), (len(rows), 3, 3)),
                                      p[rows, :27])
        return x + p[:, 27 + n_shape:n_head].reshape(-1, 21, 3) if offsets else x, b

    def batched(p):
        """Residuals (B, m) of parameter vectors p (B, n)."""
        x, b = model_points(p)
        poses = p[:, n_head:].reshape(-1, 6)
        points = np.repeat(x, len(frames), axis=0)
        proj = project_points(matrix, poses[:, :3], poses[:, 3:], points).reshape(len(p), len(frames), 21, 2)
        r = (proj - np.nan_to_num(obs))[:, t_idx, k_idx].reshape(len(p), -1)
        prior = prior_terms(p[:, :27], priors, np.zeros((len(p), 27), bool))[0]
        parts = [r, prior_scale * prior, SHAPE_WEIGHT * b[:, shape_free]]
        if offsets:
            parts += [robust_px / OFFSET_SIGMA * p[:, 27 + n_shape:n_head],
                      OFFSET_SIZE_WEIGHT * (palm_size(x) / palm0 - 1.0)[:, None]]
        return np.concatenate(parts, axis=1)

    def residual(p):
        return batched(p[None])[0]

    priors = Priors() if priors is None else priors
    no_hold = np.zeros((1, 27), bool)
    palm0 = palm_size(structure.points)
    # The solver's anatomical priors (limits, DIP-PIP coupling, a weak pull to the relaxed hand), weighed
    # against the pixels as the two-stage fit weighs them against 3D keypoints that average every frame:
    # pixels per metre at the two robust scales, times the square root of the frames.
    prior_scale = robust_px / KEYPOINT_ROBUST_SCALE * np.sqrt(len(frames))
    n_prior = prior_terms(np.zeros((1, 27)), priors, no_hold)[0].shape[1]
    n_obs = 2 * len(t_idx)
    sparsity = lil_matrix((n_obs + n_prior + n_shape + n_off + (1 if offsets else 0), n_head + 6 * len(frames)),
                          dtype=int)
    sparsity[:n_obs, :27 + n_shape] = 1
    row = np.arange(len(t_idx))
    for a in range(2):
        for c in range(6):
            sparsity[2 * row + a, n_head + 6 * t_idx + c] = 1
        if offsets:
            for c in range(3):
                sparsity[2 * row + a, 27 + n_shape + 3 * k_idx + c] = 1
    sparsity[n_obs:n_obs + n_prior, :27] = 1
    sparsity[n_obs + n_prior + np.arange(n_shape), 27 + np.arange(n_shape)] = 1
    sparsity[n_obs + n_prior + n_shape + np.arange(n_off), 27 + n_shape + np.arange(n_off)] = 1
    if offsets:
        sparsity[-1, :27 + n_shape] = 1
        sparsity[-1, 27 + n_shape + 3 * PALM[:, None] + np.arange(3)] = 1
    start = np.r_[phi, np.asarray(betas)[shape_free], np.zeros(n_off),
                  np.c_[rotation[frames], translation[frames]].reshape(-1)]
    p = graduated_fit(residual, start, sparsity, robust_px, max_nfev, n_obs, batched)
    x, b = model_points(p[None])
    poses = p[n_head:].reshape(-1, 6)
    return p[:27], b[0], video_structure(pixels, matrix, x[0], frames, poses[:, :3], poses[:, 3:])
