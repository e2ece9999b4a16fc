"""Re-aligning a trained spatial model to the take it labels (issue 14): registration and mean adaptation.

A spatial model learned on one take is wrong for a take of another day when
the back-of-hand markers sit differently relative to the fingers (a glove put
on again: 13 degrees / 13 mm) or when the hand is another subject's. Two
corrections, each estimated from the take's points in its hand frame:

1. :func:`register_to_model`: the rigid transform that takes the take's
   hand-frame points onto the spatial model, by EM on the Gaussian mixtures
   with a uniform outlier term (rigid CPD, Myronenko & Song 2010,
   doi:10.1109/TPAMI.2010.46). Without labels every point may belong to any
   label's mixture, and the mixtures are widened at first and narrowed over
   the iterations (deterministic annealing) so that a misalignment of several
   centimetres at the fingertips is caught; with labels each point is pulled
   by its own label's mixture only, with Cauchy weights against wrong labels.
2. :func:`adapt_means`: the mixture means moved toward the take's labelled
   points, maximum a posteriori with a relevance factor (Reynolds, Quatieri &
   Dunn 2000, doi:10.1006/dspr.1999.0361): a component that sees ``n`` points
   moves ``n / (n + relevance)`` of the way to their mean.

:meth:`SpatialModel.moved` then expresses the model in the take's hand frame.
The rigid set's own shape is re-learned in :mod:`handcap.labeling.relearn`.
"""

from __future__ import annotations

import numpy as np

from handcap.labeling.spatial import SpatialModel

#: Outlier share of the registration (ghosts, wrong labels), and the volume its uniform density spreads over.
OUTLIER_SHARE = 0.1
OUTLIER_VOLUME = 0.2**3
#: The most a label-free registration may turn (degrees) and shift (metres) the hand frame: back-of-hand
#: markers put on again sit within a few centimetres and a few tens of degrees of where they were (issue 14:
#: 13 degrees / 13 mm); a registration further than that has found another pose of the fingers, not the hand.
MAX_TURN_DEG = 30.0
MAX_SHIFT = 0.03



def _covariances(spatial: SpatialModel) -> np.ndarray:
    """(M, L, 3, 3) covariances of every component, m^2."""
    p = spatial.precision_chol
    return np.linalg.inv(p @ np.swapaxes(p, -1, -2))


def register_to_model(spatial: SpatialModel, local, labels=None, *, weights=None, anneal: float = 0.02,
                      iterations: int = 30, start=None):
    """Rigid transform from the take's hand frame to the model's, by EM.

    Parameters
    ----------
    spatial : SpatialModel
    local : ndarray (N, 3)
        Points in the take's hand frame, metres (the rigid markers left out).
    labels : ndarray (N,) int, optional
        Free-label index of each point (into ``spatial.names``); -1 or absent:
        any label (label-free registration).
    weights : ndarray (N,), optional
        Weight of each point (e.g. older points less).
    anneal : float
        Standard deviation (metres) added to every component at the first
        iteration, shrinking to zero by 60 % of the iterations.
    iterations : int
    start : (ndarray (3, 3), ndarray (3,)), optional
        Initial transform (default identity).

    Returns
    -------
    rotation : ndarray (3, 3)
    translation : ndarray (3,)
        ``model_local = rotation @ take_local + translation``.
    """
    local = np.asarray(local, dtype=np.float64).reshape(-1, 3)
    rot, trans = (np.eye(3), np.zeros(3)) if start is None else (np.asarray(start[0]), np.asarray(start[1]))
    weights = np.ones(len(local)) if weights is None else np.asarray(weights, dtype=np.float64)
    if len(local) < 10:
        return rot, trans
    m, n_comp = spatial.weights.shape
    cov = _covariances(spatial).reshape(-1, 3, 3)  # (M L, 3, 3)
    labelled = labels is not None
    if labelled:
        labels = np.asarray(labels)
        keep = labels >= 0
        local, labels, weights = local[keep], labels[keep], weights[keep]
        pick = labels[:, None] * n_comp + np.arange(n_comp)  # (N, L): each point's own label's components
        logw = np.log(np.maximum(spatial.weights[labels], 1e-300))  # (N, L)
    else:
        w = spatial.weights.ravel() / m
        pick = np.flatnonzero(w > 0)[None]  # (1, K): every label's components
        logw = np.log(w[pick])
    mu = spatial.means.reshape(-1, 3)[pick]  # (N or 1, K, 3)
    eye = np.eye(3)
    cut = max(1, int(0.6 * iterations))
    for it in range(iterations):
        extra = (anneal * max(0.0, 1.0 - it / cut)) ** 2
        if extra > 0:
            comp = np.linalg.cholesky(np.linalg.inv(cov + extra * eye))  # W W^T = C^-1 per component
        else:
            comp = spatial.precision_chol.reshape(-1, 3, 3)
        whiten = comp[pick]  # (N or 1, K, 3, 3)
        logdet = np.log(np.abs(np.diagonal(comp, axis1=-2, axis2=-1))).sum(axis=-1)[pick]  # (N or 1, K)
        y = local @ rot.T  # (N, 3) turned points
        if labelled:
            d = (y + trans)[:, None] - mu  # (N, L, 3)
            r = np.einsum("nkj,nkji->nki", d, whiten)  # whitened residuals W^T d
        else:  # every point against the same K components: W_k^T (y + t) - W_k^T mu_k as one product
            w0 = whiten[0]
            r = ((y + trans) @ w0.transpose(1, 0, 2).reshape(3, -1)).reshape(len(y), -1, 3) \
                - np.einsum("kj,kji->ki", mu[0], w0)
        m2 = np.einsum("nki,nki->nk", r, r)
        logp = logw + logdet - 1.5 * np.log(2 * np.pi) - 0.5 * m2
        top = logp.max(axis=1, keepdims=True)
        p = np.exp(logp - top)
        total = p.sum(axis=1, keepdims=True)
        if labelled:
            # Cauchy weights: a wrongly labelled point (far from every component of its label) counts little.
            gamma = p / total
            gamma = gamma / (1.0 + (gamma * m2).sum(axis=1, keepdims=True) / 9.0)
        else:
            outlier = np.exp(np.minimum(np.log(OUTLIER_SHARE / OUTLIER_VOLUME) - top, 700.0))
            gamma = p / (total + outlier)
        gamma = gamma * weights[:, None]
        if gamma.sum() <= 0:
            break
        # M-step: one Gauss-Newton step on sum gamma |W^T (R x + t - mu)|^2 over a small turn w and shift dt
        # (R x + t ~ y + w x y + t + dt), the full covariances kept (isotropic weights would pull points
        # on a curved finger arc toward its chord).
        skew = np.zeros(y.shape + (3,))  # d(w x y)/dw = -[y]x
        skew[:, 0, 1], skew[:, 0, 2], skew[:, 1, 2] = y[:, 2], -y[:, 1], y[:, 0]
        skew[:, 1, 0], skew[:, 2, 0], skew[:, 2, 1] = -y[:, 2], y[:, 1], -y[:, 0]
        if labelled:  # a few components per point: the Jacobian rows W^T [S, I] themselves, (N, L, 3, 6)
            wt = np.swapaxes(whiten, -1, -2)
            jac = np.concatenate([np.matmul(wt, skew[:, None]), np.broadcast_to(wt, d.shape + (3,))], axis=-1)
            root = np.sqrt(gamma)[..., None]
            a = (jac * root[..., None]).reshape(-1, 6)  # (N L 3, 6)
            h = a.T @ a + 1e-12 * np.eye(6)
            g = a.T @ (r * root).reshape(-1)
        else:
            h, g = _shared_normal_equations(whiten[0], mu[0], gamma, skew, y + trans)
        step = -np.linalg.solve(h, g)
        turn = step[:3]
        angle = np.linalg.norm(turn)
        if angle > 0:
            k = turn / angle
            kx = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
            dr = eye + np.sin(angle) * kx + (1 - np.cos(angle)) * kx @ kx
        else:
            dr = eye
        rot = dr @ rot
        trans = dr @ trans + step[3:]
    if not labelled:
        # Annealing widens the basin but does not promise the best optimum: never end worse than the start,
        # nor further from it than markers put on again can be.
        begin = (np.eye(3), np.zeros(3)) if start is None else start
        turn = np.degrees(np.arccos(np.clip((np.trace(rot @ begin[0].T) - 1) / 2, -1.0, 1.0)))
        if (turn > MAX_TURN_DEG or np.linalg.norm(trans - begin[1]) > MAX_SHIFT
                or _mixture_fit(spatial, local, weights, *begin) > _mixture_fit(spatial, local, weights, rot, trans)):
            return begin
    return rot, trans


def _shared_normal_equations(whiten, mu, gamma, skew, moved):
    """``J^T J`` (6, 6) and ``J^T r`` (6,) of the label-free M-step, every point against the same K components.

    Each point's Jacobian rows are ``W_k^T [S, I]`` (``S`` its skew matrix (N, 3, 3), ``W_k`` the whitening
    (K, 3, 3)) and its residuals ``W_k^T (x - mu_k)``, weighed by ``gamma`` (N, K): the sums are
    ``[S, I]^T Q [S, I]`` and ``[S, I]^T v`` with ``Q = sum_k gamma_k P_k``, ``v = sum_k gamma_k P_k (x - mu_k)``
    and ``P = W W^T``, so no (N, K, 3, 6) Jacobian is formed (3 times faster on 3,000 points and 30 components,
    the same step to rounding).
    """
    precision = np.matmul(whiten, np.swapaxes(whiten, -1, -2))  # (K, 3, 3)
    q = (gamma @ precision.reshape(-1, 9)).reshape(-1, 3, 3)  # (N, 3, 3)
    v = np.einsum("nij,nj->ni", q, moved) - gamma @ np.einsum("kij,kj->ki", precision, mu)
    qs = np.matmul(q, skew)
    h = np.empty((6, 6))
    h[:3, :3] = np.einsum("nji,njk->ik", skew, qs)
    h[:3, 3:] = qs.sum(axis=0).T
    h[3:, :3] = h[:3, 3:].T
    h[3:, 3:] = q.sum(axis=0)
    return h + 1e-12 * np.eye(6), np.concatenate([np.einsum("nji,nj->i", skew, v), v.sum(axis=0)])


def _mixture_fit(spatial, local, weights, rot, trans) -> float:
    """Weighted log-likelihood of points (N, 3) moved by (rot, trans) under the mixture of every label's
    mixture and the uniform outlier term (what the label-free registration maximises)."""
    m = len(spatial.names)
    ll = spatial.log_likelihood(local @ rot.T + trans)  # (M, N)
    top = ll.max(axis=0)
    mix = top + np.log(np.exp(ll - top).sum(axis=0) / m)
    total = np.logaddexp(np.log(1 - OUTLIER_SHARE) + mix, np.log(OUTLIER_SHARE / OUTLIER_VOLUME))
    return float(weights @ total)


def adapt_means(spatial: SpatialModel, local, labels, *, weights=None, relevance: float = 20.0,
                max_distance: float = 5.0) -> SpatialModel:
    """Mixture means moved toward labelled points (MAP adaptation with a relevance factor).

    Parameters
    ----------
    spatial : SpatialModel
    local : ndarray (N, 3)
        Points in the model's hand frame, metres.
    labels : ndarray (N,) int
        Free-label index of each point; -1 ignored.
    weights : ndarray (N,), optional
        Weight of each point (how many points it counts for).
    relevance : float
        Points a component must see to move half way to their mean.
    max_distance : float
        Points further than this many standard deviations (Mahalanobis) from
        every component of their label are left out (a wrong label, a ghost).
    """
    local = np.asarray(local, dtype=np.float64).reshape(-1, 3)
    labels = np.asarray(labels)
    weights = np.ones(len(local)) if weights is None else np.asarray(weights, dtype=np.float64)
    keep = labels >= 0
    local, labels, weights = local[keep], labels[keep], weights[keep]
    means = spatial.means.copy()
    if not len(local):
        return spatial
    d = local[:, None] - spatial.means[labels]  # (N, L, 3)
    y = np.einsum("nli,nlij->nlj", d, spatial.precision_chol[labels])
    m2 = (y**2).sum(axis=-1)
    logp = spatial.log_norm[labels] - 0.5 * m2
    gamma = np.exp(logp - logp.max(axis=1, keepdims=True))
    gamma /= gamma.sum(axis=1, keepdims=True)
    gamma *= ((m2.min(axis=1) < max_distance**2) * weights)[:, None]
    m, n_comp = spatial.weights.shape
    flat = labels[:, None] * n_comp + np.arange(n_comp)  # (N, L) component index
    count = np.bincount(flat.ravel(), gamma.ravel(), minlength=m * n_comp).reshape(m, n_comp)
    sums = np.stack([np.bincount(flat.ravel(), (gamma * local[:, i, None]).ravel(), minlength=m * n_comp)
                     for i in range(3)], axis=-1).reshape(m, n_comp, 3)
    share = count / (count + relevance)
    means = np.where(count[..., None] > 0, (1 - share[..., None]) * means
                     + share[..., None] * sums / np.maximum(count[..., None], 1e-300), means)
    return SpatialModel(spatial.names, spatial.weights, means, spatial.precision_chol, spatial.log_norm)
