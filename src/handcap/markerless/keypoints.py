"""The 21 hand keypoints of 2D detectors and how they map to the hand model's joints.

Detectors (MediaPipe, OpenPose, the COCO-WholeBody and InterHand annotations
that mmpose follows) all give 21 points per hand in one order: the wrist, then
the thumb, index, middle, ring and little finger, each from its base to its
tip. :data:`KEYPOINT_NAMES` names them as handcap's files do (the 2D
detections File contract of DESIGN.md: marker names = keypoint names).

The hand model's 21 joints (:data:`handcap.hand.anatomy.JOINT_NAMES` and the
tips) follow MANO's order instead (wrist; index, middle, little, ring, thumb;
then the five tips thumb to little), so :data:`MODEL_JOINT` maps each keypoint
to the model joint it stands for:

=============  ==========  =============================================
keypoint       model       what the detectors mark
=============  ==========  =============================================
wrist          wrist (0)   centre of the wrist crease (MANO: the radiocarpal joint)
thumb_cmc      thumb1      base of the thumb's metacarpal
thumb_mcp      thumb2      thumb metacarpophalangeal joint
thumb_ip       thumb3      thumb interphalangeal joint
thumb_tip      thumb tip   end of the thumb
<f>_mcp        <f>1        knuckle (metacarpophalangeal joint)
<f>_pip        <f>2        proximal interphalangeal joint
<f>_dip        <f>3        distal interphalangeal joint
<f>_tip        <f> tip     end of the finger
=============  ==========  =============================================

Keypoints are not joint centres: annotators mark a joint where it shows on the
skin, a few millimetres from its centre of rotation on the back of a bent
finger, and the tip at the end of the pad. handcap takes each keypoint as its
model joint (the joint centre, and the model's tip at the end of the
fingertip) and lets the shape fit (:func:`handcap.markerless.fit.betas_from_keypoints`)
absorb what is constant in the offsets (bone lengths measured between
keypoints); what changes with the pose (a few millimetres) stays in the
residuals.
"""

from __future__ import annotations

import numpy as np

from handcap.core.errors import HandcapError

#: Finger names in the keypoint order (thumb to little finger).
FINGERS = ("thumb", "index", "middle", "ring", "pinky")
#: The 21 keypoint names, in the detectors' order.
KEYPOINT_NAMES = ("wrist", "thumb_cmc", "thumb_mcp", "thumb_ip", "thumb_tip") + tuple(
    f"{f}_{j}" for f in FINGERS[1:] for j in ("mcp", "pip", "dip", "tip"))
#: Model joint (index into the model's 21 joints: 16 MANO joints, then the tips thumb..little) of each keypoint.
MODEL_JOINT = np.array([0, 13, 14, 15, 16, 1, 2, 3, 17, 4, 5, 6, 18, 10, 11, 12, 19, 7, 8, 9, 20])
#: Keypoint index of each model joint (the inverse of :data:`MODEL_JOINT`).
KEYPOINT_OF_JOINT = np.argsort(MODEL_JOINT)
#: The six points the palm carries rigidly (wrist and the five finger bases), as keypoint indices.
PALM = np.array([0, 1, 5, 9, 13, 17])
#: Pairs of keypoints on one rigid body, whose distance no pose changes (keypoint indices): the bones of each
#: finger's chain, then the palm's (wrist to each finger base, and between neighbouring finger bases: the
#: palm's breadth).
BONES = np.array([(0, 1), (1, 2), (2, 3), (3, 4)] + [(b + k, b + k + 1) for b in (5, 9, 13, 17) for k in range(3)]
                 + [(0, b) for b in (5, 9, 13, 17)] + [(1, 5), (5, 9), (9, 13), (13, 17)])


def keypoints_from_joints(joints) -> np.ndarray:
    """The model's joints (..., 21, 3) in keypoint order.

    Parameters
    ----------
    joints : ndarray (..., 21, 3)
        The hand model's joints (MANO order, then the five tips), any unit.

    Returns
    -------
    ndarray (..., 21, 3)
        The same points in :data:`KEYPOINT_NAMES` order.
    """
    joints = np.asarray(joints)
    if joints.shape[-2:] != (21, 3):
        raise HandcapError(f"hand joints must have shape (..., 21, 3), got {joints.shape}")
    return joints[..., MODEL_JOINT, :]


def joints_from_keypoints(keypoints) -> np.ndarray:
    """Keypoints (..., 21, D) in the model's joint order (the inverse of :func:`keypoints_from_joints`).

    Parameters
    ----------
    keypoints : ndarray (..., 21, D)
        In :data:`KEYPOINT_NAMES` order (D = 2 for pixels, 3 for metres).

    Returns
    -------
    ndarray (..., 21, D)
    """
    keypoints = np.asarray(keypoints)
    if keypoints.ndim < 2 or keypoints.shape[-2] != 21:
        raise HandcapError(f"hand keypoints must have 21 rows, got shape {keypoints.shape}")
    return keypoints[..., KEYPOINT_OF_JOINT, :]


def split_hand_name(name: str) -> tuple[str, str]:
    """``"left:index_tip"`` -> ``("left", "index_tip")``; a name without a prefix has the prefix ``""``.

    Parameters
    ----------
    name : str
        A marker name of a keypoint file.

    Returns
    -------
    prefix : str
        Candidate-hand label (``left``, ``right``, ``hand2``...), ``""`` for none.
    keypoint : str
        One of :data:`KEYPOINT_NAMES`.

    Raises
    ------
    HandcapError
        The part after the prefix is no keypoint name.
    """
    prefix, _, keypoint = str(name).rpartition(":")
    if keypoint not in KEYPOINT_NAMES:
        raise HandcapError(f"{name!r} is no hand keypoint name; expected an optional 'hand:' prefix and one of "
                           f"{', '.join(KEYPOINT_NAMES[:5])}...")
    return prefix, keypoint


def hand_names(prefix: str = "") -> tuple[str, ...]:
    """The 21 keypoint names with ``prefix:`` before each (none for ``""``).

    Parameters
    ----------
    prefix : str
        Candidate-hand label.

    Returns
    -------
    tuple of str (21,)
    """
    return KEYPOINT_NAMES if not prefix else tuple(f"{prefix}:{n}" for n in KEYPOINT_NAMES)


def is_keypoints(names) -> bool:
    """Whether every name is a hand keypoint name (with or without a ``hand:`` prefix).

    Parameters
    ----------
    names : sequence of str

    Returns
    -------
    bool
        False for an empty sequence.
    """
    names = [str(n) for n in names]
    return bool(names) and all(n.rpartition(":")[2] in KEYPOINT_NAMES for n in names)
