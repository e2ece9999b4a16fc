"""Registration of a hand's markers to its template (the paper's section 3.2.2).

The marker predictor and the joint regressor work in the hand's own frame:
the visible markers are moved onto a template hand by the rigid motion that
fits them best (Kabsch), the network predicts there, and its output is moved
back (de-registration). With the rotation and translation of the hand gone,
the networks only have to learn the posture.

Convention (row vectors, as in the paper's eq. 1)::

    local = (world - centre) @ rotation + template_centre
    world = (local - template_centre) @ rotation.T + centre

References
----------
Kabsch W. A solution for the best rotation to relate two sets of vectors.
Acta Crystallogr A 1976;32(5):922-3. doi:10.1107/S0567739476001873
"""

from __future__ import annotations

import numpy as np

from handcap.core.errors import HandcapError


def procrustes_mean(positions, *, iterations: int = 10) -> np.ndarray:
    """The mean marker shape of a take, up to a rigid motion (generalised Procrustes).

    Parameters
    ----------
    positions : ndarray (T, M, 3)
        Metres, NaN where missing; frames with missing markers are skipped.

    Returns
    -------
    template : ndarray (M, 3)
        Metres, centred on the origin, in the frame of the first complete frame.

    Raises
    ------
    HandcapError
        If no frame has every marker.
    """
    positions = np.asarray(positions, dtype=np.float64)
    full = positions[~np.isnan(positions).any(axis=(1, 2))]
    if not len(full):
        raise HandcapError("no frame has every marker: cannot build a template of the hand")
    template = full[0] - full[0].mean(axis=0)
    weights = np.ones(positions.shape[1])
    for _ in range(iterations):
        visible = np.ones(full.shape[:2], bool)
        rotation, centre, template_centre = fit_registration(full, visible, template, weights)
        local = apply_registration(full, rotation, centre, template_centre)
        new = local.mean(axis=0)
        new -= new.mean(axis=0)
        if np.abs(new - template).max() < 1e-9:
            template = new
            break
        template = new
    return template


def fit_registration(positions, visible, template, weights):
    """Rigid motions that carry the visible markers of each frame onto the template.

    Weighted Kabsch, vectorised over frames.

    Parameters
    ----------
    positions : ndarray (..., M, 3)
        Metres; entries where ``visible`` is False are ignored (may be NaN).
    visible : ndarray (..., M) bool
    template : ndarray (M, 3)
        Metres.
    weights : ndarray (M,)
        Relative weight of each marker in the fit.

    Returns
    -------
    rotation : ndarray (..., 3, 3)
        Proper rotations (det +1).
    centre : ndarray (..., 3)
        Weighted centre of the visible markers, metres.
    template_centre : ndarray (..., 3)
        Weighted centre of the same markers on the template, metres.

    Frames with fewer than three visible markers give NaN.
    """
    positions = np.asarray(positions, dtype=np.float64)
    w = np.where(visible, weights, 0.0)
    total = w.sum(axis=-1, keepdims=True)
    ok = (np.count_nonzero(visible, axis=-1) >= 3) & (total[..., 0] > 0)
    total = np.where(total > 0, total, 1.0)
    x = np.where(visible[..., None], positions, 0.0)
    centre = np.einsum("...m,...mi->...i", w, x) / total
    template_centre = (w @ template) / total
    a = (x - centre[..., None, :]) * w[..., None]
    b = template - template_centre[..., None, :]
    h = np.einsum("...mi,...mj->...ij", a, b)
    u, _, vt = np.linalg.svd(h)
    d = np.sign(np.linalg.det(u @ vt))
    u[..., :, 2] *= d[..., None]
    rotation = u @ vt
    rotation[~ok] = np.nan
    centre[~ok] = np.nan
    return rotation, centre, template_centre


def apply_registration(positions, rotation, centre, template_centre) -> np.ndarray:
    """World positions (..., M, 3) to the template frame (see the module docstring)."""
    return (positions - centre[..., None, :]) @ rotation + template_centre[..., None, :]


def undo_registration(local, rotation, centre, template_centre) -> np.ndarray:
    """Template-frame positions (..., M, 3) back to the world."""
    return (local - template_centre[..., None, :]) @ np.swapaxes(rotation, -1, -2) + centre[..., None, :]
