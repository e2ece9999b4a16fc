"""The paper's solver, kept as the baseline: Adam on every frame (DexterCap section 3.4.3).

Per frame, minimise ``E = E_point + lambda_reg E_reg`` (Eq. 2-4) over the
translation, the global orientation in the 6D representation of Zhou et al.
(2019, arXiv:1812.07035) and the 27 anatomical angles, with Adam at learning
rate 0.002 for 400 iterations (1000 for the first frame), each frame starting
from the previous frame's answer. ``lambda_reg`` is the square of handcap's
limit weight, so both solvers minimise the same limit term. Markers missing
together with everything beyond them keep their joints' previous values (the
paper's rule), as in ``lm``. The first frame starts from the same rigid
alignment and relaxed pose as ``lm``, so the two are compared from the same
start.

This runs at a few frames per second; it exists so that ``benchmarks/solve.py``
can measure what ``lm`` gains.
"""

from __future__ import annotations

import numpy as np
import torch
from tqdm import tqdm

from handcap.core.rotations import matrix_from_euler_zyx
from handcap.hand.anatomy import PHI_AXIS, PHI_JOINT
from handcap.hand.kinematics import chain_transforms
from handcap.solve.lm import Poses, unconstrained_angles
from handcap.solve.rigid_start import rigid_start

LEARNING_RATE = 0.002
ITERATIONS = 400
FIRST_ITERATIONS = 1000


def rotation_from_6d(d6):
    """Rotation matrix from the 6D representation (two columns, Gram-Schmidt)."""
    a, b = d6[..., :3], d6[..., 3:]
    x = a / torch.linalg.norm(a, dim=-1, keepdim=True)
    b = b - (x * b).sum(-1, keepdim=True) * x
    y = b / torch.linalg.norm(b, dim=-1, keepdim=True)
    z = torch.linalg.cross(x, y, dim=-1)
    return torch.stack([x, y, z], dim=-1)


class TorchMarkers:
    """Differentiable marker positions of a :class:`~handcap.solve.markers.MarkerModel` (torch, float64)."""

    def __init__(self, model):
        t = lambda a: torch.tensor(np.asarray(a), dtype=torch.float64)  # noqa: E731
        self.model = model
        self.frames = t(model.frames)
        self.rest_joints = t(model.rest_joints)
        self.rest_vertices = t(model.rest_vertices)
        self.vertex_weights = t(model.vertex_weights)
        self.corner_index = torch.as_tensor(model.corner_index)
        self.bary = t(model.attachment.barycentric)
        self.offset = t(model.attachment.offset)
        self.dof_joint = torch.as_tensor(PHI_JOINT - 1)
        self.dof_axis = torch.as_tensor(PHI_AXIS)

    def __call__(self, transl, rot, phi):
        angles = torch.zeros(15, 3, dtype=phi.dtype).index_put((self.dof_joint, self.dof_axis), phi)
        e = matrix_from_euler_zyx(angles[:, 2], angles[:, 1], angles[:, 0])
        local = self.frames @ e @ self.frames.transpose(-1, -2)
        rotations = torch.cat([rot[None], local], dim=0)[None]
        world_rot, world_pos = chain_transforms(rotations, self.rest_joints[None])
        trans = world_pos - (world_rot @ self.rest_joints[None, :, :, None])[..., 0]
        maps = torch.cat([world_rot.reshape(1, 16, 9), trans], dim=-1)[0]
        blended = self.vertex_weights @ maps
        verts = (blended[:, :9].reshape(-1, 3, 3) @ self.rest_vertices[..., None])[..., 0] + blended[:, 9:]
        tri = verts[self.corner_index]
        normal = torch.linalg.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0], dim=-1)
        normal = normal / torch.linalg.norm(normal, dim=-1, keepdim=True)
        return (self.bary[..., None] * tri).sum(1) + self.offset[:, None] * normal + transl


def solve_adam(model, target, observed, priors, *, learning_rate: float = LEARNING_RATE,
               iterations: int = ITERATIONS, first_iterations: int = FIRST_ITERATIONS,
               progress: bool | None = None) -> Poses:
    """Frame-by-frame Adam fit (see the module docstring).

    Parameters
    ----------
    model : MarkerModel
    target : ndarray (T, M, 3)
    observed : ndarray (T, M) bool
    priors : Priors
        Only the limits and their weight are used (the paper has no other prior).

    Returns
    -------
    Poses
    """
    n = len(target)
    markers = TorchMarkers(model)
    rest = priors.rest_phi()
    rot0, trans0, _ = rigid_start(model, target, observed, rest)
    held = unconstrained_angles(model, observed)  # the paper holds every unconstrained angle
    low = torch.tensor(priors.limits[:, 0])
    high = torch.tensor(priors.limits[:, 1])
    lam = priors.limit_weight**2
    out = Poses(trans0.copy(), rot0.copy(), np.tile(rest, (n, 1)))
    transl = torch.tensor(trans0[0])
    d6 = torch.tensor(np.concatenate([rot0[0][:, 0], rot0[0][:, 1]]))
    phi = torch.tensor(rest)
    hidden = None if progress is None else not progress
    threads = torch.get_num_threads()
    torch.set_num_threads(1)  # tensors of a few hundred numbers: threads only add overhead
    try:
        _adam_frames(markers, target, observed, held, out, transl, d6, phi, low, high, lam, learning_rate,
                     iterations, first_iterations, hidden)
    finally:
        torch.set_num_threads(threads)
    return out


def _adam_frames(markers, target, observed, held, out, transl, d6, phi, low, high, lam, learning_rate,
                 iterations, first_iterations, hidden):
    n = len(target)
    for t in tqdm(range(n), desc="solve (adam)", unit="frame", disable=hidden, leave=False):
        seen = np.flatnonzero(observed[t])
        if len(seen) == 0:
            out.put(slice(t, t + 1), out.take(slice(t - 1, t)) if t > 0 else out.take(slice(0, 1)))
            continue
        goal = torch.tensor(target[t, seen])
        keep = torch.tensor(held[t])
        params = [p.detach().clone().requires_grad_(True) for p in (transl, d6, phi)]
        optimiser = torch.optim.Adam(params, lr=learning_rate)
        index = torch.as_tensor(seen)
        for _ in range(first_iterations if t == 0 else iterations):
            optimiser.zero_grad()
            x = markers(params[0], rotation_from_6d(params[1]), params[2])[index]
            violation = torch.clamp(params[2], low, high) - params[2]
            loss = ((x - goal) ** 2).sum() + lam * (violation**2).sum()
            loss.backward()
            params[2].grad[keep] = 0.0  # held joints keep the previous frame's values
            optimiser.step()
        transl, d6, phi = (p.detach() for p in params)
        out.transl[t] = transl.numpy()
        out.rot[t] = rotation_from_6d(d6).numpy()
        out.phi[t] = phi.numpy()
