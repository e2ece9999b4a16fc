"""Attached markers as a function of hand pose: positions and an analytic Jacobian.

The pose of a frame is ``transl (3,)``, a rotation matrix ``rot (3, 3)`` (the
MANO ``global_orient``) and the anatomical angles ``phi (27,)``. Everything is
batched over frames: arrays carry a leading T.

Positions are exact: the three vertices of each marker's triangle are skinned
(linear blend skinning, plus MANO's pose blend shapes when the model has them)
and the marker is placed by its barycentric coordinates and its offset along
the posed triangle's normal (Eq. 1 of DexterCap). Only the vertices that
markers use are skinned, not the whole mesh.

The Jacobian treats each marker as a skinned point with its triangle's blended
weights: turning joint j by a small world rotation ``w`` moves the part of the
marker carried by segment k (k below j in the tree) by ``w x (y_k - p_j)``.
On the rigid parts of the hand, where markers sit, this is the exact
derivative; in blend zones it is a close approximation, which Gauss-Newton
tolerates because the residuals themselves are exact.
"""

from __future__ import annotations

import numpy as np

from handcap.hand.anatomy import PARENTS, PHI_AXIS, PHI_JOINT
from handcap.hand.kinematics import chain_transforms
from handcap.hand.model import HandModel

N_PARAMS = 33  # translation 3, world rotation increment 3, phi 27


def descendants() -> np.ndarray:
    """(16, 16) matrix: entry [j, k] is 1 when segment k moves with joint j (k = j included)."""
    out = np.eye(16)
    for k in range(1, 16):
        j = PARENTS[k]
        while j >= 0:
            out[j, k] = 1.0
            j = PARENTS[j]
    return out


DESCENDANTS = descendants()


def skew(v) -> np.ndarray:
    """Cross-product matrices (..., 3, 3) of vectors (..., 3): ``skew(a) @ b == a x b``."""
    v = np.asarray(v)
    z = np.zeros(v.shape[:-1])
    return np.stack([np.stack([z, -v[..., 2], v[..., 1]], -1),
                     np.stack([v[..., 2], z, -v[..., 0]], -1),
                     np.stack([-v[..., 1], v[..., 0], z], -1)], -2)


def local_rotations(phi, frames) -> np.ndarray:
    """Joint rotations ``C E(phi) C^T`` (T, 15, 3, 3) from anatomical angles (T, 27)."""
    angles = np.zeros(phi.shape[:-1] + (15, 3))
    angles[..., PHI_JOINT - 1, PHI_AXIS] = phi
    ct, cs, cb = (np.cos(angles[..., i]) for i in range(3))
    st, ss, sb = (np.sin(angles[..., i]) for i in range(3))
    # Rz(bend) Ry(spread) Rx(twist) written out (handcap.core.rotations.matrix_from_euler_zyx).
    e = np.empty(phi.shape[:-1] + (15, 3, 3))
    e[..., 0, 0], e[..., 0, 1], e[..., 0, 2] = cb * cs, cb * ss * st - sb * ct, cb * ss * ct + sb * st
    e[..., 1, 0], e[..., 1, 1], e[..., 1, 2] = sb * cs, sb * ss * st + cb * ct, sb * ss * ct - cb * st
    e[..., 2, 0], e[..., 2, 1], e[..., 2, 2] = -ss, cs * st, cs * ct
    return frames @ e @ np.swapaxes(frames, -1, -2)


def _cross_columns(axes, lever):
    """``axes[k] x lever[k]`` for every marker: axes (T, K, 3), lever (T, 3, M) or (T, K, 3, M) -> (T, K, 3, M)."""
    if lever.ndim == 3:
        lever = lever[:, None]
    ax, ay, az = (axes[..., i, None] for i in range(3))
    lx, ly, lz = lever[:, :, 0], lever[:, :, 1], lever[:, :, 2]
    return np.stack([ay * lz - az * ly, az * lx - ax * lz, ax * ly - ay * lx], axis=2)


class MarkerModel:
    """Markers of an attachment on a hand model, batched over frames.

    Parameters
    ----------
    hand : HandModel
    attachment : MarkerAttachment
    betas : ndarray (10,), optional
        Shape; the attachment's by default.
    """

    def __init__(self, hand, attachment, betas=None):
        self.hand = hand
        self.attachment = attachment
        self.betas = np.asarray(attachment.betas if betas is None else betas, dtype=np.float64)
        rest_vertices, rest_joints, _ = hand.rest(self.betas)
        corners = hand.faces[attachment.triangles]  # (M, 3) vertex ids
        self.vertex_ids, inverse = np.unique(corners, return_inverse=True)
        self.corner_index = inverse.reshape(corners.shape)
        self.rest_vertices = rest_vertices[self.vertex_ids]
        self.vertex_weights = hand.weights[self.vertex_ids]
        self.rest_joints = rest_joints
        self.frames = np.asarray(hand.frames)
        self.frame_sign = np.sign(np.linalg.det(self.frames))
        bary = attachment.barycentric
        tri = rest_vertices[corners]
        normal = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        normal /= np.linalg.norm(normal, axis=1, keepdims=True)
        self.rest_markers = np.einsum("mk,mki->mi", bary, tri) + attachment.offset[:, None] * normal
        self.marker_weights = np.einsum("mk,mkj->mj", bary, hand.weights[corners])  # (M, 16)
        self._weights_below = self.marker_weights @ DESCENDANTS.T  # [m, j]: weight carried by joints below j
        self.has_correctives = type(hand).pose_corrective is not HandModel.pose_corrective
        self._prepare_jacobian()

    @property
    def n_markers(self) -> int:
        return len(self.rest_markers)

    def kinematics(self, transl, rot, phi):
        """World rotations (T, 16, 3, 3), joint positions (T, 16, 3) and local rotations."""
        local = local_rotations(phi, self.frames)
        rotations = np.concatenate([rot[:, None], local], axis=1)
        world_rot, world_pos = chain_transforms(rotations, self.rest_joints)
        return world_rot, world_pos + transl[:, None], rotations

    def positions(self, transl, rot, phi, *, kin=None) -> np.ndarray:
        """Marker positions (T, M, 3) in metres, exact."""
        world_rot, world_pos, rotations = kin if kin is not None else self.kinematics(transl, rot, phi)
        rest = self.rest_vertices
        if self.has_correctives:
            rest = rest + self.hand.pose_corrective(rotations)[:, self.vertex_ids]
        n_frames = len(world_rot)
        trans = world_pos - np.einsum("tjab,jb->tja", world_rot, self.rest_joints)
        maps = np.concatenate([world_rot.reshape(n_frames, 16, 9), trans], axis=2)  # (T, 16, 12)
        blended = np.matmul(self.vertex_weights, maps)  # (T, K, 12): linear blend skinning
        verts = (blended[..., :9].reshape(n_frames, -1, 3, 3) @ rest[..., None])[..., 0] + blended[..., 9:]
        tri = verts[:, self.corner_index]  # (T, M, 3, 3)
        normal = np.cross(tri[:, :, 1] - tri[:, :, 0], tri[:, :, 2] - tri[:, :, 0])
        normal /= np.linalg.norm(normal, axis=-1, keepdims=True)
        on_skin = np.einsum("mk,tmki->tmi", self.attachment.barycentric, tri)
        return on_skin + self.attachment.offset[None, :, None] * normal

    def jacobian(self, transl, rot, phi, *, kin=None, out=None) -> np.ndarray:
        """Derivatives (T, 3, M, 33) of marker coordinates by the pose parameters.

        Axis 1 is the coordinate (x, y, z), axis 2 the marker. Columns:
        translation (3), world rotation increment about the wrist (3), then the
        27 anatomical angles. Only the (marker, angle) pairs where the marker
        moves with the angle's joint are computed; the rest are zero. ``out``,
        if given, must hold zeros wherever this structure has none (a buffer
        filled by earlier calls qualifies); it is overwritten and returned.
        """
        world_rot, world_pos, _ = kin if kin is not None else self.kinematics(transl, rot, phi)
        n_frames, m = len(transl), self.n_markers
        trans = world_pos - np.einsum("tjab,jb->tja", world_rot, self.rest_joints)
        # The marker as carried by each segment it is skinned to: (P, T, 3) for the P (marker, segment) pairs.
        seg, mark = self._pair_segment, self._pair_marker
        carried = np.einsum("tpab,pb->pta", world_rot[:, seg], self.rest_markers[mark]) + np.swapaxes(trans[:, seg], 0, 1)
        # Lever arm of every (joint, marker) pair: weighted sum over the segments below the joint.
        lever = (self._lever_matrix @ carried.reshape(len(seg), -1)).reshape(-1, n_frames, 3)
        lever -= self._lever_weight[:, None, None] * np.swapaxes(world_pos[:, self._lever_joint], 0, 1)
        jac = np.zeros((n_frames, 3, m, N_PARAMS)) if out is None else out
        for a in range(3):
            jac[:, a, :, a] = 1.0
        # Joint 0 carries every marker (rows 0..M-1, in marker order): e_a x r for the world axes.
        rx, ry, rz = (lever[:m, :, a].T for a in range(3))
        jac[:, 1, :, 3], jac[:, 2, :, 3] = -rz, ry
        jac[:, 0, :, 4], jac[:, 2, :, 4] = rz, -rx
        jac[:, 0, :, 5], jac[:, 1, :, 5] = -ry, rx
        axes = self.dof_axes(phi, world_rot)  # (T, 27, 3)
        cols = axes[:, self._entry_dof]  # (T, E, 3)
        arms = np.swapaxes(lever[self._entry_lever], 0, 1)  # (T, E, 3)
        flat = jac.reshape(n_frames, 3, m * N_PARAMS)
        flat[:, :, self._entry_flat] = np.swapaxes(np.cross(cols, arms), 1, 2)
        return jac

    def _prepare_jacobian(self) -> None:
        """Sparse structure: (marker, segment) pairs, (joint, marker) levers, (lever, angle) entries."""
        weights = self.marker_weights
        mark, seg = np.nonzero(weights > 1e-9)
        self._pair_marker, self._pair_segment = mark, seg
        below = self._weights_below > 1e-9  # (M, 16)
        below[:, 0] = True
        joints, markers = [], []
        for j in range(16):
            ms = np.flatnonzero(below[:, j])
            joints.append(np.full(len(ms), j))
            markers.append(ms)
        self._lever_joint = np.concatenate(joints)
        self._lever_marker = np.concatenate(markers)
        self._lever_weight = self._weights_below[self._lever_marker, self._lever_joint]
        from scipy.sparse import csr_matrix
        carries = DESCENDANTS[self._lever_joint[:, None], seg[None, :]] * (self._lever_marker[:, None] == mark[None, :])
        values = carries * weights[mark, seg][None, :]
        self._lever_matrix = csr_matrix(values)
        entry_lever, entry_dof = [], []
        for d, j in enumerate(PHI_JOINT):
            rows = np.flatnonzero(self._lever_joint == j)
            entry_lever.append(rows)
            entry_dof.append(np.full(len(rows), d))
        self._entry_lever = np.concatenate(entry_lever)
        self._entry_dof = np.concatenate(entry_dof)
        self._entry_marker = self._lever_marker[self._entry_lever]
        self._entry_flat = self._entry_marker * N_PARAMS + 6 + self._entry_dof

    def dof_axes(self, phi, world_rot) -> np.ndarray:
        """World axis (T, 27, 3) of every anatomical angle (intrinsic z-y'-x'' Euler axes)."""
        angles = np.zeros(phi.shape[:-1] + (15, 3))
        angles[..., PHI_JOINT - 1, PHI_AXIS] = phi
        bend, spread = angles[..., 2], angles[..., 1]
        cb, sb, cs, ss = np.cos(bend), np.sin(bend), np.cos(spread), np.sin(spread)
        zero, one = np.zeros_like(bend), np.ones_like(bend)
        # Axes in the E frame: bend about z, spread about Rz(b) y, twist about Rz(b) Ry(s) x.
        local = np.stack([np.stack([cb * cs, sb * cs, -ss], -1),          # twist
                          np.stack([-sb, cb, zero], -1),                  # spread
                          np.stack([zero, zero, one], -1)], -2)           # bend
        # Into the parent's frame (mirrored frames turn the axis round), then the world.
        in_parent = np.einsum("jab,tjkb->tjka", self.frames, local) * self.frame_sign[None, :, None, None]
        parent_rot = world_rot[:, PARENTS[1:]]  # (T, 15, 3, 3)
        world = np.einsum("tjab,tjkb->tjka", parent_rot, in_parent)  # (T, 15, 3 dofs, 3)
        return world[:, PHI_JOINT - 1, PHI_AXIS]
