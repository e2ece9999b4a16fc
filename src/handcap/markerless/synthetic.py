"""Synthetic hand keypoints with exact truth: what a 2D detector would give, and what it gets wrong.

The truth is the hand model itself: a generated motion (:func:`handcap.synth.motions.make_motion`) posed on an
OpenHand of random shape, its 21 joints taken as the keypoints (:mod:`~handcap.markerless.keypoints`). The
views add what real detectors do to them, each at a rate the caller sets: pixel noise, keypoints not
given, wrong keypoints (a detector's typical confusion: the position of another keypoint of the same hand),
and left/right labels swapped for a whole hand in a camera and frame.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from handcap.core.errors import HandcapError
from handcap.hand import OpenHand
from handcap.markerless.keypoints import hand_names, keypoints_from_joints
from handcap.multiview.detections import Detections
from handcap.synth.motions import make_motion


@dataclass(frozen=True)
class SyntheticHand:
    """One generated hand and its truth.

    Attributes
    ----------
    side : str
    betas : ndarray (10,)
    phi : ndarray (T, 27)
        Anatomical angles, radians.
    global_orient, transl : ndarray (T, 3)
        Axis-angle and metres.
    keypoints : ndarray (T, 21, 3)
        The true keypoints, metres, keypoint order.
    """

    side: str
    betas: np.ndarray
    phi: np.ndarray
    global_orient: np.ndarray
    transl: np.ndarray
    keypoints: np.ndarray


def synthetic_hand(n_frames: int, rate: float, rng, *, side: str = "right", motion: str = "random",
                   offset=(0.0, 0.0, 0.0), shape_sd: float = 1.0) -> SyntheticHand:
    """A hand moving as ``motion``, of a random shape, and its true keypoints.

    Parameters
    ----------
    n_frames : int
    rate : float
        Frames per second.
    rng : numpy.random.Generator
    side : {"right", "left"}
    motion : str
        One of :data:`handcap.synth.motions.MOTIONS` without an object.
    offset : (3,) float
        Added to the hand's translation, metres (to set two hands apart).
    shape_sd : float
        Standard deviation of the shape values.

    Returns
    -------
    SyntheticHand
    """
    hand = OpenHand(side)
    betas = np.clip(rng.normal(0.0, shape_sd, 10), -2.5, 2.5)
    m = make_motion(motion, hand, n_frames, rate, rng)
    transl = m.transl + np.asarray(offset, dtype=np.float64)
    joints = hand.forward(betas, m.global_orient, None, transl, phi=m.phi, vertices=False).joints
    return SyntheticHand(side, betas, m.phi, m.global_orient, transl, keypoints_from_joints(joints))


def view_keypoints(rig, hands: dict, *, rate: float = 30.0, noise_px: float = 1.0, missing: float = 0.0,
                   wrong: float = 0.0, swap: float = 0.0, rng=None) -> tuple[Detections, np.ndarray]:
    """What a 2D keypoint detector gives in every camera of ``rig`` for the hands' true keypoints.

    Parameters
    ----------
    rig : CameraRig
    hands : dict of str to ndarray (T, 21, 3)
        True keypoints of each hand, metres, by label (``"left"``, ``"right"``).
    rate : float
        Frames per second.
    noise_px : float
        Standard deviation of the Gaussian pixel noise.
    missing : float
        Share of keypoints not given.
    wrong : float
        Share of keypoints given at the place of another keypoint of the same hand (plus noise).
    swap : float
        Share of camera-frames whose hand labels are exchanged (with one label, it changes to the other of
        ``left``/``right``).
    rng : numpy.random.Generator, optional

    Returns
    -------
    detections : Detections
        Marker names ``LABEL:keypoint``; keypoints outside an image are not given.
    true_hand : ndarray (N,) str
        The label of the hand each row really belongs to.
    """
    rng = np.random.default_rng(0) if rng is None else rng
    labels = sorted(hands)
    if not labels:
        raise HandcapError("give at least one hand")
    other = {"left": "right", "right": "left"}
    names = sorted({lab for lab in labels} | ({other.get(labels[0], labels[0])} if len(labels) == 1 else set()))
    n_frames = len(next(iter(hands.values())))
    n_cams = len(rig)
    flips = rng.random((n_frames, n_cams)) < swap
    frame, camera, marker, xy, truth = [], [], [], [], []
    for label in labels:
        points = np.asarray(hands[label], dtype=np.float64)
        pixels, depth = rig.project(points.reshape(-1, 3))
        pixels = pixels.reshape(n_cams, n_frames, 21, 2) + rng.normal(0.0, noise_px, (n_cams, n_frames, 21, 2))
        bad = rng.random((n_cams, n_frames, 21)) < wrong
        source = (np.arange(21) + rng.integers(1, 21, (n_cams, n_frames, 21))) % 21
        moved = np.take_along_axis(pixels, source[..., None], axis=2)
        pixels = np.where(bad[..., None], moved, pixels)
        seen = rig.in_image(pixels.reshape(n_cams, -1, 2)).reshape(n_cams, n_frames, 21)
        seen &= depth.reshape(n_cams, n_frames, 21) > 0
        seen &= rng.random(seen.shape) >= missing
        c, t, k = np.nonzero(seen)
        given = np.where(flips[t, c], np.array([other.get(label, label)]), np.array([label]))
        if len(labels) > 1:  # two hands: a flip exchanges the two labels
            given = np.where(flips[t, c], [lab for lab in labels if lab != label][0], label)
        marker.append(np.array([names.index(g) for g in given]) * 21 + k)
        frame.append(t)
        camera.append(c)
        xy.append(pixels[c, t, k])
        truth.append(np.full(len(t), label))
    marker_names = tuple(n for name in names for n in hand_names(name))
    detections = Detections(rig.names, marker_names, np.concatenate(frame), np.concatenate(camera),
                            np.concatenate(marker), np.concatenate(xy), np.ones(sum(len(f) for f in frame)), rate,
                            n_frames, source="synthetic keypoints")
    return detections, np.concatenate(truth)
