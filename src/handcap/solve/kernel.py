"""Levenberg-Marquardt iterations for one frame, compiled with numba (extra 'stream').

:func:`handcap.solve.lm.levenberg_marquardt` is written for whole takes: each of its numpy operations covers
every frame at once, and on one frame those operations' own overhead is most of the time (about 1.3 ms of a
1.4 ms step on the 2-core VM). The live stream solves one frame at a time, and so does
:func:`handcap.solve.motion.solve_lm` (its key frames one after the other, then each frame between them from
its neighbours), so this module does the same iterations for a single frame in compiled loops: the same forward
kinematics (``C E(phi) C^T`` joint
rotations down the tree), the same exact marker positions (skin spot from the segments' affine maps, plus the
offset along the triangle's normal), the same Cauchy-weighted Gauss-Newton matrix from the same Jacobian (the
translation, ``e x r`` for the wrist's rotation, ``axis x lever`` for each angle), the same anatomical priors
and the same damping schedule. It works in double precision throughout (the batch solver builds its normal
equations in single precision), so the two agree to rounding; a test compares them step by step.

Only models without pose correctives (the OpenHand) are compiled; :class:`FrameKernel` says so with
``available`` and the callers use the batch code otherwise, or where numba is not installed. The first use on
a machine compiles the loops (16 s on the 2-core VM); numba keeps them in its cache, and a process then loads
them in about 0.6 s. The loops are written element by element, without numba's array expressions, slice
assignments or ``@``: each of those took seconds to compile (34 s in all before).
"""

from __future__ import annotations

import math

import numpy as np

from handcap.hand.anatomy import PARENTS, PHI_AXIS, PHI_JOINT, TIP_PARENTS
from handcap.solve.lm import COUPLED, SYNERGY, unconstrained_angles
from handcap.solve.markers import MarkerModel

from handcap.core.compiled import AVAILABLE as NUMBA
from handcap.core.compiled import njit as _njit


@_njit
def _mat3(a, b, out):
    for i in range(3):
        for j in range(3):
            out[i, j] = a[i, 0] * b[0, j] + a[i, 1] * b[1, j] + a[i, 2] * b[2, j]


@_njit
def _mat3t(a, b, out):
    """``out = a @ b.T`` for 3 x 3 matrices."""
    for i in range(3):
        for j in range(3):
            out[i, j] = a[i, 0] * b[j, 0] + a[i, 1] * b[j, 1] + a[i, 2] * b[j, 2]


@_njit
def _matvec(a, x, y, z):
    """``a @ (x, y, z)`` for a 3 x 3 matrix: a new (3,) array."""
    out = np.empty(3)
    for i in range(3):
        out[i] = a[i, 0] * x + a[i, 1] * y + a[i, 2] * z
    return out


@_njit
def _matmul(a, b):
    """``a @ b`` written as loops: numba's BLAS-backed ``@`` takes many seconds to compile, these loops none."""
    out = np.zeros((a.shape[0], b.shape[1]))
    for i in range(a.shape[0]):
        for k in range(a.shape[1]):
            aik = a[i, k]
            if aik != 0.0:
                for j in range(b.shape[1]):
                    out[i, j] += aik * b[k, j]
    return out


@_njit
def _solve_linear(hess, grad, lam):
    """The step ``-(H + lam diag(max(H_pp, 1e-9)))^-1 g`` (N,), by Gaussian elimination with partial pivoting."""
    n = grad.shape[0]
    a, x = np.empty((n, n)), np.empty(n)
    for r in range(n):
        x[r] = -grad[r]
        for k in range(n):
            a[r, k] = hess[r, k]
        a[r, r] += lam * max(hess[r, r], 1e-9)
    for c in range(n):
        pivot = c
        for r in range(c + 1, n):
            if abs(a[r, c]) > abs(a[pivot, c]):
                pivot = r
        if pivot != c:
            for k in range(n):
                a[c, k], a[pivot, k] = a[pivot, k], a[c, k]
            x[c], x[pivot] = x[pivot], x[c]
        for r in range(c + 1, n):
            f = a[r, c] / a[c, c]
            if f != 0.0:
                for k in range(c, n):
                    a[r, k] -= f * a[c, k]
                x[r] -= f * x[c]
    for c in range(n - 1, -1, -1):
        t = x[c]
        for k in range(c + 1, n):
            t -= a[c, k] * x[k]
        x[c] = t / a[c, c]
    return x


@_njit
def _kinematics(transl, rot, phi, mc):
    """World rotations (16, 3, 3), joint positions (16, 3) with the translation, and the angles (15, 3)."""
    frames, rest, parents, phi_joint, phi_axis = mc[0], mc[1], mc[2], mc[3], mc[4]
    angles = np.zeros((15, 3))
    for d in range(phi.shape[0]):
        angles[phi_joint[d] - 1, phi_axis[d]] = phi[d]
    world_rot, world_pos = np.empty((16, 3, 3)), np.empty((16, 3))
    for a in range(3):  # element by element: numba's array expressions take seconds each to compile
        world_pos[0, a] = rest[0, a]
        for b in range(3):
            world_rot[0, a, b] = rot[a, b]
    e, ce, local = np.empty((3, 3)), np.empty((3, 3)), np.empty((3, 3))
    for j in range(1, 16):
        ct, st = math.cos(angles[j - 1, 0]), math.sin(angles[j - 1, 0])
        cs, ss = math.cos(angles[j - 1, 1]), math.sin(angles[j - 1, 1])
        cb, sb = math.cos(angles[j - 1, 2]), math.sin(angles[j - 1, 2])
        # Rz(bend) Ry(spread) Rx(twist), as handcap.solve.rotation_math.local_rotations
        e[0, 0], e[0, 1], e[0, 2] = cb * cs, cb * ss * st - sb * ct, cb * ss * ct + sb * st
        e[1, 0], e[1, 1], e[1, 2] = sb * cs, sb * ss * st + cb * ct, sb * ss * ct - cb * st
        e[2, 0], e[2, 1], e[2, 2] = -ss, cs * st, cs * ct
        _mat3(frames[j - 1], e, ce)
        _mat3t(ce, frames[j - 1], local)
        p = parents[j]
        _mat3(world_rot[p], local, world_rot[j])
        lever = _matvec(world_rot[p], rest[j, 0] - rest[p, 0], rest[j, 1] - rest[p, 1], rest[j, 2] - rest[p, 2])
        for a in range(3):
            world_pos[j, a] = world_pos[p, a] + lever[a]
    for j in range(16):
        for a in range(3):
            world_pos[j, a] += transl[a]
    return world_rot, world_pos, angles


@_njit
def _columns(world_rot, world_pos, rest):
    """The segments' affine maps as a (64, 3) matrix, row ``4 j + b`` (see ``markers._affine_columns``)."""
    out = np.empty((64, 3))
    for j in range(16):
        for a in range(3):
            t = world_pos[j, a]
            for b in range(3):
                out[4 * j + b, a] = world_rot[j, a, b]
                t -= world_rot[j, a, b] * rest[j, b]
            out[4 * j + 3, a] = t
    return out


@_njit
def _priors(phi, held, free, pc):
    """Residuals (R,) and Jacobian (R, 27) of the priors, as ``handcap.solve.lm.prior_terms`` for one frame."""
    limits, limit_w, coupling, coupling_w, synergy, synergy_w, relaxed, rest_w, coupled, syn, seen_coupling_w = pc
    n_c, n_s = coupled.shape[0], syn.shape[0]
    r, jac = np.zeros(54 + n_c + n_s), np.zeros((54 + n_c + n_s, 27))
    for d in range(27):
        low, high, v = limits[d, 0], limits[d, 1], phi[d]
        r[d] = limit_w * (min(max(v, low), high) - v)
        if v < low or v > high:
            jac[d, d] = -limit_w
    for i in range(n_c):
        dip, pip = coupled[i, 0], coupled[i, 1]
        if not (held[dip] or held[pip]):
            w = coupling_w if free[dip] else seen_coupling_w
            r[27 + i] = w * (phi[dip] - coupling * phi[pip])
            jac[27 + i, dip], jac[27 + i, pip] = w, -w * coupling
    for i in range(n_s):
        distal, mcp = syn[i, 0], syn[i, 1]
        if free[distal] and not held[mcp]:
            r[27 + n_c + i] = synergy_w * (phi[distal] - synergy * phi[mcp])
            jac[27 + n_c + i, distal], jac[27 + n_c + i, mcp] = synergy_w, -synergy_w * synergy
    base = 27 + n_c + n_s
    for d in range(27):
        if not held[d]:
            r[base + d] = rest_w * (phi[d] - relaxed[d])
            jac[base + d, d] = rest_w
    return r, jac


@_njit
def _evaluate(transl, rot, phi, target, observed, held, free, scale, mc, pc):
    """The cost of a pose and the pieces of its Gauss-Newton step (see ``lm.frame_costs``)."""
    world_rot, world_pos, angles = _kinematics(transl, rot, phi, mc)
    cols = _columns(world_rot, world_pos, mc[1])
    marker_affine, offset = mc[5], mc[6]
    m = offset.shape[0]
    parts = _matmul(marker_affine, cols)  # (3M, 3): skin spots, then the triangles' two edges
    resid, norms = np.zeros((m, 3)), np.zeros(m)
    cost = 0.0
    for i in range(m):
        if not observed[i]:
            continue
        e1, e2 = parts[m + i], parts[2 * m + i]
        n0, n1, n2 = e1[1] * e2[2] - e1[2] * e2[1], e1[2] * e2[0] - e1[0] * e2[2], e1[0] * e2[1] - e1[1] * e2[0]
        length = math.sqrt(n0 * n0 + n1 * n1 + n2 * n2)
        resid[i, 0] = parts[i, 0] + offset[i] * n0 / length - target[i, 0]
        resid[i, 1] = parts[i, 1] + offset[i] * n1 / length - target[i, 1]
        resid[i, 2] = parts[i, 2] + offset[i] * n2 / length - target[i, 2]
        norms[i] = math.sqrt(resid[i, 0] ** 2 + resid[i, 1] ** 2 + resid[i, 2] ** 2)
        cost += 0.5 * scale * scale * math.log1p((norms[i] / scale) ** 2)
    r_p, j_p = _priors(phi, held, free, pc)
    for k in range(r_p.shape[0]):
        cost += 0.5 * r_p[k] * r_p[k]
    return cost, world_rot, world_pos, angles, cols, resid, norms, r_p, j_p


@_njit
def _normal_equations(world_rot, angles, cols, resid, weights, mc):
    """``J^T W J`` (33, 33) and ``J^T W r`` (33,) from the dense (3M, 33) Jacobian of the markers."""
    frames, parents, phi_joint, phi_axis = mc[0], mc[2], mc[3], mc[4]
    lever_affine, entry_lever, entry_dof, entry_marker, frame_sign = mc[7], mc[8], mc[9], mc[10], mc[11]
    m = resid.shape[0]
    lever = _matmul(lever_affine, cols)  # (L, 3): rows 0..M-1 are the markers from the wrist
    axes, local = np.empty((27, 3)), np.zeros(3)
    for d in range(27):  # each angle's world axis (see rotation_math.dof_axes)
        j, a = phi_joint[d], phi_axis[d]
        cb, sb = math.cos(angles[j - 1, 2]), math.sin(angles[j - 1, 2])
        cs, ss = math.cos(angles[j - 1, 1]), math.sin(angles[j - 1, 1])
        if a == 0:
            local[0], local[1], local[2] = cb * cs, sb * cs, -ss
        elif a == 1:
            local[0], local[1], local[2] = -sb, cb, 0.0
        else:
            local[0], local[1], local[2] = 0.0, 0.0, 1.0
        f = _matvec(frames[j - 1], frame_sign[j - 1] * local[0], frame_sign[j - 1] * local[1],
                    frame_sign[j - 1] * local[2])
        axis = _matvec(world_rot[parents[j]], f[0], f[1], f[2])
        axes[d, 0], axes[d, 1], axes[d, 2] = axis[0], axis[1], axis[2]
    jac = np.zeros((3 * m, 33))
    for i in range(m):
        rx, ry, rz = lever[i, 0], lever[i, 1], lever[i, 2]
        for a in range(3):
            jac[3 * i + a, a] = 1.0
        jac[3 * i + 1, 3], jac[3 * i + 2, 3] = -rz, ry  # e_x x r
        jac[3 * i, 4], jac[3 * i + 2, 4] = rz, -rx  # e_y x r
        jac[3 * i, 5], jac[3 * i + 1, 5] = -ry, rx  # e_z x r
    for k in range(entry_dof.shape[0]):  # axis x lever for the markers below each angle's joint
        d, lv, i = entry_dof[k], entry_lever[k], entry_marker[k]
        ax, ay, az = axes[d, 0], axes[d, 1], axes[d, 2]
        lx, ly, lz = lever[lv, 0], lever[lv, 1], lever[lv, 2]
        jac[3 * i, 6 + d], jac[3 * i + 1, 6 + d], jac[3 * i + 2, 6 + d] = ay * lz - az * ly, az * lx - ax * lz, \
            ax * ly - ay * lx
    hess, grad = np.zeros((33, 33)), np.zeros(33)
    for row in range(3 * m):
        w = weights[row // 3]
        if w == 0.0:
            continue
        rv = w * resid[row // 3, row % 3]
        for p in range(33):
            jp = jac[row, p]
            if jp == 0.0:
                continue
            grad[p] += jp * rv
            wjp = w * jp
            for q in range(p, 33):
                hess[p, q] += wjp * jac[row, q]
    for p in range(33):
        for q in range(p):
            hess[p, q] = hess[q, p]
    return hess, grad


@_njit
def _rodrigues(v):
    theta_sq = v[0] * v[0] + v[1] * v[1] + v[2] * v[2]
    if theta_sq < 1e-12:
        a, b = 1.0 - theta_sq / 6.0, 0.5 - theta_sq / 24.0
    else:
        theta = math.sqrt(theta_sq)
        a, b = math.sin(theta) / theta, (1.0 - math.cos(theta)) / theta_sq
    c = 1.0 - b * theta_sq
    x, y, z = v[0], v[1], v[2]
    out = np.empty((3, 3))
    out[0, 0], out[0, 1], out[0, 2] = c + b * x * x, b * x * y - a * z, b * x * z + a * y
    out[1, 0], out[1, 1], out[1, 2] = b * x * y + a * z, c + b * y * y, b * y * z - a * x
    out[2, 0], out[2, 1], out[2, 2] = b * x * z - a * y, b * y * z + a * x, c + b * z * z
    return out


@_njit
def _solve(transl, rot, phi, target, observed, held, free, scale, lam, iterations, tries, tolerance, gain_tolerance,
           mc, pc, rest_tips, tip_parents):
    state = _evaluate(transl, rot, phi, target, observed, held, free, scale, mc, pc)
    accepted = 0
    for attempt in range(max(tries, iterations)):
        if attempt >= iterations and accepted:  # past the iterations: only until a step is taken
            break
        cost, world_rot, world_pos, angles, cols, resid, norms, r_p, j_p = state
        weights = np.zeros(norms.shape[0])
        for i in range(norms.shape[0]):
            if observed[i]:
                weights[i] = 1.0 / (1.0 + (norms[i] / scale) ** 2)  # Cauchy IRLS
        hess, grad = _normal_equations(world_rot, angles, cols, resid, weights, mc)
        for r in range(j_p.shape[0]):  # the priors: J_p^T J_p and J_p^T r_p
            for p in range(27):
                jp = j_p[r, p]
                if jp != 0.0:
                    grad[6 + p] += jp * r_p[r]
                    for q in range(27):
                        hess[6 + p, 6 + q] += jp * j_p[r, q]
        for d in range(27):
            if held[d]:
                for p in range(33):
                    hess[6 + d, p] = 0.0
                    hess[p, 6 + d] = 0.0
                hess[6 + d, 6 + d] = 1.0
                grad[6 + d] = 0.0
        step = _solve_linear(hess, grad, lam)
        new_rot = np.empty((3, 3))
        _mat3(_rodrigues(step[3:6]), rot, new_rot)
        new_transl, new_phi = np.empty(3), np.empty(27)
        for a in range(3):
            new_transl[a] = transl[a] + step[a]
        for d in range(27):
            new_phi[d] = phi[d] + step[6 + d]
        trial = _evaluate(new_transl, new_rot, new_phi, target, observed, held, free, scale, mc, pc)
        better = trial[0] <= cost
        if better:
            gain = (cost - trial[0]) / max(cost, 1e-300)
            transl, rot, phi, state = new_transl, new_rot, new_phi, trial
            lam = max(lam / 3.0, 1e-7)
            accepted += 1
        else:
            lam *= 4.0
        largest = 0.0
        for p in range(33):
            largest = max(largest, abs(step[p]))
        if largest < tolerance or (better and gain < gain_tolerance) or lam > 1e8:
            break
    world_rot, world_pos = state[1], state[2]
    joints = np.empty((21, 3))
    for j in range(16):
        for a in range(3):
            joints[j, a] = world_pos[j, a]
    rest = mc[1]
    for k in range(tip_parents.shape[0]):
        p = tip_parents[k]
        tip = _matvec(world_rot[p], rest_tips[k, 0] - rest[p, 0], rest_tips[k, 1] - rest[p, 1],
                      rest_tips[k, 2] - rest[p, 2])
        for a in range(3):
            joints[16 + k, a] = world_pos[p, a] + tip[a]
    return transl, rot, phi, joints, state[6]


class FrameKernel:
    """Compiled Levenberg-Marquardt iterations of one frame for a marker model (see the module docstring).

    Parameters
    ----------
    model : MarkerModel
    priors : Priors
    rest_tips : ndarray (5, 3), optional
        The fingertips at rest in the model's shape, metres (default ``model.hand.rest(model.betas)[2]``).

    Attributes
    ----------
    available : bool
        numba is installed, and the model is a :class:`~handcap.solve.markers.MarkerModel` with its own marker
        positions and normal equations and no pose correctives: :meth:`solve` may be called.
    """

    def __init__(self, model, priors, rest_tips=None):
        self.model = model
        same = isinstance(model, MarkerModel) and all(getattr(type(model), name) is getattr(MarkerModel, name)
                                                      for name in ("kinematics", "positions", "normal_equations"))
        self.available = NUMBA and same and not model.has_correctives
        if not self.available:
            return
        if rest_tips is None:
            rest_tips = model.hand.rest(model.betas)[2]
        self.mc = (np.ascontiguousarray(model.frames, dtype=np.float64), np.ascontiguousarray(model.rest_joints),
                   PARENTS.astype(np.int64), PHI_JOINT.astype(np.int64), PHI_AXIS.astype(np.int64),
                   np.ascontiguousarray(model._marker_affine), np.ascontiguousarray(model.attachment.offset,
                                                                                    dtype=np.float64),
                   np.ascontiguousarray(model._lever_affine), model._entry_lever.astype(np.int64),
                   model._entry_dof.astype(np.int64), model._entry_marker.astype(np.int64),
                   np.asarray(model.frame_sign, dtype=np.float64))
        self.pc = (np.ascontiguousarray(priors.limits, dtype=np.float64), float(priors.limit_weight),
                   float(priors.coupling), float(priors.coupling_weight), float(priors.synergy),
                   float(priors.synergy_weight), np.ascontiguousarray(priors.rest_phi()), float(priors.rest_weight),
                   COUPLED.astype(np.int64), SYNERGY.astype(np.int64), float(priors.seen_coupling_weight))
        self.rest_tips = np.ascontiguousarray(rest_tips, dtype=np.float64)
        self.tip_parents = TIP_PARENTS.astype(np.int64)

    def solve(self, transl, rot, phi, target, observed, *, scale: float, iterations: int, held=None,
              lam: float = 1e-3, tolerance: float = 3e-5, gain_tolerance: float = 1e-3, rest=None,
              rest_weight: float | None = None, tries: int = 0):
        """Iterate from a pose, as :func:`~handcap.solve.lm.levenberg_marquardt` does for one frame.

        Parameters
        ----------
        transl : ndarray (3,)
            Metres.
        rot : ndarray (3, 3)
            Global orientation.
        phi : ndarray (27,)
            Radians.
        target : ndarray (M, 3)
            The markers, metres (any value where not observed).
        observed : ndarray (M,) bool
        scale : float
            Cauchy scale, metres.
        iterations : int
        held : ndarray (27,) bool, optional
            Angles kept at their value (default none: a frame solved alone has no earlier frame that
            constrained them, see :func:`~handcap.solve.lm.held_angles`).
        lam, tolerance, gain_tolerance : float
            As :func:`~handcap.solve.lm.levenberg_marquardt`.
        tries : int
            Steps tried at most: past ``iterations``, until one is taken (a step that raised the cost is tried
            again, more damped). Default: ``iterations`` (a rejected step counts as one).
        rest, rest_weight : ndarray (27,) and float, optional
            Another target (radians) and weight (metres per radian) of the priors' weak pull for this solve
            (default the priors': :class:`~handcap.solve.lm.Priors`).

        Returns
        -------
        transl (3,), rot (3, 3), phi (27,)
            The pose reached (metres, rotation, radians).
        joints : ndarray (21, 3)
            Its joints and fingertips, metres.
        norms : ndarray (M,)
            Its marker residuals, metres (0 where not observed).
        """
        observed = np.ascontiguousarray(observed, dtype=np.bool_)
        held = np.zeros(27, dtype=np.bool_) if held is None else np.ascontiguousarray(held, dtype=np.bool_)
        free = unconstrained_angles(self.model, observed[None])[0] & ~held
        return _solve(np.asarray(transl, dtype=np.float64), np.ascontiguousarray(rot, dtype=np.float64),
                      np.asarray(phi, dtype=np.float64), np.ascontiguousarray(target, dtype=np.float64), observed,
                      held, free, float(scale), float(lam), int(iterations), int(tries), float(tolerance),
                      float(gain_tolerance),
                      self.mc, self._pulled(rest, rest_weight), self.rest_tips, self.tip_parents)

    def _pulled(self, rest, rest_weight) -> tuple:
        """The priors' constants with another target and weight of the weak pull."""
        if rest is None and rest_weight is None:
            return self.pc
        pc = list(self.pc)
        if rest is not None:
            pc[6] = np.ascontiguousarray(rest, dtype=np.float64)
        if rest_weight is not None:
            pc[7] = float(rest_weight)
        return tuple(pc)
