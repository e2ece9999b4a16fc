"""Spatial model: one Gaussian mixture per marker label in the hand's frame (Eq. 1-2 of the paper).

Fitted by EM (scikit-learn ``GaussianMixture``, full covariances) on a labeled
range-of-motion take moved into the hand frame. Evaluation is done here, in
numpy, for a whole frame of points at once: the (labels x points) matrix of
log-likelihoods.

Units: metres, so a log-likelihood is a log density per cubic metre. Near the
centre of a 1 cm wide component it is about +11; the paper's tolerance
``theta_min = -2`` then means about five standard deviations away.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from handcap.core.errors import HandcapError

#: Fewest training samples of a label for a mixture fit.
MIN_SAMPLES = 20


@dataclass(frozen=True)
class SpatialModel:
    """Gaussian mixtures of M labels with L components each.

    Attributes
    ----------
    names : tuple of str (M,)
    weights : ndarray (M, L)
    means : ndarray (M, L, 3)
        Metres, hand frame.
    precision_chol : ndarray (M, L, 3, 3)
        Cholesky factors of the precision matrices (``Sigma^-1 = P P^T``).
    log_norm : ndarray (M, L)
        ``log w - 1.5 log(2 pi) + log det P``: everything but the quadratic term.
    """

    names: tuple
    weights: np.ndarray
    means: np.ndarray
    precision_chol: np.ndarray
    log_norm: np.ndarray

    @classmethod
    def fit(cls, names, local, *, components: int = 3, seed: int = 0, reg_covar: float = 1e-6) -> "SpatialModel":
        """Fit one mixture per label.

        Parameters
        ----------
        names : sequence of str (M,)
        local : ndarray (T, M, 3)
            Labeled training positions in the hand frame, metres; NaN where missing.
        components : int
            Mixture components per label (the paper: 3).
        seed : int
            EM initialisation seed (k-means++), for reproducible models.
        reg_covar : float
            Added to every covariance diagonal, m^2 (1e-6: a 1 mm floor).
        """
        from sklearn.mixture import GaussianMixture
        local = np.asarray(local, dtype=np.float64)
        weights, means, chols = [], [], []
        for i, name in enumerate(names):
            samples = local[:, i][~np.isnan(local[:, i]).any(axis=1)]
            if len(samples) < MIN_SAMPLES:
                raise HandcapError(f"marker {name!r} appears in only {len(samples)} training frames; "
                                   f"a spatial model needs at least {MIN_SAMPLES}")
            n = min(components, max(1, len(np.unique(samples.round(4), axis=0)) // 2))
            gmm = GaussianMixture(n, covariance_type="full", reg_covar=reg_covar, random_state=seed,
                                  n_init=1, max_iter=200).fit(samples)
            w, mu, pc = gmm.weights_, gmm.means_, gmm.precisions_cholesky_
            if n < components:  # pad with components of zero weight
                pad = components - n
                w = np.r_[w, np.zeros(pad)]
                mu = np.r_[mu, np.repeat(mu[:1], pad, axis=0)]
                pc = np.r_[pc, np.repeat(pc[:1], pad, axis=0)]
            weights.append(w)
            means.append(mu)
            chols.append(pc)
        weights, means, chols = np.array(weights), np.array(means), np.array(chols)
        return cls(tuple(names), weights, means, chols, _log_norm(weights, chols))

    def __post_init__(self):
        # Whitening of every component as one matrix: y = (x - mu) P = x P - mu P for all of them at once.
        m, n_comp = self.weights.shape
        object.__setattr__(self, "_whiten", self.precision_chol.transpose(2, 0, 1, 3).reshape(3, m * n_comp * 3))
        object.__setattr__(self, "_offset", np.einsum("mli,mlij->mlj", self.means, self.precision_chol).ravel())

    def log_likelihood(self, points) -> np.ndarray:
        """Log-likelihood (M, K) of every label for every point (K, 3) in the hand frame (Eq. 1)."""
        points = np.asarray(points, dtype=np.float64)
        m, n_comp = self.weights.shape
        y = (points @ self._whiten - self._offset).reshape(len(points), m, n_comp, 3)  # whitened offsets
        terms = self.log_norm - 0.5 * np.einsum("kmlj,kmlj->kml", y, y)  # (K, M, L)
        top = terms.max(axis=2, keepdims=True)
        top = np.where(np.isfinite(top), top, 0.0)
        return (top + np.log(np.exp(terms - top).sum(axis=2, keepdims=True)))[..., 0].T

    def typical_fit(self, samples: int = 200, seed: int = 0) -> float:
        """How well points fit the model when the hand frame is right: the median, over points drawn from
        every label's mixture, of their best label's log-likelihood.

        A frame whose points fit this model far worse (their median best
        log-likelihood several units below) is seen in a wrong hand frame,
        or the model is not the take's yet. The value is unchanged by
        :meth:`moved`; it needs no training data (a model read from a file
        has it too).

        Parameters
        ----------
        samples : int
            Points drawn per label.
        seed : int
            Seed of the draw (the value is reproducible).

        Returns
        -------
        float
            Log density per cubic metre (about +11 to +13 for finger markers; see the module).
        """
        rng = np.random.default_rng(seed)
        m, n_comp = self.weights.shape
        drawn = []
        for i in range(m):
            comp = rng.choice(n_comp, size=samples, p=self.weights[i] / self.weights[i].sum())
            z = rng.standard_normal((samples, 3))
            # x = mu + L^-T z, with P = L the precision's Cholesky factor: covariance (P P^T)^-1.
            offsets = np.linalg.solve(np.swapaxes(self.precision_chol[i, comp], -1, -2), z[..., None])[..., 0]
            drawn.append(self.means[i, comp] + offsets)
        return float(np.median(self.log_likelihood(np.concatenate(drawn)).max(axis=0)))

    def moved(self, rotation, translation) -> "SpatialModel":
        """The same mixtures expressed in another hand frame.

        Parameters
        ----------
        rotation : ndarray (3, 3)
        translation : ndarray (3,)
            ``model_local = rotation @ other_local + translation`` (metres).

        Returns
        -------
        SpatialModel
            Evaluated on points of the other frame, it gives what this model
            gives on the same points moved into its own frame.
        """
        rot = np.asarray(rotation, dtype=np.float64)
        trans = np.asarray(translation, dtype=np.float64)
        means = (self.means - trans) @ rot  # R^T (mu - t), row vectors
        precision = self.precision_chol @ np.swapaxes(self.precision_chol, -1, -2)
        chol = np.linalg.cholesky(rot.T @ precision @ rot)  # a rotation keeps the determinant
        return SpatialModel(self.names, self.weights, means, chol, self.log_norm)

    def widened(self, spread: float, labels=None) -> "SpatialModel":
        """The same mixtures, every component (of ``labels``) widened by ``spread`` of isotropic standard deviation.

        A search wider than training allows: another subject's marker can sit
        15 mm from where the training subject's did, many standard deviations
        of a knuckle marker's 1 mm wide components away.

        Parameters
        ----------
        spread : float
            Metres; each covariance becomes ``Sigma + spread^2 I``.
        labels : ndarray (M,) bool, optional
            The labels widened (default: every one).

        Returns
        -------
        SpatialModel
            Same names, weights and means.
        """
        precision = self.precision_chol @ np.swapaxes(self.precision_chol, -1, -2)
        extra = np.ones(len(self.names)) if labels is None else np.asarray(labels, dtype=np.float64)
        covariance = np.linalg.inv(precision) + float(spread) ** 2 * extra[:, None, None, None] * np.eye(3)
        chol = np.linalg.cholesky(np.linalg.inv(covariance))
        return SpatialModel(self.names, self.weights, self.means, chol, _log_norm(self.weights, chol))

    def to_arrays(self, prefix: str = "gmm_") -> dict:
        """The mixtures as ``.npz`` entries (``log_norm`` is recomputed on reading).

        Parameters
        ----------
        prefix : str
            Put before each entry name.

        Returns
        -------
        dict of str to ndarray
            ``<prefix>names`` (M,), ``<prefix>weights`` (M, L), ``<prefix>means`` (M, L, 3) in metres
            (hand frame) and ``<prefix>precision_chol`` (M, L, 3, 3) in 1/metres.
        """
        return {f"{prefix}names": np.array(self.names), f"{prefix}weights": self.weights,
                f"{prefix}means": self.means, f"{prefix}precision_chol": self.precision_chol}

    @classmethod
    def from_arrays(cls, data, prefix: str = "gmm_") -> "SpatialModel":
        """The mixtures stored by :meth:`to_arrays`.

        Parameters
        ----------
        data : mapping of str to ndarray
            Holds ``<prefix>names`` (M,), ``<prefix>weights`` (M, L), ``<prefix>means`` (M, L, 3) in
            metres (hand frame) and ``<prefix>precision_chol`` (M, L, 3, 3) in 1/metres.
        prefix : str
            Prefix of the entry names.

        Returns
        -------
        SpatialModel
            ``log_norm`` computed from the weights and Cholesky factors.
        """
        weights = np.asarray(data[f"{prefix}weights"], dtype=np.float64)
        chols = np.asarray(data[f"{prefix}precision_chol"], dtype=np.float64)
        return cls(tuple(str(n) for n in data[f"{prefix}names"]), weights,
                   np.asarray(data[f"{prefix}means"], dtype=np.float64), chols, _log_norm(weights, chols))


def median_fit(ll) -> float:
    """How well a frame's points fit the labels: the better of the points' median best log-likelihood and the
    labels' (each label's best point). A held object's markers, not given to the labeler, fit no label and pull the
    points' median down, while the hand's labels still find their markers (:meth:`SpatialModel.typical_fit` is the
    yardstick).

    Parameters
    ----------
    ll : ndarray (M, K)
        Log-likelihood of every label for each of the frame's K points (K >= 1).
    """
    return float(max(np.median(ll.max(axis=0)), np.median(ll.max(axis=1))))


def _log_norm(weights, chols) -> np.ndarray:
    """``log w - 1.5 log(2 pi) + log det P`` (M, L) of weights (M, L) and precision Cholesky factors (M, L, 3, 3)."""
    log_det = np.log(np.diagonal(chols, axis1=2, axis2=3)).sum(axis=-1)
    with np.errstate(divide="ignore"):  # components of zero weight: -inf, never chosen
        return np.log(weights) - 1.5 * np.log(2 * np.pi) + log_det
