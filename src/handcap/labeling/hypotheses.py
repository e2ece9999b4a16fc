"""A frame's assignment hypotheses and their scores, for the online labeler's Viterbi trellis.

Given a frame's (labels x points) spatial log-likelihoods and the previous
frame's Kalman predictions, the functions here build the hypotheses of
:class:`handcap.labeling.OnlineLabeler` and score them (Alexanderson et al.
2016; see :mod:`handcap.labeling.online` for the steps):

- :func:`spatial_hypotheses`: the N spatially best assignments of labels to
  points (Murty), a label occluded scoring ``log(1/M)``, pairings below
  ``theta_min`` not allowed, and :func:`emission_scores`, the spatial score
  of any assignment;
- :func:`tracking_hypothesis`: the assignment best for spatial and temporal
  evidence together given one previous hypothesis' filters;
- :func:`transition_scores`: Eq. 3, the temporal score of every (previous,
  new) hypothesis pair.

Log-likelihoods are natural logs of densities (per m^3); positions are in
metres, variances in m^2. Pure functions: the labeler keeps the state.
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import linear_sum_assignment

from handcap.labeling.murty import k_best_assignments


def spatial_hypotheses(ll, n_best: int, theta_min: float, occluded_score: float):
    """The N spatially best assignments of labels to a frame's candidate points.

    Parameters
    ----------
    ll : ndarray (F, K)
        Spatial log-likelihood (per m^3) of each free label at each candidate
        point, in the hand frame.
    n_best : int
        N, the assignments wanted (fewer when fewer exist).
    theta_min : float
        Least log-likelihood (per m^3) of a pairing: those below are not allowed.
    occluded_score : float
        Score of a label left occluded (``log(1/M)``, M free labels).

    Returns
    -------
    hyps : ndarray (N, F) int
        Candidate point of each label per hypothesis, -1 occluded.
    emission : ndarray (N,)
        Spatial score of each hypothesis (sum of its labels' log-likelihoods
        and occlusion scores), best first.
    """
    n_free, k = ll.shape
    rows = np.arange(n_free)
    cost = np.full((n_free, k + n_free), np.inf)
    cost[:, :k] = np.where(ll >= theta_min, -ll, np.inf)
    cost[rows, k + rows] = -occluded_score
    best = k_best_assignments(cost, n_best)
    hyps = np.array([c for c, _ in best])
    hyps = np.where(hyps < k, hyps, -1)
    emission = -np.array([t for _, t in best])
    return hyps, emission


def emission_scores(hyps, ll, theta_min: float, occluded_score: float, born=None) -> np.ndarray:
    """Spatial score of hypotheses: the log-likelihood of each pairing, ``occluded_score`` for a gap and for a
    pairing below ``theta_min`` (the paper's filtered assignment), ``theta_min`` for a birth.

    Parameters
    ----------
    hyps : ndarray (N, F) int
        Candidate point of each free label per hypothesis, -1 occluded.
    ll : ndarray (F, K)
        Spatial log-likelihood (per m^3) of each label at each candidate point.
    theta_min : float
        Least log-likelihood (per m^3) of an accepted pairing.
    occluded_score : float
        Score of a gap (``log(1/M)``).
    born : ndarray (F, K) bool, optional
        Pairings that would start a track (:func:`handcap.labeling.birth.birth_pairings`).

    Returns
    -------
    ndarray (N,)
        Summed score of each hypothesis.
    """
    f = np.arange(hyps.shape[1])
    values = np.where(hyps >= 0, ll[f, np.maximum(hyps, 0)] if ll.shape[1] else 0.0, occluded_score)
    filtered = (hyps >= 0) & (values < theta_min)
    values = np.where(filtered, occluded_score, values)
    if born is not None:
        born = filtered & born[f, np.maximum(hyps, 0)]
        values = np.where(born, theta_min, values)
    return values.sum(axis=1)


def tracking_hypothesis(world, ll, pred, var, trackable, vouch, log_norm, at_gate, *, theta_min: float,
                        occluded_score: float, jump_cost: float, born=None) -> np.ndarray:
    """The assignment best for spatial and temporal evidence together, given one previous hypothesis' filters.

    A pairing the spatial model filters out may still be made when the
    marker's own track vouches for it (a pose the training take did not
    cover); spatially it then scores as a gap.

    Parameters
    ----------
    world : ndarray (K, 3)
        The frame's candidate points, metres.
    ll : ndarray (F, K)
        Spatial log-likelihood (per m^3) of each free label at each point.
    pred : ndarray (F, 3)
        Each label's predicted position, metres.
    var : ndarray (F,)
        Each label's innovation variance (per axis, isotropic), m^2.
    trackable : ndarray (F,) bool
        Labels whose filters score transitions (not coasting too long, warmed up).
    vouch : ndarray (F,) bool
        Tracks that may still carry their label onto a spatially filtered point.
    log_norm : ndarray (F,)
        Gaussian normaliser (log, per m^3) of each label's filter.
    at_gate : ndarray (F,)
        Temporal log-likelihood of a measurement at the gate (what a gap scores).
    theta_min : float
        Least log-likelihood (per m^3) of a spatially accepted pairing.
    occluded_score : float
        Spatial score of a gap (``log(1/M)``).
    jump_cost : float
        A measurement beyond the gate scores this much below a gap (log-likelihood).
    born : ndarray (F, K) bool, optional
        Pairings that would start a track: no track scores them, spatially at ``theta_min``.

    Returns
    -------
    ndarray (1, F) int
        Candidate point of each label, -1 occluded.
    """
    n_free, k = ll.shape[0], len(world)
    rows = np.arange(n_free)
    allowed = ll >= theta_min  # (F, K)
    diff = world[None] - pred[:, None]
    temporal = log_norm[:, None] - 0.5 * np.einsum("fkx,fkx->fk", diff, diff) / var[:, None]  # (F, K)
    track = trackable[:, None]
    reward = np.where(allowed, ll, occluded_score) + track * np.maximum(temporal, at_gate[:, None] - jump_cost)
    cost = np.full((n_free, k + n_free), np.inf)
    ok = allowed | (vouch[:, None] & (temporal >= at_gate[:, None]))
    if born is not None:  # a birth: no track to score it, spatially at theta_min (see ``OnlineLabeler(birth)``)
        reward = np.where(born, theta_min, reward)
        ok |= born
    cost[:, :k] = np.where(ok, -reward, np.inf)
    cost[rows, k + rows] = -occluded_score - trackable * at_gate
    r, c = linear_sum_assignment(cost)
    out = np.full((1, n_free), -1)
    out[0, r] = np.where(c < k, c, -1)
    return out


def transition_scores(obs, pred, var, trackable, log_norm, at_gate, gate: float, jump_cost: float) -> np.ndarray:
    """Eq. 3 for every (previous, new) hypothesis pair.

    A gap scores as a measurement at the gate; a measurement beyond the gate
    (a marker that jumped: real reconstructions do) costs a fixed
    ``jump_cost`` more than a gap, so strong spatial evidence can still keep it.

    Parameters
    ----------
    obs : ndarray (N, F, 3)
        Observed position of each label in each new hypothesis, metres; NaN where occluded.
    pred : ndarray (P, F, 3)
        Each previous hypothesis' predicted position of each label, metres.
    var : ndarray (P, F)
        Innovation variances (per axis, isotropic), m^2.
    trackable : ndarray (P, F) bool
        Filters that score transitions; the others add nothing.
    log_norm : ndarray (P, F)
        Gaussian normaliser (log, per m^3) of each filter.
    at_gate : ndarray (P, F)
        Temporal log-likelihood of a measurement ``gate`` standard deviations off.
    gate : float
        Standard deviations at which a gap scores.
    jump_cost : float
        Log-likelihood below a gap of a measurement beyond the gate.

    Returns
    -------
    ndarray (P, N)
        Summed temporal log-likelihood of each transition.
    """
    residual = obs[None, :, :, :] - pred[:, None, :, :]  # (P, N, F, 3), NaN where occluded
    squared = np.einsum("pnfx,pnfx->pnf", residual, residual) / var[:, None, :]
    squared = np.where(np.isnan(squared), gate**2, squared)
    ll = np.maximum(log_norm[:, None, :] - 0.5 * squared, (at_gate - jump_cost)[:, None, :])
    return (ll * trackable[:, None, :]).sum(axis=-1)
