"""Smoothing of solved motion (DexterCap Appendix D).

A zero-phase Butterworth low-pass (``scipy.signal.butter`` + ``sosfiltfilt``:
forward and backward, so no lag) on translations and joint angles. Rotations
are filtered without flips: each frame's global orientation becomes a rotation
vector relative to a running reference (its tangent space, where nearby
rotations are nearly Euclidean), the vectors are filtered, and the result is
mapped back.
"""

from __future__ import annotations

import numpy as np
from scipy.signal import butter, sosfiltfilt
from scipy.spatial.transform import Rotation

from handcap.core.checks import check_cutoff
from handcap.core.errors import HandcapError
from handcap.core.motion import HandMotion, ObjectMotion
from handcap.hand import OpenHand


def lowpass(values, rate: float, cutoff: float = 5.0, order: int = 2) -> np.ndarray:
    """Zero-phase Butterworth low-pass along axis 0.

    Parameters
    ----------
    values : ndarray (T, ...)
        Samples at ``rate`` Hz; NaN runs are left as they are (each finite run
        is filtered on its own).
    rate : float
        Hz.
    cutoff : float
        -3 dB frequency of the one-way filter, Hz (default 5 Hz, DexterCap's
        choice at 20 Hz capture).
    order : int
        Butterworth order of the one-way filter (default 2).

    Returns
    -------
    ndarray, same shape
    """
    check_cutoff(cutoff, rate, order)
    values = np.asarray(values, dtype=np.float64)
    sos = butter(order, cutoff, btype="low", fs=rate, output="sos")
    flat = values.reshape(len(values), -1)
    out = flat.copy()
    finite = np.isfinite(flat).all(axis=1)
    edges = np.flatnonzero(np.diff(np.r_[0, finite.astype(int), 0]))
    for start, stop in zip(edges[0::2], edges[1::2]):
        run = flat[start:stop]
        # sosfiltfilt pads by 3 * (2 * sections + 1) samples; shorter runs stay as they are.
        if len(run) > 3 * (2 * len(sos) + 1):
            out[start:stop] = sosfiltfilt(sos, run, axis=0)
    return out.reshape(values.shape)


def smooth_rotations(rotvecs, rate: float, cutoff: float = 5.0, order: int = 2) -> np.ndarray:
    """Low-pass a sequence of rotations (T, 3) axis-angle without sign flips or wrap jumps.

    Each rotation is expressed relative to the previous one (increments are
    small, far from the 180-degree wrap), the increments are accumulated into a
    continuous rotation-vector path relative to the first frame, filtered, and
    mapped back.

    Parameters
    ----------
    rotvecs : array_like (T, 3)
        Axis-angle vectors, radians, finite (T >= 1).
    rate : float
        Frames per second.
    cutoff : float
        -3 dB frequency of the one-way filter, Hz.
    order : int
        Butterworth order of the one-way filter.

    Returns
    -------
    ndarray (T, 3)
        Axis-angle vectors, radians.
    """
    rotvecs = np.asarray(rotvecs, dtype=np.float64)
    rots = Rotation.from_rotvec(rotvecs)
    ref = rots[0]
    # Unwrap: compose frame-to-frame increments so the path in the tangent space is continuous.
    steps = (rots[:-1].inv() * rots[1:]).as_rotvec()
    path = np.zeros_like(rotvecs)
    current = Rotation.identity()
    for t, step in enumerate(steps, start=1):
        current = current * Rotation.from_rotvec(step)
        path[t] = current.as_rotvec()
    smoothed = lowpass(_continuous(path), rate, cutoff, order)
    return (ref * Rotation.from_rotvec(smoothed)).as_rotvec()


def _continuous(path) -> np.ndarray:
    """Rotation vectors with the 2-pi jumps of the axis-angle wrap removed."""
    out = path.copy()
    for t in range(1, len(out)):
        angle = np.linalg.norm(out[t])
        prev = out[t - 1]
        if angle < 1e-6:  # near a whole turn the axis is undefined: keep the previous one
            norm = np.linalg.norm(prev)
            if norm > 0:
                axis = prev / norm
                out[t] = out[t] + axis * 2 * np.pi * np.round(norm / (2 * np.pi))
            continue
        axis = out[t] / angle
        # Of the equivalent vectors axis * (angle + 2 pi k), take the one closest to the previous.
        k = np.round((prev @ axis - angle) / (2 * np.pi))
        out[t] = axis * (angle + 2 * np.pi * k)
    return out


def smooth_hand_motion(motion: HandMotion, hand=None, *, cutoff: float = 5.0, order: int = 2) -> HandMotion:
    """A hand motion low-passed: translation, global orientation and the 27 anatomical angles.

    ``hand_pose`` is rebuilt from the filtered angles (filtering axis-angle
    vectors directly would not give anatomical motion) and the joints are
    recomputed with ``hand``; ``warnings`` are carried over (a smoothed implausible fit is still one), while
    ``marker_names``, ``marker_fit`` and ``marker_residuals`` (of the unsmoothed poses) are not.

    Parameters
    ----------
    motion : HandMotion
        With ``phi`` (radians); ``transl`` in metres.
    hand : HandModel, optional
        The motion's model; an :class:`~handcap.hand.OpenHand` of its side by default
        (required for a MANO motion).
    cutoff : float
        -3 dB frequency of the one-way filter, Hz.
    order : int
        Butterworth order of the one-way filter.

    Returns
    -------
    HandMotion
        Same frames and rate; radians and metres.

    Raises
    ------
    HandcapError
        No ``phi``, a MANO motion without ``hand``, or a cutoff at or above the Nyquist frequency.
    """
    if motion.phi is None:
        raise HandcapError("smoothing needs the anatomical angles phi of the motion")
    transl = lowpass(motion.transl, motion.rate, cutoff, order)
    orient = smooth_rotations(motion.global_orient, motion.rate, cutoff, order)
    phi = lowpass(motion.phi, motion.rate, cutoff, order)
    if hand is None:
        if motion.model != "openhand":
            raise HandcapError("pass the hand model to smooth a MANO motion")
        hand = OpenHand(motion.side)
    hand_pose = hand.hand_pose_from_phi(phi)
    joints = hand.forward(motion.betas, orient, hand_pose, transl, vertices=False).joints
    return HandMotion(motion.betas, orient, hand_pose, transl, motion.rate, motion.side, phi, motion.model, joints,
                      warnings=motion.warnings)


def smooth_object_motion(motion: ObjectMotion, *, cutoff: float = 5.0, order: int = 2) -> ObjectMotion:
    """An object motion low-passed (translation and rotation); unsolved (NaN) frames stay NaN.

    Each run of solved frames is filtered on its own; runs too short to filter are kept as they
    are. ``warnings`` are carried over.

    Parameters
    ----------
    motion : ObjectMotion
        Rotation axis-angle in radians, translation in metres.
    cutoff : float
        -3 dB frequency of the one-way filter, Hz.
    order : int
        Butterworth order of the one-way filter.

    Returns
    -------
    ObjectMotion
        Same frames, rate, name, markers, canonical shape, state and warnings.
    """
    ok = np.isfinite(motion.rotation).all(axis=1)
    rotation = np.full_like(motion.rotation, np.nan)
    translation = lowpass(motion.translation, motion.rate, cutoff, order)
    edges = np.flatnonzero(np.diff(np.r_[0, ok.astype(int), 0]))
    for start, stop in zip(edges[0::2], edges[1::2]):
        if stop - start > 3 * (2 * ((order + 1) // 2) + 1):
            rotation[start:stop] = smooth_rotations(motion.rotation[start:stop], motion.rate, cutoff, order)
        else:
            rotation[start:stop] = motion.rotation[start:stop]
    return ObjectMotion(rotation, translation, motion.rate, motion.name, motion.marker_names, motion.canonical,
                        motion.state, warnings=motion.warnings)
