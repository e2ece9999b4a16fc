"""Hand and object motion containers: ``HandMotion`` and ``ObjectMotion``."""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from handcap.core.errors import HandcapError, merge_warnings
from handcap.core.checks import check_rate
from handcap.core.rotations import matrix_from_axis_angle

SIDES = ("right", "left")


def check_side(side: str) -> str:
    """Return ``side`` if it is ``"right"`` or ``"left"``."""
    if side not in SIDES:
        raise HandcapError(f"side must be 'right' or 'left', got {side!r}")
    return side


def _frames_array(value, name: str, width: tuple[int, ...], n_frames: int | None) -> np.ndarray:
    value = np.asarray(value, dtype=np.float64)
    if value.ndim != 1 + len(width) or value.shape[1:] != width:
        raise HandcapError(f"{name} must have shape (T, {', '.join(map(str, width))}), got {value.shape}")
    if n_frames is not None and value.shape[0] != n_frames:
        raise HandcapError(f"{name} has {value.shape[0]} frames, expected {n_frames}")
    value = value.copy()
    return value


@dataclass(frozen=True, eq=False)
class HandMotion:
    """Hand motion in MANO's parameter layout.

    Parameters
    ----------
    betas : ndarray of shape (10,)
        Shape values (fixed over the take).
    global_orient : ndarray of shape (T, 3)
        Axis-angle of the wrist in the world, radians.
    hand_pose : ndarray of shape (T, 45)
        Axis-angle of the 15 finger joints relative to the flat hand (MANO order).
    transl : ndarray of shape (T, 3)
        Translation in metres.
    rate : float
        Frames per second.
    side : {"right", "left"}
    phi : ndarray of shape (T, 27), optional
        The same pose as anatomical angles (radians), see :mod:`handcap.hand.anatomy`.
    model : str
        ``"openhand"`` or ``"mano"``: which hand model the parameters belong to.
    joints : ndarray of shape (T, 21, 3), optional
        Joint positions in metres (16 MANO joints, then the tips of thumb,
        index, middle, ring, pinky).
    marker_names : tuple of str, optional
    marker_fit : ndarray of shape (T, M, 3), optional
        Model-predicted marker positions in metres.
    marker_residuals : ndarray of shape (T, M), optional
        Distance between fitted and observed markers, metres (NaN where unobserved).
    warnings : tuple of str
        One-line warnings about the result (large residuals, shape at its bounds, ...),
        stored in the motion file.
    """

    betas: np.ndarray
    global_orient: np.ndarray
    hand_pose: np.ndarray
    transl: np.ndarray
    rate: float
    side: str = "right"
    phi: np.ndarray | None = None
    model: str = "openhand"
    joints: np.ndarray | None = None
    marker_names: tuple[str, ...] = field(default=())
    marker_fit: np.ndarray | None = None
    marker_residuals: np.ndarray | None = None
    warnings: tuple[str, ...] = field(default=())

    def __post_init__(self):
        betas = np.asarray(self.betas, dtype=np.float64).copy()
        if betas.shape != (10,):
            raise HandcapError(f"betas must have shape (10,), got {betas.shape}")
        orient = _frames_array(self.global_orient, "global_orient", (3,), None)
        n = orient.shape[0]
        set_ = lambda k, v: object.__setattr__(self, k, v)  # noqa: E731 - frozen dataclass
        set_("betas", betas)
        set_("global_orient", orient)
        set_("hand_pose", _frames_array(self.hand_pose, "hand_pose", (45,), n))
        set_("transl", _frames_array(self.transl, "transl", (3,), n))
        set_("rate", check_rate(self.rate))
        set_("side", check_side(self.side))
        if self.phi is not None:
            set_("phi", _frames_array(self.phi, "phi", (27,), n))
        if self.joints is not None:
            set_("joints", _frames_array(self.joints, "joints", (21, 3), n))
        names = tuple(str(m) for m in self.marker_names)
        set_("marker_names", names)
        if self.marker_fit is not None:
            set_("marker_fit", _frames_array(self.marker_fit, "marker_fit", (len(names), 3), n))
        if self.marker_residuals is not None:
            set_("marker_residuals", _frames_array(self.marker_residuals, "marker_residuals", (len(names),), n))
        set_("warnings", merge_warnings(self.warnings))

    def with_warnings(self, *messages) -> "HandMotion":
        """The same motion with ``messages`` (one-line strings) added to its warnings."""
        return replace(self, warnings=merge_warnings(self.warnings, messages))

    @property
    def n_frames(self) -> int:
        """Number of frames T."""
        return self.global_orient.shape[0]

    def __len__(self) -> int:
        return self.n_frames

    def __repr__(self) -> str:
        return f"HandMotion({self.side} {self.model}, {self.n_frames} frames at {self.rate:g} Hz)"

    def summary(self) -> str:
        """One line: frames, rate, and the marker error of the fit (when it has residuals)."""
        line = f"{self.n_frames} frames at {self.rate:g} Hz ({self.side} hand, {self.model})"
        r = self.marker_residuals
        if r is not None and np.isfinite(r).any():
            line += f", MRE {1000 * np.nanmean(r):.2f} ± {1000 * np.nanstd(r):.2f} mm"
        return line

    def frames(self, start: int = 0, stop: int | None = None) -> "HandMotion":
        """Frames ``start:stop`` of the motion.

        Parameters
        ----------
        start : int
            First frame kept (frame index; Python slice semantics).
        stop : int, optional
            Frame index one past the last kept; None for the end.

        Returns
        -------
        HandMotion
            Every per-frame array cut to the T' frames kept; ``betas``, rate, names and warnings unchanged.
        """
        sl = slice(start, stop)
        pick = lambda a: None if a is None else a[sl]  # noqa: E731
        return HandMotion(self.betas, self.global_orient[sl], self.hand_pose[sl], self.transl[sl],
                          self.rate, self.side, pick(self.phi), self.model, pick(self.joints),
                          self.marker_names, pick(self.marker_fit), pick(self.marker_residuals), self.warnings)


@dataclass(frozen=True, eq=False)
class ObjectMotion:
    """6-DoF motion of a rigid object.

    Parameters
    ----------
    rotation : ndarray of shape (T, 3)
        Axis-angle, object frame to world, radians.
    translation : ndarray of shape (T, 3)
        Object origin in the world, metres.
    rate : float
    name : str
    marker_names : tuple of str
    canonical : ndarray of shape (M, 3), optional
        Marker positions in the object frame, metres.
    state : dict of str to ndarray, optional
        Articulation state per frame for articulated objects (e.g. a 2x2x2 cube's
        layer angles), each array with T rows.
    warnings : tuple of str
        One-line warnings about the result, stored in the object file.
    """

    rotation: np.ndarray
    translation: np.ndarray
    rate: float
    name: str = "object"
    marker_names: tuple[str, ...] = field(default=())
    canonical: np.ndarray | None = None
    state: dict = field(default_factory=dict)
    warnings: tuple[str, ...] = field(default=())

    def __post_init__(self):
        rotation = _frames_array(self.rotation, "rotation", (3,), None)
        n = rotation.shape[0]
        object.__setattr__(self, "rotation", rotation)
        object.__setattr__(self, "translation", _frames_array(self.translation, "translation", (3,), n))
        object.__setattr__(self, "rate", check_rate(self.rate))
        names = tuple(str(m) for m in self.marker_names)
        object.__setattr__(self, "marker_names", names)
        if self.canonical is not None:
            canonical = np.asarray(self.canonical, dtype=np.float64).copy()
            if canonical.shape != (len(names), 3):
                raise HandcapError(f"canonical must have shape ({len(names)}, 3), got {canonical.shape}")
            object.__setattr__(self, "canonical", canonical)
        state = {}
        for key, value in dict(self.state).items():
            value = np.asarray(value)
            if value.shape[:1] != (n,):
                raise HandcapError(f"object state {key!r} must have {n} rows, got shape {value.shape}")
            state[str(key)] = value
        object.__setattr__(self, "state", state)
        object.__setattr__(self, "warnings", merge_warnings(self.warnings))

    def with_warnings(self, *messages) -> "ObjectMotion":
        """The same motion with ``messages`` (one-line strings) added to its warnings."""
        return replace(self, warnings=merge_warnings(self.warnings, messages))

    def summary(self) -> str:
        """One line: name, frames, rate and how many frames hold a pose."""
        solved = int(np.isfinite(self.translation).all(axis=1).sum()) if self.translation.size else 0
        return f"{self.name}: {self.n_frames} frames at {self.rate:g} Hz, {solved} with a pose"

    @property
    def n_frames(self) -> int:
        """Number of frames T."""
        return self.rotation.shape[0]

    def __len__(self) -> int:
        return self.n_frames

    def matrices(self) -> np.ndarray:
        """Homogeneous object-to-world transforms, shape (T, 4, 4)."""
        out = np.zeros((self.n_frames, 4, 4))
        out[:, :3, :3] = matrix_from_axis_angle(self.rotation)
        out[:, :3, 3] = self.translation
        out[:, 3, 3] = 1.0
        return out

    def transform_points(self, points) -> np.ndarray:
        """Object-frame points (N, 3) moved into the world, shape (T, N, 3)."""
        points = np.asarray(points, dtype=np.float64)
        rot = matrix_from_axis_angle(self.rotation)
        return np.einsum("tij,nj->tni", rot, points) + self.translation[:, None, :]
