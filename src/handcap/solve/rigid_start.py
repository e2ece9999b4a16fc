"""The rigid initial pose of a take: each frame's global rotation and translation from the markers alone.

Before any angle is solved, the hand is taken as rigid in a reference pose
and aligned to the observed markers by Kabsch, on the palm markers where
enough are seen. The motion solvers (:mod:`handcap.solve.motion`,
:mod:`handcap.solve.adam`) start from it.
"""

from __future__ import annotations

import numpy as np

from handcap.objects.rigid import kabsch


def rigid_start(model, target, observed, rest_phi) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per-frame rotation and translation from the palm markers (Kabsch).

    All markers are used where fewer than three palm markers are seen, or
    where the palm markers do not span a plane on the model (2nd singular
    value of their spread under 5 mm).

    Parameters
    ----------
    model : :class:`~handcap.solve.markers.MarkerModel`
        The markers on the hand (M markers).
    target : ndarray (T, M, 3)
        Observed markers, metres (ignored where not ``observed``).
    observed : ndarray (T, M) bool
    rest_phi : ndarray (27,)
        The pose the model's markers are aligned in, radians.

    Returns
    -------
    rotation : ndarray (T, 3, 3)
        Global orientation about the wrist joint; identity where not ok.
    translation : ndarray (T, 3)
        The model's ``transl``, metres; zero where not ok.
    ok : ndarray (T,) bool
        Frames where at least three markers made the alignment possible.
    """
    n = len(target)
    rest = model.positions(np.zeros((1, 3)), np.eye(3)[None], rest_phi[None])[0]
    palm = model.marker_weights[:, 0] > 0.9
    if palm.sum() >= 3:
        # Palm markers that (nearly) coincide on the model, as position-less markers do before a calibration
        # has placed them, fix no rotation: align all markers then.
        spread = np.linalg.svd(rest[palm] - rest[palm].mean(axis=0), compute_uv=False)
        if spread[1] < 0.005:
            palm = np.zeros_like(palm)
    use_palm = (observed & palm).sum(axis=1) >= 3
    weights = np.where(use_palm[:, None], observed & palm, observed).astype(float)
    ok = weights.sum(axis=1) >= 3
    src = np.broadcast_to(rest, target.shape)
    tgt = np.where(observed[..., None], target, 0.0)
    rot = np.tile(np.eye(3), (n, 1, 1))
    trans = np.zeros((n, 3))
    if ok.any():
        r, t = kabsch(src[ok], tgt[ok], weights[ok])
        rot[ok] = r
        # Kabsch gives y = R x + t about the origin; the model turns about the wrist joint J0.
        j0 = model.rest_joints[0]
        trans[ok] = t + np.einsum("tij,j->ti", r, j0) - j0
    return rot, trans, ok
