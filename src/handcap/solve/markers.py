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

Speed: skinning, the barycentric blend, triangle edges and every lever arm are
linear in the 16 segments' affine maps, so each is one matrix product of a
precomputed (rows, 64) matrix with the maps of all frames. The solver asks for
``J^T W J`` and ``J^T W r`` (:meth:`MarkerModel.normal_equations`), built from
the few non-zero entries per marker in single precision, never the dense
(3M x 33) Jacobian; :meth:`MarkerModel.jacobian` remains for checks and users.

This module owns :class:`MarkerModel`. The angle and rotation maths it builds
on is :mod:`handcap.solve.rotation_math`; the rigid initial pose of a take is
:mod:`handcap.solve.rigid_start` (both re-exported here).
"""

from __future__ import annotations

import numpy as np
from scipy.sparse import csr_matrix

from handcap.hand.anatomy import PHI_JOINT
from handcap.hand.kinematics import chain_transforms
from handcap.hand.model import HandModel
from handcap.solve.rigid_start import rigid_start
from handcap.solve.rotation_math import DESCENDANTS, cross, cross0, descendants, dof_axes, local_rotations

# The rotation helpers and rigid_start live in their own modules and are re-exported here for existing callers.
__all__ = ["DESCENDANTS", "MarkerModel", "N_PARAMS", "cross", "cross0", "descendants", "local_rotations",
           "rigid_start"]

N_PARAMS = 33  # translation 3, world rotation increment 3, phi 27


def _affine_columns(world_rot, world_pos, rest_joints) -> np.ndarray:
    """The segments' affine maps ``x -> R_j x + t_j`` as a (64, 3T) matrix: row ``4 j + b``, column ``3 t + a``.

    ``t_j`` moves joint j's rest position to its posed one. A row vector
    ``[w_j x_j, w_j]`` over the 16 segments times this matrix gives the blended
    point ``sum_j w_j (R_j x_j + t_j)`` for every frame at once.
    """
    trans = world_pos - np.einsum("tjab,jb->tja", world_rot, rest_joints)
    maps = np.concatenate([world_rot, trans[..., None]], axis=-1)  # (T, 16, 3, 4)
    return maps.transpose(1, 3, 0, 2).reshape(64, -1)


def _affine_rows(weights, points) -> np.ndarray:
    """Rows (N, 64) ``[w_j p, w_j]`` for points (N, 3) blended by segment weights (N, 16)."""
    aug = np.concatenate([points, np.ones((len(points), 1))], axis=1)  # (N, 4)
    return (weights[:, :, None] * aug[:, None, :]).reshape(len(points), 64)


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
        skin = _affine_rows(self.vertex_weights, self.rest_vertices)[self.corner_index]  # (M, 3 corners, 64)
        # Rows giving the marker's spot on the skin and its triangle's two edges, from the maps.
        self._marker_affine = np.concatenate([np.einsum("mk,mkc->mc", bary, skin), skin[:, 1] - skin[:, 0],
                                              skin[:, 2] - skin[:, 0]])  # (3M, 64)
        self.has_correctives = type(hand).pose_corrective is not HandModel.pose_corrective
        # The Jacobian's sparse structure (_prepare_jacobian) is built on first use (see __getattr__):
        # positions alone, as the shape fit asks for hundreds of times, do not need it.

    #: Attributes made by :meth:`_prepare_jacobian`.
    _JACOBIAN_PARTS = frozenset({"_pair_marker", "_pair_segment", "_lever_joint", "_lever_marker", "_lever_weight",
                                 "_lever_affine", "_entry_lever", "_entry_dof", "_entry_marker", "_entry_flat",
                                 "_entry_to_dof", "_pair_e", "_pair_f", "_pair_to_cell"})

    def __getattr__(self, name):
        # Only called when ``name`` is not set yet: build the Jacobian's structure once, then it is.
        if name in MarkerModel._JACOBIAN_PARTS:
            self._prepare_jacobian()
            return self.__dict__[name]
        raise AttributeError(f"{type(self).__name__!r} object has no attribute {name!r}")

    @property
    def n_markers(self) -> int:
        """Number of markers M."""
        return len(self.rest_markers)

    def kinematics(self, transl, rot, phi):
        """World rotations (T, 16, 3, 3), joint positions (T, 16, 3) and local rotations.

        Parameters
        ----------
        transl : ndarray (T, 3)
            Translation, metres.
        rot : ndarray (T, 3, 3)
            Global orientation (MANO ``global_orient`` as a matrix).
        phi : ndarray (T, 27)
            Anatomical angles, radians.

        Returns
        -------
        world_rot : ndarray (T, 16, 3, 3)
            World rotation of every segment.
        world_pos : ndarray (T, 16, 3)
            Posed joint positions, metres, ``transl`` included.
        rotations : ndarray (T, 16, 3, 3)
            Local rotations: ``rot``, then :func:`local_rotations`.
        """
        local = local_rotations(phi, self.frames)
        rotations = np.concatenate([rot[:, None], local], axis=1)
        world_rot, world_pos = chain_transforms(rotations, self.rest_joints)
        return world_rot, world_pos + transl[:, None], rotations

    def positions(self, transl, rot, phi, *, kin=None) -> np.ndarray:
        """Marker positions (T, M, 3) in metres, exact.

        Parameters
        ----------
        transl : ndarray (T, 3)
            Translation, metres.
        rot : ndarray (T, 3, 3)
            Global orientation.
        phi : ndarray (T, 27)
            Anatomical angles, radians.
        kin : tuple, optional
            :meth:`kinematics` of the same pose, when the caller has it (the pose is then not read).

        Returns
        -------
        ndarray (T, M, 3)
            Metres.
        """
        world_rot, world_pos, rotations = kin if kin is not None else self.kinematics(transl, rot, phi)
        n_frames = len(world_rot)
        if self.has_correctives:  # rest shape changes with the pose: blend the maps, then apply them
            rest = self.rest_vertices + self.hand.pose_corrective(rotations)[:, self.vertex_ids]
            trans = world_pos - np.einsum("tjab,jb->tja", world_rot, self.rest_joints)
            maps = np.concatenate([world_rot.reshape(n_frames, 16, 9), trans], axis=2)  # (T, 16, 12)
            blended = np.matmul(self.vertex_weights, maps)  # (T, K, 12): linear blend skinning
            verts = (blended[..., :9].reshape(n_frames, -1, 3, 3) * rest[..., None, :]).sum(axis=-1) + blended[..., 9:]
            tri = verts[:, self.corner_index]  # (T, M, 3, 3)
            on_skin = np.einsum("mk,tmki->tmi", self.attachment.barycentric, tri)
            edges = tri[:, :, 1:] - tri[:, :, :1]  # (T, M, 2, 3)
        else:  # skinning, barycentric blend and triangle edges are linear in the maps: one product
            columns = _affine_columns(world_rot, world_pos, self.rest_joints)
            parts = (self._marker_affine @ columns).reshape(3, self.n_markers, n_frames, 3)
            on_skin, edges = np.swapaxes(parts[0], 0, 1), parts[1:].transpose(2, 1, 0, 3)  # (T, M, 3), (T, M, 2, 3)
        normal = cross(edges[:, :, 0], edges[:, :, 1])
        normal /= np.linalg.norm(normal, axis=-1, keepdims=True)
        return on_skin + self.attachment.offset[None, :, None] * normal

    def jacobian(self, transl, rot, phi, *, kin=None, out=None) -> np.ndarray:
        """Derivatives (T, 3, M, 33) of marker coordinates by the pose parameters.

        Axis 1 is the coordinate (x, y, z), axis 2 the marker. Columns:
        translation (3), world rotation increment about the wrist (3), then the
        27 anatomical angles. Only the (marker, angle) pairs where the marker
        moves with the angle's joint are computed; the rest are zero. ``out``,
        if given, must hold zeros wherever this structure has none (a buffer
        filled by earlier calls qualifies); it is overwritten and returned.

        Parameters
        ----------
        transl : ndarray (T, 3)
            Translation, metres.
        rot : ndarray (T, 3, 3)
            Global orientation.
        phi : ndarray (T, 27)
            Anatomical angles, radians.
        kin : tuple, optional
            :meth:`kinematics` of the same pose (``transl`` still gives T).
        out : ndarray (T, 3, M, 33), optional
            Buffer to fill.

        Returns
        -------
        ndarray (T, 3, M, 33)
            No unit for the translation columns; metres per radian for the rotation and angle columns.
        """
        world_rot, world_pos, _ = kin if kin is not None else self.kinematics(transl, rot, phi)
        n_frames, m = len(transl), self.n_markers
        lever = self._levers(world_rot, world_pos)
        jac = np.zeros((n_frames, 3, m, N_PARAMS)) if out is None else out
        for a in range(3):
            jac[:, a, :, a] = 1.0
        # Joint 0 carries every marker (rows 0..M-1, in marker order): e_a x r for the world axes.
        rx, ry, rz = (lever[:m, :, a].T for a in range(3))
        jac[:, 1, :, 3], jac[:, 2, :, 3] = -rz, ry
        jac[:, 0, :, 4], jac[:, 2, :, 4] = rz, -rx
        jac[:, 0, :, 5], jac[:, 1, :, 5] = -ry, rx
        flat = jac.reshape(n_frames, 3, m * N_PARAMS)
        flat[:, :, self._entry_flat] = self._angle_columns(phi, world_rot, lever).transpose(2, 0, 1)
        return jac

    def normal_equations(self, transl, rot, phi, resid, weights, *, kin=None,
                         dtype=np.float32) -> tuple[np.ndarray, np.ndarray]:
        """Gauss-Newton matrix ``J^T W J`` (T, 33, 33) and gradient ``J^T W r`` (T, 33), without forming J.

        Equal to the products with :meth:`jacobian` (to rounding), but built
        from the few non-zero entries per marker: the translation columns are
        the identity, the rotation columns ``-[r]x`` (r: the marker from the
        wrist), and each angle column a 3-vector ``g`` for the markers below
        its joint. Cost grows with the number of (marker, angle) entries, not
        with markers x 33.

        Parameters
        ----------
        resid : ndarray (T, M, 3)
            Residuals (model minus observed), metres; zero where unobserved.
        weights : ndarray (T, M)
            Weight of every marker's squared residual (0 where unobserved).
        dtype : numpy dtype
            Working precision (float32 by default: relative error about 1e-6,
            harmless for the step, while costs stay in float64).
        """
        world_rot, world_pos, _ = kin if kin is not None else self.kinematics(transl, rot, phi)
        c = self._constants(dtype)
        # Lever arms are differences of positions (decimetres), so single precision loses nothing
        # a Gauss-Newton step needs, and halves the memory traffic of this, the solver's hot spot.
        world_rot, world_pos = world_rot.astype(dtype, copy=False), world_pos.astype(dtype, copy=False)
        resid, weights = resid.astype(dtype, copy=False), weights.astype(dtype, copy=False)
        n_frames, m = len(transl), self.n_markers
        lever = self._levers(world_rot, world_pos, c)
        r = np.swapaxes(lever[:m], 0, 1)  # (T, M, 3): markers from the wrist joint
        g = self._angle_columns(phi, world_rot, lever)  # (T, E, 3)
        w = weights
        wr = w[..., None] * r
        w_sum, wr_sum = w.sum(axis=1), wr.sum(axis=1)
        hess = np.empty((n_frames, N_PARAMS, N_PARAMS))  # float64: the solve follows
        eye3 = np.eye(3, dtype=dtype)
        hess[:, :3, :3] = w_sum[:, None, None] * eye3
        # J_t^T J_r = -[sum w r]x; J_r^T J_r = sum w (|r|^2 I - r r^T).
        sx, sy, sz = wr_sum[:, 0], wr_sum[:, 1], wr_sum[:, 2]
        zero = np.zeros_like(sx)
        h_tr = np.stack([np.stack([zero, sz, -sy], -1), np.stack([-sz, zero, sx], -1),
                         np.stack([sy, -sx, zero], -1)], -2)
        hess[:, :3, 3:6] = h_tr
        hess[:, 3:6, :3] = np.swapaxes(h_tr, 1, 2)
        rr = np.einsum("tmi,tmj->tij", wr, r)
        hess[:, 3:6, 3:6] = np.trace(rr, axis1=1, axis2=2)[:, None, None] * eye3 - rr
        # Angle columns (3, E, T): J_t^T g = g, J_r^T g = r x g, summed per angle over its entries.
        em = self._entry_marker
        w_e = w.T[em]  # (E, T)
        wg = g * w_e
        r_e = np.moveaxis(lever[em], 2, 0)  # (3, E, T)
        to_dof_t = c.entry_to_dof_t  # (27, E)
        hess[:, :3, 6:] = np.matmul(to_dof_t, wg).transpose(2, 0, 1)
        hess[:, 3:6, 6:] = np.matmul(to_dof_t, cross0(r_e, wg)).transpose(2, 0, 1)
        hess[:, 6:, :6] = np.swapaxes(hess[:, :6, 6:], 1, 2)
        # Angle-angle: g_e . g_f w for the entry pairs that share a marker.
        dots = (wg[:, self._pair_e] * g[:, self._pair_f]).sum(axis=0)  # (pairs, T)
        hess[:, 6:, 6:] = (c.cell_from_pair @ dots).T.reshape(n_frames, 27, 27)
        res_e = resid.T[:, em]  # (3, E, T)
        grad = np.empty((n_frames, N_PARAMS))
        wres = w[..., None] * resid
        grad[:, :3] = wres.sum(axis=1)
        grad[:, 3:6] = cross(r, wres).sum(axis=1)
        grad[:, 6:] = (to_dof_t @ (wg * res_e).sum(axis=0)).T
        return hess, grad

    def _levers(self, world_rot, world_pos, c=None) -> np.ndarray:
        """Lever arm (L, T, 3) of every (joint, marker) pair, rows 0..M-1 being joint 0 (the wrist).

        The lever of joint j and marker m is the blend, over the segments k below
        j, of the marker as carried by k (``R_k x_m + t_k``) less the joint's
        position (``R_j J_j + t_j``): linear in the segments' affine maps, so all
        of them are one product of a precomputed (L, 64) matrix with the maps.
        """
        c = self._constants(world_rot.dtype) if c is None else c
        return (c.lever_affine @ _affine_columns(world_rot, world_pos, c.rest_joints)).reshape(-1, len(world_rot), 3)

    def _angle_columns(self, phi, world_rot, lever) -> np.ndarray:
        """Derivative (3, E, T) of each entry's marker by its angle: the angle's world axis x the lever arm."""
        axes = self.dof_axes(phi, world_rot).T.astype(lever.dtype, copy=False)  # (3, 27, T)
        return cross0(axes[:, self._entry_dof], np.moveaxis(lever[self._entry_lever], 2, 0))

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
        carries = DESCENDANTS[self._lever_joint[:, None], seg[None, :]] * (self._lever_marker[:, None] == mark[None, :])
        values = carries * weights[mark, seg][None, :]
        # Levers as rows over the segments' affine maps: the marker as carried by each segment below
        # the joint, weighted, less the joint's own position (see _levers).
        carried_rows = _affine_rows(np.eye(16)[seg], self.rest_markers[mark])  # (P, 64)
        joint_rows = _affine_rows(np.eye(16)[self._lever_joint], self.rest_joints[self._lever_joint])
        self._lever_affine = values @ carried_rows - self._lever_weight[:, None] * joint_rows  # (L, 64)
        entry_lever, entry_dof = [], []
        for d, j in enumerate(PHI_JOINT):
            rows = np.flatnonzero(self._lever_joint == j)
            entry_lever.append(rows)
            entry_dof.append(np.full(len(rows), d))
        self._entry_lever = np.concatenate(entry_lever)
        self._entry_dof = np.concatenate(entry_dof)
        self._entry_marker = self._lever_marker[self._entry_lever]
        self._entry_flat = self._entry_marker * N_PARAMS + 6 + self._entry_dof
        self._entry_to_dof = np.zeros((len(self._entry_dof), 27))
        self._entry_to_dof[np.arange(len(self._entry_dof)), self._entry_dof] = 1.0
        # Pairs of entries on one marker (e <= f) and the Hessian cells (d_e, d_f), (d_f, d_e) they add to.
        order = np.argsort(self._entry_marker, kind="stable")
        starts = np.searchsorted(self._entry_marker[order], np.arange(self.n_markers + 1))
        pe, pf, upper = [], [], {}  # upper: the triangle's indices by size (markers share a few sizes)
        for a, b in zip(starts[:-1], starts[1:]):
            ids = order[a:b]
            i, j = upper[b - a] if b - a in upper else upper.setdefault(b - a, np.triu_indices(b - a))
            pe.append(ids[i])
            pf.append(ids[j])
        self._pair_e, self._pair_f = np.concatenate(pe), np.concatenate(pf)
        de, df = self._entry_dof[self._pair_e], self._entry_dof[self._pair_f]
        rows = np.r_[np.arange(len(de)), np.flatnonzero(de != df)]
        cells = np.r_[de * 27 + df, (df * 27 + de)[de != df]]
        self._pair_to_cell = csr_matrix((np.ones(len(rows)), (rows, cells)), shape=(len(de), 27 * 27))

    def _constants(self, dtype):
        """The precomputed arrays of the sparse structure in the working precision (cached)."""
        dtype = np.dtype(dtype)
        cache = self.__dict__.setdefault("_by_dtype", {})
        if dtype not in cache:
            from types import SimpleNamespace
            cache[dtype] = SimpleNamespace(
                rest_joints=self.rest_joints.astype(dtype), lever_affine=self._lever_affine.astype(dtype),
                entry_to_dof_t=np.ascontiguousarray(self._entry_to_dof.T, dtype=dtype),
                cell_from_pair=self._pair_to_cell.T.tocsr().astype(dtype))
        return cache[dtype]

    def dof_axes(self, phi, world_rot) -> np.ndarray:
        """World axis (T, 27, 3) of every anatomical angle (intrinsic z-y'-x'' Euler axes).

        :func:`handcap.solve.rotation_math.dof_axes` with this model's joint frames.

        Parameters
        ----------
        phi : ndarray (T, 27)
            Anatomical angles, radians.
        world_rot : ndarray (T, 16, 3, 3)
            World rotations of the segments (:meth:`kinematics`).

        Returns
        -------
        ndarray (T, 27, 3)
            Unit vectors in the world.
        """
        return dof_axes(phi, world_rot, self.frames, self.frame_sign)
