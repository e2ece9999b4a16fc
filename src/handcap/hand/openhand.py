"""OpenHand: the built-in open hand model (no download, no licence restrictions).

Mesh: the right hand of the MakeHuman hm08 base mesh with its skinning
weights, both CC0 1.0 (public domain), re-posed onto an anthropometric flat
hand by ``tools/build_openhand.py`` (see ``data/README.md``). Skeleton: MANO's
16-joint tree and parameter layout, with joint centres from
:mod:`handcap.hand.anthropometry` (Buchholz et al. 1992), not from MANO.

Shape
-----
Ten shape values change the rest hand smoothly: every length or girth factor
is ``exp(sum_k c_k * beta_k)``, with ``c_k`` chosen so one unit is about one
standard deviation of adult variation. ``betas = 0`` is the average adult
hand (hand length 182.5 mm, breadth 81.5 mm).

=====  ===========================================  =======================
beta   what it changes                              factor per unit
=====  ===========================================  =======================
0      overall size (every length and girth)        exp(0.052): HL SD 5.2 %
1      palm breadth                                 exp(0.05)
2      finger length (phalanges of all digits)      exp(0.04)
3      palm length (metacarpals)                    exp(0.04)
4      thickness of palm and fingers                exp(0.06)
5      thumb length (all three thumb segments)      exp(0.05)
6      index vs ring length (2D:4D ratio)           index exp(0.03), ring exp(-0.03)
7      little finger length                         exp(0.05)
8      finger girth (not the palm)                  exp(0.06)
9      middle and distal vs proximal phalanges      exp(0.04) / exp(-0.04)
=====  ===========================================  =======================

The palm is scaled about the wrist along its length (x), thickness (y) and
breadth (z); every finger segment is scaled along its bone by its length
factor and across it by its girth factor, and the mesh follows by blending
these maps with the skinning weights, so joints and surface stay consistent.
"""

from __future__ import annotations

from importlib.resources import files

import numpy as np
from array_api_compat import array_namespace

from handcap.core.errors import HandcapError
from handcap.core.motion import check_side
from handcap.hand import anthropometry
from handcap.hand.anatomy import TIP_PARENTS, joint_frames
from handcap.hand.kinematics import linear_blend_skinning
from handcap.hand.model import HandModel

_FINGER_JOINTS = {"index": (1, 2, 3), "middle": (4, 5, 6), "pinky": (7, 8, 9), "ring": (10, 11, 12),
                  "thumb": (13, 14, 15)}


def _shape_matrices():
    """Log-factor matrices: palm (3, 10), segment length (15, 10), segment girth (15, 10)."""
    palm = np.zeros((3, 10))
    palm[:, 0] = 0.052
    palm[0, 3] = 0.04   # length
    palm[1, 4] = 0.06   # thickness
    palm[2, 1] = 0.05   # breadth
    length = np.zeros((15, 10))
    girth = np.zeros((15, 10))
    length[:, 0] = girth[:, 0] = 0.052
    girth[:, 4] = 0.06
    girth[:, 8] = 0.06
    for finger, (a, b, c) in _FINGER_JOINTS.items():
        rows = np.array([a, b, c]) - 1
        if finger == "thumb":
            length[rows, 5] = 0.05
            length[rows[1:], 2] = 0.04
            continue
        length[rows, 2] = 0.04
        length[rows, 9] = (-0.04, 0.04, 0.04)
        length[rows, 6] = {"index": 0.03, "ring": -0.03}.get(finger, 0.0)
        length[rows, 7] = 0.05 if finger == "pinky" else 0.0
    return palm, length, girth


SHAPE_PALM, SHAPE_LENGTH, SHAPE_GIRTH = _shape_matrices()


class OpenHand(HandModel):
    """The built-in open hand model.

    Parameters
    ----------
    side : {"right", "left"}
        The left hand is the mirror image of the right (z negated, faces flipped).

    Attributes
    ----------
    template_vertices : ndarray (V, 3)
        Flat hand at ``betas = 0``, metres.
    faces : ndarray (F, 3)
        Outward-facing triangles of a closed surface.
    weights : ndarray (V, 16)
        Skinning weights on MANO's joints.
    frames : ndarray (15, 3, 3)
        Anatomical joint frames (see :mod:`handcap.hand.anatomy`).
    """

    name = "openhand"

    def __init__(self, side: str = "right"):
        self.side = check_side(side)
        with files("handcap.hand").joinpath("data/openhand.npz").open("rb") as fh, \
                np.load(fh, allow_pickle=False) as asset:
            vertices = np.array(asset["vertices"], dtype=np.float64)
            faces = np.array(asset["faces"], dtype=np.int64)
            weights = np.array(asset["weights"], dtype=np.float64)
        joints, tips = anthropometry.rest_joints()
        if side == "left":
            mirror = np.array([1.0, 1.0, -1.0])
            vertices, joints, tips = vertices * mirror, joints * mirror, tips * mirror
            faces = faces[:, ::-1]
        for a in (vertices, faces, weights, joints, tips):
            a.setflags(write=False)
        self.template_vertices, self.faces, self.weights = vertices, faces, weights
        self.template_joints, self.template_tips = joints, tips
        self.frames = joint_frames(joints, tips, self.is_right)
        self.frames.setflags(write=False)
        axes = self.frames[:, :, 0]
        # Outer products of the bone axes, for scaling along (x x^T) and across (I - x x^T) bones.
        self._along = axes[:, :, None] * axes[:, None, :]

    def __repr__(self) -> str:
        return f"OpenHand(side={self.side!r}, {self.n_vertices} vertices)"

    def shape_factors(self, betas):
        """Palm scale (..., 3) and segment length and girth factors (..., 15) for ``betas``."""
        xp = array_namespace(betas)
        mat = lambda m: self.constant(m, betas)  # noqa: E731
        palm = xp.exp(xp.matmul(betas, mat(SHAPE_PALM).T))
        length = xp.exp(xp.matmul(betas, mat(SHAPE_LENGTH).T))
        girth = xp.exp(xp.matmul(betas, mat(SHAPE_GIRTH).T))
        return palm, length, girth

    def _shape_rest(self, betas):
        """Rest (flat) pose of the OpenHand for shape ``betas``.

        Parameters
        ----------
        betas : array (..., 10)
            Shape values (numpy, or torch for a differentiable result).

        Returns
        -------
        vertices : array (..., V, 3)
            Metres.
        joints : array (..., 16, 3)
            MANO joints, metres.
        tips : array (..., 5, 3)
            Tips of thumb, index, middle, ring, pinky, metres.
        """
        xp = array_namespace(betas)
        c = lambda a: self.constant(a, betas)  # noqa: E731
        palm, length, girth = self.shape_factors(betas)
        rest_joints, rest_tips = c(self.template_joints), c(self.template_tips)
        # Joints: MCPs (and the thumb CMC) move with the palm; every later joint
        # sits one scaled segment beyond its parent.
        first = np.array([1, 4, 7, 10, 13])
        joints = {0: xp.zeros(betas.shape[:-1] + (3,), dtype=betas.dtype, device=getattr(betas, "device", None))}
        for j in first:
            joints[int(j)] = palm * rest_joints[int(j)]
        for step in (1, 2):
            for j in first + step:
                p = int(j) - 1
                joints[int(j)] = joints[p] + length[..., p - 1, None] * (rest_joints[int(j)] - rest_joints[p])
        tips = [joints[int(p)] + length[..., int(p) - 1, None] * (rest_tips[t] - rest_joints[int(p)])
                for t, p in enumerate(TIP_PARENTS)]
        joints_arr = xp.stack([joints[j] for j in range(16)], axis=-2)
        tips_arr = xp.stack(tips, axis=-2)
        # Per-segment affine maps from the template to this shape, blended over the mesh.
        along = c(self._along)
        eye = c(np.eye(3))
        lin = (length[..., None, None] * along + girth[..., None, None] * (eye - along))  # (..., 15, 3, 3)
        heads = rest_joints[1:]
        trans = joints_arr[..., 1:, :] - xp.sum(lin * heads[:, None, :], axis=-1)
        seg = xp.concat([lin, trans[..., None]], axis=-1)
        palm_map = xp.concat([palm[..., :, None] * eye, xp.zeros_like(palm)[..., None]], axis=-1)
        maps = xp.concat([palm_map[..., None, :, :], seg], axis=-3)
        vertices = linear_blend_skinning(c(self.template_vertices), c(self.weights), maps)
        return vertices, joints_arr, tips_arr

    def measurements(self, betas=None) -> dict:
        """Hand length and breadth (metres) of the rest hand for ``betas`` (numpy).

        Hand length: wrist joint to the middle fingertip. Breadth: the
        anthropometric breadth scaled by the palm's breadth factor.
        """
        betas = np.zeros(10) if betas is None else np.asarray(betas, dtype=np.float64)
        if betas.shape != (10,):
            raise HandcapError(f"betas must have shape (10,), got {betas.shape}")
        _, joints, tips = self.rest(betas)
        palm, _, _ = self.shape_factors(betas)
        return {"hand_length": float(np.linalg.norm(tips[2] - joints[0])),
                "hand_breadth": float(anthropometry.HAND_BREADTH * palm[2])}
