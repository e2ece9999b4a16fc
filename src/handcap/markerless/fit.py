"""Hand motion from 3D hand keypoints: ``fit_keypoints`` (issue 17, the paper's Stage 3 and its future work).

The paper fits its hand in two stages: the palm pose from the six rigid
points (wrist and the five finger bases) by Umeyama's similarity, then the
joint angles by inverse kinematics. handcap does the same with more of the
hand model, as the paper's future work asks:

1. **Scale and units** (:func:`palm_similarity`): Umeyama's similarity of the
   six palm points against the average hand gives the subject's scale; a
   scale no adult hand has (keypoints in millimetres, a detector's normalised
   coordinates) is one clear error instead of an absurd fit.
2. **Shape** (:func:`betas_from_keypoints`): the ten shape values from the
   take's median bone lengths. Distances between keypoints on one rigid body
   (a phalanx, the palm) do not change with the pose, so every frame measures
   them, and a robust median ignores wrong detections.
3. **Pose**: the batched Levenberg-Marquardt of the marker solver
   (:func:`handcap.solve.motion.solve_lm`) with the keypoints as rigid points
   of the model (:class:`~handcap.markerless.joint_model.KeypointModel`): the
   rigid start aligns the palm points (Kabsch at the fitted shape), then every
   frame's 27 anatomical angles within the joint limits, under a Cauchy loss
   that lets a wrong keypoint go.

The result is the usual hand motion file, so metrics, filters and exports take
it; its ``marker_fit`` holds the fitted keypoints.
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import least_squares

from handcap.core.errors import HandcapError
from handcap.core.markers import MarkerSequence
from handcap.core.motion import HandMotion
from handcap.hand import OpenHand
from handcap.markerless.joint_model import KeypointModel
from handcap.markerless.keypoints import BONES, KEYPOINT_NAMES, PALM, hand_names
from handcap.quality.limits import HAND_LENGTH_RANGE, MM
from handcap.quality.plausibility import SHAPE_BOUND, attach, residual_warnings, shape_warnings
from handcap.solve.lm import Priors
from handcap.solve.motion import motion_from_poses, observed_markers, smoothed_poses, solve_lm

#: Mean keypoint error above which a fit is warned about, metres. Keypoints of 2D detectors triangulated from
#: calibrated views sit 2-8 mm from the joint centres they stand for (skin, annotation convention), so
#: twice the upper end means a wrong hand, a swapped label or the wrong units.
KEYPOINT_MRE_LIMIT = 0.015
#: Cauchy scale of the keypoint residuals, metres: about the spread of annotation offsets.
ROBUST_SCALE = 0.008
#: Weight of each shape value against the relative bone-length errors (keeps undetermined values at zero).
SHAPE_PRIOR = 0.02
#: Least frames in which a bone must be seen for its length to count.
MIN_BONE_FRAMES = 3


def palm_similarity(points, hand=None) -> tuple[float, np.ndarray, np.ndarray]:
    """Umeyama's similarity from the average hand's six palm points to the observed ones.

    Parameters
    ----------
    points : ndarray (T, 21, 3)
        Keypoints (metres, NaN where missing), keypoint order.
    hand : HandModel, optional
        Default: the right OpenHand.

    Returns
    -------
    scale : float
        Median over frames with all six palm points of ``|observed| / |model|`` (1 for an average adult).
    rotation : ndarray (T, 3, 3)
        Per frame (identity where fewer than three palm points are seen).
    translation : ndarray (T, 3)
        Metres; ``observed ~ scale * rotation @ model + translation``.

    Raises
    ------
    HandcapError
        No frame shows three palm points.
    """
    hand = OpenHand() if hand is None else hand
    model = KeypointModel(hand).rest_markers[PALM]
    pts = np.asarray(points, dtype=np.float64)[:, PALM]
    seen = np.isfinite(pts).all(axis=2)
    ok = seen.sum(axis=1) >= 3
    if not ok.any():
        raise HandcapError("no frame shows three of the six palm keypoints (wrist and the finger bases): "
                           "the hand cannot be placed")
    n = len(pts)
    rot, trans, scales = np.tile(np.eye(3), (n, 1, 1)), np.zeros((n, 3)), np.full(n, np.nan)
    for t in np.flatnonzero(ok):
        x, y = model[seen[t]], pts[t, seen[t]]
        mx, my = x.mean(axis=0), y.mean(axis=0)
        cov = (y - my).T @ (x - mx) / len(x)
        u, s, vt = np.linalg.svd(cov)
        d = np.ones(3)
        d[2] = np.sign(np.linalg.det(u @ vt))
        rot[t] = (u * d) @ vt
        var = ((x - mx) ** 2).sum() / len(x)
        scales[t] = (s * d).sum() / var
        trans[t] = my - scales[t] * rot[t] @ mx
    full = ok & seen.all(axis=1)
    scale = float(np.median(scales[full] if full.any() else scales[ok]))
    return scale, rot, trans


def bone_lengths(points, min_frames: int = MIN_BONE_FRAMES) -> np.ndarray:
    """Median length of every bone of :data:`~handcap.markerless.keypoints.BONES` over a take.

    Parameters
    ----------
    points : ndarray (T, 21, 3)
        Keypoints, metres, NaN where missing.
    min_frames : int
        A bone seen in fewer frames gets NaN.

    Returns
    -------
    ndarray (len(BONES),)
        Metres.
    """
    pts = np.asarray(points, dtype=np.float64)
    d = np.linalg.norm(pts[:, BONES[:, 1]] - pts[:, BONES[:, 0]], axis=2)  # (T, B)
    count = np.isfinite(d).sum(axis=0)
    out = np.full(len(BONES), np.nan)
    enough = count >= min_frames
    out[enough] = np.nanmedian(d[:, enough], axis=0)
    return out


def betas_from_keypoints(hand, points, *, prior: float = SHAPE_PRIOR) -> np.ndarray:
    """Shape values whose bone lengths match the take's median keypoint distances.

    Least squares on the relative length errors of the bones seen in at least
    :data:`MIN_BONE_FRAMES` frames, with a pull of ``prior`` per unit towards
    the average hand, within +-:data:`~handcap.quality.plausibility.SHAPE_BOUND`.

    Parameters
    ----------
    hand : HandModel
    points : ndarray (T, 21, 3)
        Keypoints, metres, NaN where missing (keypoint order).
    prior : float

    Returns
    -------
    ndarray (10,)
    """
    points = np.asarray(points, dtype=np.float64)
    goal = bone_lengths(points, min(MIN_BONE_FRAMES, len(points)))
    use = np.isfinite(goal) & (goal > 1e-4)
    if use.sum() < 3:
        return np.zeros(10)

    def lengths(betas):
        rest = KeypointModel(hand, betas).rest_markers
        return np.linalg.norm(rest[BONES[use, 1]] - rest[BONES[use, 0]], axis=1)

    def residual(betas):
        return np.concatenate([(lengths(betas) - goal[use]) / goal[use], prior * betas])

    return least_squares(residual, np.zeros(10), bounds=(-SHAPE_BOUND, SHAPE_BOUND), diff_step=1e-4).x


def hand_labels(names) -> list[str]:
    """The hand labels of keypoint marker names: ``"right"`` for ``right:wrist``..., ``""`` for bare names.

    Parameters
    ----------
    names : sequence of str

    Returns
    -------
    list of str
        Labels with at least one keypoint name, in order of appearance.
    """
    out = []
    for name in names:
        label, _, point = str(name).rpartition(":")
        if point in KEYPOINT_NAMES and label not in out:
            out.append(label)
    return out


def fit_keypoints(keypoints: MarkerSequence, *, label: str | None = None, side: str | None = None, hand=None,
                  fit_shape: bool = True,
                  betas=None, priors: Priors | None = None, robust_scale: float = ROBUST_SCALE,
                  iterations: int = 8, first_iterations: int = 60, filter_cutoff: float | None = None,
                  filter_order: int = 2, progress: bool | None = None) -> HandMotion:
    """Fit the hand model to 3D hand keypoints.

    Parameters
    ----------
    keypoints : MarkerSequence
        The 21 keypoints (names as :data:`~handcap.markerless.keypoints.KEYPOINT_NAMES`, a ``hand:`` prefix
        allowed; missing names are never seen), metres, NaN where missing.
    label : str, optional
        The hand to fit when the file has several (``right`` for ``right:wrist``...); default: the only one.
    side : {"right", "left"}, optional
        Which hand (default: the model's, else ``label`` when it is left or right, else right).
    hand : HandModel, optional
        Default: the OpenHand of ``side``.
    fit_shape : bool
        Fit the shape to the take's bone lengths (:func:`betas_from_keypoints`); else ``betas`` or the average.
    betas : ndarray (10,), optional
        Shape to use when not fitting it.
    priors : Priors, optional
        Joint limits and anatomical priors of the solve.
    robust_scale : float
        Cauchy scale of the keypoint residuals, metres.
    iterations, first_iterations : int
        As :func:`handcap.solve.solve_hand`.
    filter_cutoff : float, optional
        Low-pass the solved pose at this frequency, Hz.
    filter_order : int
    progress : bool, optional
        Progress bar (default: on a terminal).

    Returns
    -------
    HandMotion
        With ``marker_names`` the 21 keypoint names, ``marker_fit`` (T, 21, 3) the fitted keypoints and
        ``marker_residuals`` (T, 21) metres; warnings for an MRE above :data:`KEYPOINT_MRE_LIMIT` and shape
        values at their bounds.

    Raises
    ------
    HandcapError
        No keypoint names in the input, no frame with three palm points, or a hand of a size no adult has
        (wrong units).
    """
    labels = hand_labels(keypoints.names)
    if not labels:
        raise HandcapError(f"the input has none of the 21 hand keypoint names ({', '.join(KEYPOINT_NAMES[:4])}...); "
                           f"it has {', '.join(keypoints.names[:6])}")
    if label is None:
        if len(labels) > 1:
            raise HandcapError(f"the input holds several hands ({', '.join(repr(x) for x in labels)}): choose one "
                               f"(--hand LABEL)")
        label = labels[0] if labels else ""
    elif label not in labels:
        raise HandcapError(f"no hand {label!r} in the input (it has {', '.join(repr(x) for x in labels) or 'none'})")
    if side is None and hand is None and label in ("left", "right"):
        side = label
    hand = (OpenHand(side or "right") if hand is None else hand)
    if side is not None and hand.side != side:
        raise HandcapError(f"the hand model is a {hand.side} hand but side={side!r} was asked for")
    target, _ = observed_markers(keypoints, hand_names(label))
    observed = np.isfinite(target).all(axis=2)
    scale, _, _ = palm_similarity(target, hand)
    length = scale * np.linalg.norm(np.subtract(*KeypointModel(hand).rest_markers[[12, 0]]))
    low, high = HAND_LENGTH_RANGE
    if not low / 1.5 <= length <= high * 1.5:
        raise HandcapError(f"the keypoints make a hand {MM * length:.4g} mm long (wrist to middle fingertip; adults: "
                           f"{MM * low:.0f}-{MM * high:.0f} mm): are they in metres? (convert with --units)")
    if fit_shape:
        betas = betas_from_keypoints(hand, target)
    betas = np.zeros(10) if betas is None else np.asarray(betas, dtype=np.float64)
    model = KeypointModel(hand, betas)
    priors = Priors() if priors is None else priors
    poses = solve_lm(model, np.nan_to_num(target), observed, priors, robust_scale, keypoints.rate, iterations,
                     first_iterations, progress)
    if filter_cutoff is not None:
        poses = smoothed_poses(poses, keypoints.rate, filter_cutoff, filter_order)
    motion = motion_from_poses(hand, model, poses, target, observed, keypoints.rate, hand_names(label))
    residuals = motion.marker_residuals
    found = residual_warnings(residuals, names=hand_names(label), what="keypoint fit MRE", limit=KEYPOINT_MRE_LIMIT)
    return attach(motion, found + (shape_warnings(betas) if fit_shape else []))
