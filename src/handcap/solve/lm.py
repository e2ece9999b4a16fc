"""Levenberg-Marquardt pose fitting of attached markers, batched over frames.

For every frame the cost is

    sum_i rho(|x_i(q) - y_i|)                        observed markers (Eq. 2, robust)
  + (w_lim  |clip(phi, low, high) - phi|)^2          joint limits (Eq. 3-4)
  + (w_dip  (phi_dip - k phi_pip))^2                  DIP follows PIP (k = 2/3), per finger
  + (w_rest |phi - phi_rest|)^2                        weak pull to a relaxed hand

with ``q = (transl, rotation, phi)``. Each prior weight is in metres per radian:
an angle off by one radian costs as much as a marker off by that many metres.
Frames are independent, so a block of frames is solved at once: one batched
normal-equation solve (33 x 33 per frame) per iteration, with the damping of
every frame adapted on its own (Marquardt's rule) and the weights of the
Cauchy loss ``rho`` renewed each iteration (iteratively reweighted least
squares).

References
----------
Marquardt D.W. (1963) doi:10.1137/0111030; Nocedal J., Wright S.J. (2006)
Numerical Optimization, ch. 10.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from handcap.core.rotations import matrix_from_axis_angle
from handcap.hand.anatomy import DIP_PIP_RATIO, PHI_JOINT, PHI_LIMITS, PHI_NAMES, relaxed_pose
from handcap.solve.markers import N_PARAMS

_I = {n: i for i, n in enumerate(PHI_NAMES)}
#: (dip, pip) angle indices of the four fingers for the coupling prior.
COUPLED = np.array([(_I[f"{f}_dip_bend"], _I[f"{f}_pip_bend"]) for f in ("index", "middle", "pinky", "ring")])
#: (pip, mcp) flexion indices of the four fingers and (ip, mcp) of the thumb for the synergy prior.
SYNERGY = np.array([(_I[f"{f}_pip_bend"], _I[f"{f}_mcp_bend"]) for f in ("index", "middle", "pinky", "ring")]
                   + [(_I["thumb_ip_bend"], _I["thumb_mcp_bend"])])
_RELAXED = relaxed_pose()  # built once: the priors are evaluated twice per frame of every solve
#: Rows of the prior residuals: limits (27), coupling (4), synergy (5), rest pull (27).
N_PRIOR_ROWS = 27 + len(COUPLED) + len(SYNERGY) + 27


@dataclass(frozen=True)
class Priors:
    """Weights (metres per radian) and targets of the anatomical priors.

    Attributes
    ----------
    limits : ndarray (27, 2)
        Joint limits in radians (default :data:`handcap.hand.PHI_LIMITS`).
    limit_weight : float
        Eq. (3): cost of leaving the limits (0.1: 10 degrees out weigh as much
        as a marker 17 mm off).
    coupling : float
        DIP flexion per unit PIP flexion (2/3: tendon coupling of the finger
        flexors, as in handcap.synth).
    coupling_weight : float
        Strength of that coupling where no marker sets the DIP (0.01: 10 degrees off cost like 1.7 mm).
    seen_coupling_weight : float
        Its strength where markers set the DIP (0.001: 10 degrees off cost like 0.17 mm, as the weak pull). The
        coupling holds roughly in free motion only: a finger wrapped round an object or pressing on it bends its
        DIP far more or less (DIP angles estimated linearly from the PIP's are 9-18 degrees off on average per
        task of daily living; Roda-Sales A. et al. 2022, PeerJ 10:e14051). At 0.01 it outweighed markers that
        see the DIP: synthetic grasps solved with their true attachment put the ring and little fingers' DIPs
        30-45 degrees off (joints 7-8 mm off at p99, dense-patches and joints-19) with their markers 1-3.5 mm off.
    synergy : float
        PIP (thumb: IP) flexion per unit MCP flexion, applied only where no
        marker constrains the PIP (IP) joint and none did earlier in the take
        (e.g. a fingertip marker lost for the whole take): 1.0, the ratio of
        the mean functional flexion postures of daily activities (MCP 61 deg,
        PIP 60 deg; Hume M.C. et al. 1990, J Hand Surg 15A:240-243).
    synergy_weight : float
        Strength of that synergy (0.01).
    rest : ndarray (27,)
        Relaxed hand the weak pull draws unconstrained angles towards.
    rest_weight : float
        Strength of the pull (0.001: 10 degrees cost like 0.17 mm).
    """

    limits: np.ndarray = field(default_factory=lambda: PHI_LIMITS.copy())
    limit_weight: float = 0.1
    coupling: float = DIP_PIP_RATIO
    coupling_weight: float = 0.01
    seen_coupling_weight: float = 0.001
    synergy: float = 1.0
    synergy_weight: float = 0.01
    rest: np.ndarray | None = None
    rest_weight: float = 0.001

    def rest_phi(self) -> np.ndarray:
        """The relaxed hand (27,) the weak pull draws towards, radians: ``rest``, else :func:`relaxed_pose`."""
        if self.rest is not None:
            return np.asarray(self.rest, dtype=np.float64)
        return _RELAXED.copy()

    def pulled(self, target, weight: float) -> "Priors":
        """These priors with a second pull, towards ``target`` at ``weight`` metres per radian, joined to the weak
        pull: one quadratic pull towards the two targets weighed by their squared weights, of weight their
        quadrature sum (the same cost, up to a constant).

        Parameters
        ----------
        target : ndarray (27,) or (T, 27)
            Radians (one target per frame where the solve takes several frames).
        weight : float
            Metres per radian.
        """
        both = float(np.hypot(self.rest_weight, weight))
        joined = (self.rest_weight ** 2 * self.rest_phi() + weight ** 2 * np.asarray(target, np.float64)) / both ** 2
        return replace(self, rest=joined, rest_weight=both)


def robust_weights(norms, scale):
    """IRLS weights of the Cauchy (Lorentzian) loss on residual norms: ``1 / (1 + (e / scale)^2)``.

    A marker ``scale`` off counts half; a mislabelled marker 4 cm off (with the
    default 5 mm) pulls with the force of a 0.6 mm error, so it barely moves
    the hand.

    Parameters
    ----------
    norms : ndarray (...)
        Residual norms ``e``, metres.
    scale : float
        Scale of the loss, metres.

    Returns
    -------
    ndarray (...)
        Weights in (0, 1], no unit.
    """
    return 1.0 / (1.0 + (norms / scale) ** 2)


def robust_cost(norms, scale):
    """Cauchy (Lorentzian) loss ``0.5 scale^2 log(1 + (e / scale)^2)`` of residual norms.

    Parameters
    ----------
    norms : ndarray (...)
        Residual norms ``e``, metres.
    scale : float
        Scale of the loss, metres.

    Returns
    -------
    ndarray (...)
        Square metres; ``0.5 e^2`` for ``e`` much below ``scale``.
    """
    return 0.5 * scale**2 * np.log1p((norms / scale) ** 2)


def prior_terms(phi, priors: Priors, held, free=None):
    """Residuals (T, R) and their Jacobian (T, R, 27) of the priors; held angles get none.

    ``free`` (T, 27) marks the angles no marker constrains now or did before:
    their PIP (IP) follows the MCP by the synergy prior, and a free DIP follows
    its PIP at the full coupling weight (at ``seen_coupling_weight`` where not free).

    Parameters
    ----------
    phi : ndarray (T, 27)
        Anatomical angles, radians.
    priors : Priors
    held : ndarray (T, 27) bool
        Angles held at their value: no coupling or rest pull on them (limits still apply).
    free : ndarray (T, 27) bool, optional
        Angles no marker constrains; without it the synergy prior is off and the coupling at full weight.

    Returns
    -------
    residuals : ndarray (T, R)
        Metres (weights in metres per radian times radians); R = 63: limits (27), coupling (4),
        synergy (5), rest pull (27).
    jacobian : ndarray (T, R, 27)
        Metres per radian.
    """
    n = phi.shape[0]
    low, high = priors.limits[:, 0], priors.limits[:, 1]
    n_syn = len(SYNERGY)
    residuals = np.empty((n, N_PRIOR_ROWS))
    jacobian = np.zeros((n, N_PRIOR_ROWS, 27))  # rows: limits 27, coupling 4, synergy, rest 27 (one array)
    idx = np.arange(27)
    residuals[:, :27] = priors.limit_weight * (np.clip(phi, low, high) - phi)
    jacobian[:, idx, idx] = np.where((phi < low) | (phi > high), -priors.limit_weight, 0.0)
    dip, pip = COUPLED[:, 0], COUPLED[:, 1]
    weight = priors.coupling_weight if free is None else np.where(free[:, dip], priors.coupling_weight,
                                                                  priors.seen_coupling_weight)
    weight = weight * ~(held[:, dip] | held[:, pip])
    residuals[:, 27:31] = weight * (phi[:, dip] - priors.coupling * phi[:, pip])
    rows = 27 + np.arange(4)
    jacobian[:, rows, dip] = weight
    jacobian[:, rows, pip] = -weight * priors.coupling
    distal, mcp = SYNERGY[:, 0], SYNERGY[:, 1]
    follows = np.zeros((n, n_syn), bool) if free is None else free[:, distal] & ~held[:, mcp]
    residuals[:, 31:31 + n_syn] = priors.synergy_weight * (phi[:, distal] - priors.synergy * phi[:, mcp]) * follows
    rows = 31 + np.arange(n_syn)
    jacobian[:, rows, distal] = priors.synergy_weight * follows
    jacobian[:, rows, mcp] = -priors.synergy_weight * priors.synergy * follows
    residuals[:, 31 + n_syn:] = priors.rest_weight * (phi - priors.rest_phi()) * ~held
    jacobian[:, 31 + n_syn + idx, idx] = priors.rest_weight * ~held
    return residuals, jacobian


#: A marker constrains a joint when at least this share of its skinning moves with the joint. A marker
#: near the PIP on the proximal phalanx moves a few per cent with the PIP: far too little to set it.
CONSTRAINING_WEIGHT = 0.3


def unconstrained_angles(model, observed) -> np.ndarray:
    """Angles (T, 27) that no observed marker sets (their segments and everything beyond are unseen).

    A marker sets the angles of the joints that carry at least
    :data:`CONSTRAINING_WEIGHT` of it.

    Parameters
    ----------
    model : MarkerModel
    observed : ndarray (T, M) bool
        Markers seen in each frame.

    Returns
    -------
    ndarray (T, 27) bool
    """
    carries = model._weights_below >= CONSTRAINING_WEIGHT  # (M, 16): marker m moves with joint j
    constrained = (observed[:, :, None] & carries[None]).any(axis=1)  # (T, 16)
    return ~constrained[:, PHI_JOINT]


def held_angles(model, observed) -> np.ndarray:
    """Angles (T, 27) to hold at the previous frame's value, as in DexterCap.

    Those unconstrained now (:func:`unconstrained_angles`) that markers did
    constrain in an earlier frame. Angles never constrained so far are not
    held: the anatomical priors set them (see :class:`Priors`).

    Parameters
    ----------
    model : MarkerModel
    observed : ndarray (T, M) bool
        Markers seen in each frame, in time order (earlier rows count as before).

    Returns
    -------
    ndarray (T, 27) bool
    """
    unconstrained = unconstrained_angles(model, observed)
    seen_before = np.logical_or.accumulate(~unconstrained, axis=0)
    return unconstrained & seen_before


@dataclass
class Poses:
    """Pose parameters of T frames (arrays are modified in place by the solver)."""

    transl: np.ndarray  # (T, 3)
    rot: np.ndarray  # (T, 3, 3)
    phi: np.ndarray  # (T, 27)

    def copy(self) -> "Poses":
        """A deep copy (new arrays)."""
        return Poses(self.transl.copy(), self.rot.copy(), self.phi.copy())

    def take(self, index) -> "Poses":
        """The poses of frames ``index`` (fancy indices copy; a slice gives views of these arrays)."""
        return Poses(self.transl[index], self.rot[index], self.phi[index])

    def put(self, index, other: "Poses") -> None:
        """Write ``other`` into frames ``index`` of these arrays, in place.

        Parameters
        ----------
        index : int array, bool mask or slice
            The frames to overwrite, T' of them.
        other : Poses
            T' frames: ``transl`` metres, ``rot`` rotation matrices, ``phi`` radians.
        """
        self.transl[index], self.rot[index], self.phi[index] = other.transl, other.rot, other.phi


def frame_costs(model, poses: Poses, target, observed, held, priors: Priors, scale, free=None, kin=None):
    """Total cost per frame (T,), and the pieces the next step needs.

    Parameters
    ----------
    model : MarkerModel
    poses : Poses
        ``transl`` (T, 3) metres, ``rot`` (T, 3, 3), ``phi`` (T, 27) radians.
    target : ndarray (T, M, 3)
        Observed markers, metres (ignored where not ``observed``).
    observed : ndarray (T, M) bool
    held : ndarray (T, 27) bool
        Held angles (see :func:`prior_terms`).
    priors : Priors
    scale : float
        Scale of the Cauchy loss, metres.
    free : ndarray (T, 27) bool, optional
        Unconstrained angles, for the synergy prior.
    kin : tuple, optional
        :meth:`MarkerModel.kinematics` of ``poses``, when the caller has them (not computed again).

    Returns
    -------
    cost : ndarray (T,)
        Robust marker cost plus half the squared prior residuals, square metres.
    parts : tuple
        ``(kin, resid (T, M, 3) metres, norms (T, M) metres, prior residuals (T, R) metres,
        prior Jacobian (T, R, 27) metres per radian)``; ``kin`` is :meth:`MarkerModel.kinematics`.
    """
    if kin is None:
        kin = model.kinematics(poses.transl, poses.rot, poses.phi)
    x = model.positions(poses.transl, poses.rot, poses.phi, kin=kin)
    resid = np.where(observed[..., None], x - target, 0.0)
    norms = np.linalg.norm(resid, axis=-1)
    r_p, j_p = prior_terms(poses.phi, priors, held, free)
    cost = robust_cost(norms, scale).sum(axis=1) + 0.5 * (r_p**2).sum(axis=1)
    return cost, (kin, resid, norms, r_p, j_p)


def levenberg_marquardt(model, target, observed, poses: Poses, priors: Priors, *, scale: float = 0.005,
                        iterations: int = 10, tolerance: float = 3e-5, gain_tolerance: float = 1e-3, held=None,
                        lam: float = 1e-3, return_parts: bool = False, start_kin=None, tries: int = 0):
    """Fit poses to observed markers, every frame at once.

    Parameters
    ----------
    model : MarkerModel
    target : ndarray (T, M, 3)
        Observed marker positions, metres (ignored where not ``observed``).
    observed : ndarray (T, M) bool
    poses : Poses
        Initial poses; not modified.
    priors : Priors
    scale : float
        Scale of the Cauchy loss, metres: markers much further off than this
        hardly count (see :func:`robust_weights`).
    iterations : int
    tolerance : float
        Stop a frame once its step is shorter than this (metres / radians;
        default 0.03 mm, well below marker noise).
    gain_tolerance : float
        Or once an accepted step lowers its cost by less than this fraction.
    held : ndarray (T, 27) bool, optional
        Angles kept at their initial value (default: :func:`held_angles` of
        these frames). Unconstrained angles not held are set by the priors.
    lam : float
        Initial damping.
    return_parts : bool
        Also return the final poses' pieces (see :func:`frame_costs`: their kinematics and marker residuals), so
        that a caller needs no second forward pass.
    start_kin : tuple, optional
        :meth:`MarkerModel.kinematics` of the initial ``poses`` (a warm start from the poses an earlier call
        returned, with their ``parts[0]``): the first cost then needs no forward pass.
    tries : int
        Steps tried at most: past ``iterations``, a frame goes on only until it has taken a step (one that raised
        the cost is tried again, more damped). Default: ``iterations`` (a rejected step counts as one).

    Returns
    -------
    poses : Poses
    cost : ndarray (T,)
    parts : tuple
        Only with ``return_parts``.
    """
    poses = poses.copy()
    n = len(poses.transl)
    held = held_angles(model, observed) if held is None else held
    free = unconstrained_angles(model, observed) & ~held
    fixed = np.concatenate([np.zeros((n, 6), bool), held], axis=1)
    blind = ~observed.any(axis=1)  # frames without a single marker keep their start
    fixed[blind] = True
    damping = np.full(n, lam)
    active = ~blind
    cost, parts = frame_costs(model, poses, target, observed, held, priors, scale, free, kin=start_kin)
    eye = np.eye(N_PARAMS)
    taken = np.zeros(n, bool)
    for attempt in range(max(tries, iterations)):
        if attempt >= iterations:  # past the iterations: only the frames that have not taken a step
            active &= ~taken
        if not active.any():
            break
        idx = np.flatnonzero(active)
        whole = len(idx) == n  # every frame still active (always so for one frame): no copies of subsets
        kin, resid, norms, r_p, j_p = parts if whole else (
            p[idx] if not isinstance(p, tuple) else tuple(k[idx] for k in p) for p in parts)
        sub = poses if whole else poses.take(idx)
        weights = robust_weights(norms, scale) * observed[idx]  # IRLS: J^T W J and J^T W r
        hess, grad = model.normal_equations(sub.transl, sub.rot, sub.phi, resid, weights, kin=kin)
        hess[:, 6:, 6:] += np.matmul(np.swapaxes(j_p, 1, 2), j_p)
        grad[:, 6:] += np.einsum("trp,tr->tp", j_p, r_p)
        f = fixed[idx]
        hess[f[:, :, None] | f[:, None, :]] = 0.0
        hess += eye * f[:, :, None]
        grad[f] = 0.0
        diag = np.diagonal(hess, axis1=1, axis2=2)
        system = hess + (damping[idx, None] * np.maximum(diag, 1e-9))[:, :, None] * eye
        step = -np.linalg.solve(system, grad[..., None])[..., 0]
        trial = Poses(sub.transl + step[:, :3], matrix_from_axis_angle(step[:, 3:6]) @ sub.rot, sub.phi + step[:, 6:])
        sel = slice(None) if whole else idx  # a slice takes views, the indices copies
        new_cost, new_parts = frame_costs(model, trial, target[sel], observed[sel], held[sel], priors, scale,
                                          free[sel])
        better = new_cost <= cost[idx]
        good = idx[better]
        gain = (cost[idx] - new_cost) / np.maximum(cost[idx], 1e-300)
        poses.put(good, trial.take(better))
        cost[good] = new_cost[better]
        taken[good] = True
        parts = new_parts if whole and better.all() else _merge(parts, new_parts, idx, better)
        damping[good] = np.maximum(damping[good] / 3.0, 1e-7)
        damping[idx[~better]] *= 4.0
        # Done when the step is tiny, or an accepted step gained less than gain_tolerance of the cost
        # (a rejected one raises the damping and tries a shorter step).
        converged = (np.abs(step).max(axis=1) < tolerance) | (better & (gain < gain_tolerance))
        active[idx[converged]] = False
        active[idx[damping[idx] > 1e8]] = False
    return (poses, cost, parts) if return_parts else (poses, cost)


def _merge(parts, new_parts, idx, better):
    """Copy the accepted frames' cached pieces into the full-batch cache."""
    out = []
    for old, new in zip(parts, new_parts):
        if isinstance(old, tuple):
            merged = tuple(_put(o, n, idx, better) for o, n in zip(old, new))
            out.append(merged)
        else:
            out.append(_put(old, new, idx, better))
    return tuple(out)


def _put(old, new, idx, better):
    old = old.copy()
    old[idx[better]] = new[better]
    return old
