"""Fingers that do not pass through each other: the clearance between neighbouring fingers' bones.

Random key poses drawn finger by finger (:func:`handcap.synth.motions.natural_pose`: each finger's
flexion and spread drawn on its own) can put two neighbouring fingers in one place: in ``random`` takes of
the average hand, 22 % of the frames had the bone axes of two neighbouring long fingers under 12 mm apart,
14 % under 10 mm, and some 0.3 mm (one finger through the other). Real fingers are 14-18 mm thick; the
tightest closure of any other motion, the fist of ``open-close``, brings them to 12.4 mm. A labeler tested on
such takes meets markers of two fingers on one spot, which no hand makes.

:func:`finger_clearance` measures the least distance between the bones (the segments between joints) of
each pair of neighbouring long fingers; :func:`clear_keys` draws key poses again where the motion through
them comes closer than :data:`FINGER_CLEARANCE`.
"""

from __future__ import annotations

import numpy as np

#: Least distance between the bone axes of neighbouring long fingers, metres: the fist of ``open-close`` (the
#: tightest closure of the motions whose poses are not drawn at random) keeps 12.4 mm.
FINGER_CLEARANCE = 0.012
#: Draws of one key before it is kept as it is; rounds of drawing again the keys around frames still too close.
ATTEMPTS, ROUNDS = 50, 10
#: Poses checked on the straight way between two keys.
STEPS = 8
#: Joints of each long finger from its MCP to its tip (16 MANO joints, then the tips of thumb, index, middle,
#: ring and pinky), in order across the hand.
_CHAINS = ((1, 2, 3, 17), (4, 5, 6, 18), (10, 11, 12, 19), (7, 8, 9, 20))
#: The bones compared (end joints of one, end joints of the other; 24 pairs): every bone of a finger against
#: every bone of its neighbour, but for the two proximal phalanges, which the palm holds apart.
_BONE_PAIRS = np.array([(a[i], a[i + 1], b[k], b[k + 1]) for a, b in zip(_CHAINS[:-1], _CHAINS[1:])
                        for i in range(3) for k in range(3) if i or k]).T


def segment_distance(p0, p1, q0, q1) -> np.ndarray:
    """Least distance between segments ``p0-p1`` and ``q0-q1`` (arrays (..., 3)), elementwise.

    Parameters
    ----------
    p0, p1, q0, q1 : ndarray (..., 3)
        End points, metres.

    Returns
    -------
    ndarray (...)
        Metres.
    """
    d1, d2, r = p1 - p0, q1 - q0, p0 - q0

    def dot(x, y):  # over the last axis of length 3, faster than a reduction over it
        return x[..., 0] * y[..., 0] + x[..., 1] * y[..., 1] + x[..., 2] * y[..., 2]

    a, e, b, c, f = dot(d1, d1), dot(d2, d2), dot(d1, d2), dot(d1, r), dot(d2, r)
    denom = a * e - b * b
    with np.errstate(divide="ignore", invalid="ignore"):
        s = np.where(denom > 1e-18, np.clip((b * f - c * e) / denom, 0.0, 1.0), 0.0)
        t = (b * s + f) / np.maximum(e, 1e-18)
        # t outside [0, 1]: clamp it and find s again
        t_c = np.clip(t, 0.0, 1.0)
        s = np.where(t != t_c, np.clip((b * t_c - c) / np.maximum(a, 1e-18), 0.0, 1.0), s)
    closest = (p0 + s[..., None] * d1) - (q0 + t_c[..., None] * d2)
    return np.linalg.norm(closest, axis=-1)


def finger_clearance(joints) -> np.ndarray:
    """Least distance between the bones of neighbouring long fingers in each frame.

    Every bone of a finger against every bone of its neighbour, but for the two proximal phalanges, which
    the palm holds apart.

    Parameters
    ----------
    joints : ndarray (T, 21, 3)
        Joint positions (``HandModel.forward(...).joints``), metres.

    Returns
    -------
    ndarray (T,)
        Metres.
    """
    joints = np.asarray(joints, dtype=np.float64)
    out = np.empty(joints.shape[0])
    for start in range(0, len(out), 128):  # every pair at once, a few frames at a time (in the cache)
        by_joint = joints[start:start + 128].transpose(1, 0, 2)  # (21, t, 3)
        out[start:start + 128] = segment_distance(*(by_joint[k] for k in _BONE_PAIRS)).min(axis=0)
    return out


def clear_keys(hand, keys, key_t, t, draw, path) -> np.ndarray:
    """Key poses drawn again until the motion through them keeps neighbouring fingers apart.

    Each key is drawn until it and the straight ways (in angles) to the keys before and after it are clear
    (at most :data:`ATTEMPTS` draws), first in order, then, for :data:`ROUNDS` rounds, the keys around the
    frames that ``path`` still brings too close (a spline swings wider than the straight way).

    Parameters
    ----------
    hand : HandModel
        Its average shape judges the clearance.
    keys : list of ndarray (27,)
        Key poses, radians (replaced in place where drawn again).
    key_t : ndarray (K,)
        Their times, seconds.
    t : ndarray (T,)
        Frame times, seconds.
    draw : callable () -> ndarray (27,)
        A new key pose (from the motion's random generator).
    path : callable (key_t, keys (K, 27), t) -> ndarray (T, 27)
        The angles of every frame through the keys.

    Returns
    -------
    ndarray (T, 27)
        The angles through the final keys, radians. Frames still closer than :data:`FINGER_CLEARANCE` after
        that are kept (the motion still plays).
    """
    steps = np.linspace(0.0, 1.0, STEPS)[:, None]

    def clear(k) -> bool:
        ways = [keys[k][None]] + [keys[j] + steps * (keys[k] - keys[j]) for j in (k - 1, k + 1) if 0 <= j < len(keys)]
        return bool(finger_clearance(hand.forward(phi=np.concatenate(ways), vertices=False).joints).min()
                    >= FINGER_CLEARANCE)

    def redraw(k) -> None:
        for _ in range(ATTEMPTS):
            if clear(k):
                return
            keys[k] = draw()

    for k in range(len(keys)):
        redraw(k)
    phi = path(key_t, np.array(keys), t)
    for _ in range(ROUNDS):
        close = finger_clearance(hand.forward(phi=phi, vertices=False).joints) < FINGER_CLEARANCE
        if not close.any():
            break
        after = np.searchsorted(key_t, t[close])  # the keys on either side of each frame too close
        for k in np.unique(np.clip(np.concatenate([after - 1, after]), 0, len(keys) - 1)):
            keys[k] = draw()
            redraw(k)
        phi = path(key_t, np.array(keys), t)
    return phi
