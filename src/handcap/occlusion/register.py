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

from handcap.objects.rigid import kabsch


def fit_registration(positions, visible, template, weights):
    """Rigid motions that carry the visible markers of each frame onto the template.

    Weighted Kabsch (:func:`handcap.objects.rigid.kabsch`), vectorised over frames.

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
    x = np.where(visible[..., None], positions, 0.0)
    rotation, _ = kabsch(x, np.broadcast_to(template, x.shape), w)  # template ~ rotation @ x + t
    total = np.where(total > 0, total, 1.0)
    centre = np.einsum("...m,...mi->...i", w, x) / total
    template_centre = (w @ template) / total
    rotation = np.swapaxes(rotation, -1, -2)  # row vectors: local = (x - centre) @ rotation + template_centre
    rotation[~ok] = np.nan
    centre[~ok] = np.nan
    return rotation, centre, template_centre


def apply_registration(positions, rotation, centre, template_centre) -> np.ndarray:
    """World positions (..., M, 3) to the template frame (see the module docstring).

    Parameters
    ----------
    positions : ndarray (..., M, 3)
        World, metres.
    rotation : ndarray (..., 3, 3)
    centre : ndarray (..., 3)
        Metres.
    template_centre : ndarray (..., 3)
        Metres; the three from :func:`fit_registration`.

    Returns
    -------
    ndarray (..., M, 3)
        Template frame, metres (NaN on frames whose registration failed).
    """
    return (positions - centre[..., None, :]) @ rotation + template_centre[..., None, :]


def undo_registration(local, rotation, centre, template_centre) -> np.ndarray:
    """Template-frame positions (..., M, 3) back to the world.

    Parameters
    ----------
    local : ndarray (..., M, 3)
        Template frame, metres.
    rotation : ndarray (..., 3, 3)
    centre : ndarray (..., 3)
        Metres.
    template_centre : ndarray (..., 3)
        Metres; the three from :func:`fit_registration`.

    Returns
    -------
    ndarray (..., M, 3)
        World, metres.
    """
    return (local - template_centre[..., None, :]) @ np.swapaxes(rotation, -1, -2) + centre[..., None, :]


class Registrar:
    """Registration of one frame (or several with one visible set) to a template, per-set terms cached.

    The streaming filler's fast path of :func:`fit_registration` (same weighted Kabsch).

    With ``b_i = w_i (q_i - q_mean)`` summing to zero, the cross-covariance is simply
    ``P^T B``: no centring of the measured points is needed.

    Parameters
    ----------
    template : ndarray (M, 3)
        Metres.
    weights : ndarray (M,)
    """

    def __init__(self, template, weights):
        self.template, self.weights = template, weights
        self.cache = {}

    def _entry(self, visible):
        key = visible.tobytes()
        entry = self.cache.get(key)
        if entry is None:
            if len(self.cache) > 4096:
                self.cache.clear()
            index = np.flatnonzero(visible)
            w = self.weights[index] / self.weights[index].sum()
            tc = w @ self.template[index]
            entry = (index, w, tc, w[:, None] * (self.template[index] - tc), len(index) == len(visible))
            self.cache[key] = entry
        return entry

    def fit(self, points, visible):
        """(rotation (3, 3), centre (3,), template_centre (3,)) of one frame ``points`` (M, 3), metres.

        Parameters
        ----------
        points : ndarray (M, 3)
            Metres; ignored where not visible.
        visible : ndarray (M,) bool
            At least 3 markers.

        Returns
        -------
        tuple
            As :func:`fit_registration` for one frame.
        """
        index, w, tc, b, full = self._entry(visible)
        p = points if full else points[index]
        c = w @ p
        u, _, vt = np.linalg.svd(p.T @ b)
        r = u @ vt
        if _det(r) < 0:
            u[:, 2] = -u[:, 2]
            r = u @ vt
        return r, c, tc

    def fit_many(self, points, visible):
        """:meth:`fit` of F frames with one visible set.

        Parameters
        ----------
        points : ndarray (F, M, 3)
            Metres; ignored where not visible.
        visible : ndarray (M,) bool

        Returns
        -------
        rotation : ndarray (F, 3, 3)
        centre : ndarray (F, 3)
            Metres.
        template_centre : ndarray (3,)
            Metres.
        """
        index, w, tc, b, _ = self._entry(visible)
        p = points[:, index]
        u, _, vt = np.linalg.svd(np.swapaxes(p, 1, 2) @ b)
        r = u @ vt
        flip = np.linalg.det(r) < 0
        if flip.any():
            u[flip, :, 2] *= -1.0
            r[flip] = u[flip] @ vt[flip]
        return r, w @ p, tc


def _det(m) -> float:
    (a, b, c), (d, e, f), (g, h, i) = m.tolist()
    return a * (e * i - f * h) - b * (d * i - f * g) + c * (d * h - e * g)
