"""The hand-model interface shared by :class:`OpenHand` and :class:`ManoHand`.

A hand model loads its data once; :meth:`HandModel.forward` reads as numbered
steps that call the pure functions of :mod:`handcap.hand.kinematics`. Inputs
may be numpy arrays (float64 results) or torch tensors (differentiable, in the
inputs' dtype and device); the same code runs for both.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass
from functools import cached_property

import numpy as np
from array_api_compat import array_namespace, is_torch_array

from handcap.core.errors import HandcapError
from handcap.hand import anatomy
from handcap.hand.kinematics import (
    attached_points,
    chain_transforms,
    linear_blend_skinning,
    pose_rotations,
    skinning_transforms,
)


#: Shapes whose rest pose a hand model keeps (see :meth:`HandModel.rest`).
REST_SHAPES_KEPT = 8


@dataclass(frozen=True)
class HandOutput:
    """Result of :meth:`HandModel.forward`.

    Attributes
    ----------
    joints : array (..., 21, 3)
        Metres: 16 MANO joints, then the tips of thumb, index, middle, ring, pinky.
    vertices : array (..., V, 3) or None
        Skinned mesh in metres (None when ``vertices=False`` was asked).
    rotations : array (..., 16, 3, 3)
        World orientation of every joint's segment.
    """

    joints: object
    vertices: object
    rotations: object


class HandModel(ABC):
    """Base class: subclasses provide the rest shape; posing is shared.

    Subclasses set ``name``, ``side``, ``faces (F, 3)``, ``weights (V, 16)``,
    ``frames (15, 3, 3)`` and implement :meth:`rest`.
    """

    name: str = "hand"
    side: str = "right"
    faces: np.ndarray
    weights: np.ndarray
    frames: np.ndarray
    parents = anatomy.PARENTS
    joint_names = anatomy.JOINT_NAMES + anatomy.TIP_NAMES
    segment_names = anatomy.SEGMENT_NAMES
    n_betas = 10

    @property
    def is_right(self) -> bool:
        """Whether this is a right-hand model."""
        return self.side == "right"

    @property
    def n_vertices(self) -> int:
        """Number of mesh vertices V."""
        return self.weights.shape[0]

    @cached_property
    def segment_of_vertex(self) -> np.ndarray:
        """Segment id (0 palm, then MANO joint order) of every vertex, (V,)."""
        return np.argmax(self.weights, axis=1)

    def segment_id(self, name: str) -> int:
        """Index of a segment name such as ``"index_proximal"``."""
        try:
            return self.segment_names.index(name)
        except ValueError:
            raise HandcapError(f"unknown hand segment {name!r}; segments are: "
                               f"{', '.join(self.segment_names)}") from None

    def segment_faces(self, name: str) -> np.ndarray:
        """Indices of the triangles whose three vertices belong to segment ``name``."""
        seg = self.segment_of_vertex[self.faces]
        return np.flatnonzero((seg == self.segment_id(name)).all(axis=1))

    # -- to implement --------------------------------------------------------
    @abstractmethod
    def _shape_rest(self, betas):
        """Rest (flat) pose for shape ``betas``: what :meth:`rest` returns, made anew on every call."""

    def pose_corrective(self, rotations):
        """Vertex offsets (..., V, 3) added before skinning (MANO's pose blend shapes), or None."""
        return None

    # -- shared ------------------------------------------------------------
    def rest(self, betas):
        """Rest (flat) pose for shape ``betas``.

        The last few numpy shapes (10,) are remembered, with their results as read-only arrays: a fit that
        calls :meth:`forward` many times with one shape makes its rest mesh once.

        Parameters
        ----------
        betas : array (..., 10)

        Returns
        -------
        vertices : array (..., V, 3)
        joints : array (..., 16, 3)
        tips : array (..., 5, 3)
            Metres.
        """
        if is_torch_array(betas) or np.ndim(betas) != 1:
            return self._shape_rest(betas)
        betas = np.asarray(betas)
        key = (betas.dtype.str, betas.tobytes())
        cache = self.__dict__.setdefault("_rest_cache", {})
        found = cache.get(key)
        if found is None:
            found = tuple(np.array(a) for a in self._shape_rest(betas))
            for a in found:
                a.setflags(write=False)
            if len(cache) >= REST_SHAPES_KEPT:
                cache.clear()
            cache[key] = found
        return found

    def constant(self, value, like):
        """A model array converted to the namespace, dtype and device of ``like``.

        Parameters
        ----------
        value : array_like
            A model array (any shape and unit, kept as they are).
        like : array
            A numpy array or torch tensor whose kind, dtype and device the result takes.

        Returns
        -------
        array
            For numpy, ``value`` as float64 (dtype of ``like`` not used); for torch, a tensor cached per
            model under ``id(value)``, dtype and device.
        """
        if is_torch_array(like):
            import torch
            key = ("_torch_cache", id(value), like.dtype, like.device)
            cache = self.__dict__.setdefault("_torch_cache", {})
            if key not in cache:
                cache[key] = torch.tensor(np.array(value), dtype=like.dtype, device=like.device)
            return cache[key]
        return np.asarray(value, dtype=np.float64)

    def hand_pose_from_phi(self, phi):
        """MANO ``hand_pose`` (..., 45) from anatomical angles (..., 27) of this model."""
        return anatomy.hand_pose_from_phi(phi, self.constant(self.frames, phi))

    def phi_from_hand_pose(self, hand_pose) -> np.ndarray:
        """Anatomical angles (..., 27) from MANO ``hand_pose`` (..., 45), numpy."""
        return anatomy.phi_from_hand_pose(hand_pose, self.frames)

    def forward(self, betas=None, global_orient=None, hand_pose=None, transl=None, *,
                phi=None, vertices: bool = True) -> HandOutput:
        """Posed joints and mesh.

        Parameters
        ----------
        betas : array (10,) or (..., 10), optional
            Shape values; zeros (the average hand) when omitted.
        global_orient : array (..., 3), optional
            Axis-angle of the wrist, radians; zeros when omitted.
        hand_pose : array (..., 45), optional
            MANO finger pose relative to the flat hand; give this or ``phi``.
        transl : array (..., 3), optional
            Metres; zeros when omitted.
        phi : array (..., 27), optional
            Anatomical angles (radians), converted with :meth:`hand_pose_from_phi`.
        vertices : bool
            Skin the mesh (False: joints only, much faster).

        Returns
        -------
        HandOutput
        """
        # 1. Inputs: one namespace (torch if any input is a tensor), one batch shape, defaults filled in.
        like = next((a for a in (betas, global_orient, hand_pose, transl, phi) if is_torch_array(a)), None)
        xp = np if like is None else array_namespace(like)
        global_orient, hand_pose, transl, phi, betas = (
            None if a is None else _as_array(a, like) for a in (global_orient, hand_pose, transl, phi, betas))
        if hand_pose is not None and phi is not None:
            raise HandcapError("give hand_pose or phi, not both")
        batch = _batch_shape({"global_orient": (global_orient, 3), "hand_pose": (hand_pose, 45),
                              "transl": (transl, 3), "phi": (phi, 27)})
        zeros = lambda n: _as_array(np.zeros(batch + (n,)), like)  # noqa: E731
        if betas is None:
            betas = _as_array(np.zeros(10), like)
        if betas.shape[-1] != 10:
            raise HandcapError(f"betas must have 10 values, got shape {tuple(betas.shape)}")
        if phi is not None:
            hand_pose = self.hand_pose_from_phi(phi)
        global_orient = zeros(3) if global_orient is None else global_orient
        hand_pose = zeros(45) if hand_pose is None else hand_pose
        transl = zeros(3) if transl is None else transl

        # 2. Rest shape.
        rest_vertices, rest_joints, rest_tips = self.rest(betas)

        # 3. Joint rotations and forward kinematics.
        rotations = pose_rotations(global_orient, hand_pose)
        world_rot, world_pos = chain_transforms(rotations, rest_joints)
        tips = attached_points(world_rot, world_pos, xp.broadcast_to(rest_joints, batch + (16, 3)),
                               xp.broadcast_to(rest_tips, batch + (5, 3)), anatomy.TIP_PARENTS)
        joints = xp.concat([world_pos, tips], axis=-2) + transl[..., None, :]
        if not vertices:
            return HandOutput(joints, None, world_rot)

        # 4. Linear blend skinning of the (pose-corrected) rest mesh.
        corrective = self.pose_corrective(rotations)
        if corrective is not None:
            rest_vertices = rest_vertices + corrective
        transforms = skinning_transforms(world_rot, world_pos, xp.broadcast_to(rest_joints, batch + (16, 3)))
        verts = linear_blend_skinning(rest_vertices, self.constant(self.weights, betas), transforms)
        return HandOutput(joints, verts + transl[..., None, :], world_rot)

    def rest_joints(self, betas=None) -> np.ndarray:
        """The 21 joints (16 + tips) of the flat hand, (21, 3) metres (numpy)."""
        betas = np.zeros(10) if betas is None else np.asarray(betas, dtype=np.float64)
        _, joints, tips = self.rest(betas)
        return np.concatenate([joints, tips], axis=-2)


def _as_array(value, like):
    """``value`` as an array of the kind of ``like``: numpy float64 when ``like`` is None,
    else a torch tensor of its dtype and device (tensors already so are passed through)."""
    if like is None:
        return np.asarray(value, dtype=np.float64)
    if is_torch_array(value):
        return value.to(dtype=like.dtype, device=like.device)
    import torch
    return torch.as_tensor(np.asarray(value), dtype=like.dtype, device=like.device)


def _batch_shape(arrays: dict) -> tuple:
    batch = None
    for name, (value, width) in arrays.items():
        if value is None:
            continue
        if value.ndim < 1 or value.shape[-1] != width:
            raise HandcapError(f"{name} must have shape (..., {width}), got {tuple(value.shape)}")
        shape = tuple(value.shape[:-1])
        if batch is not None and shape != batch:
            raise HandcapError(f"{name} has batch shape {shape}, others have {batch}")
        batch = shape
    return () if batch is None else batch
