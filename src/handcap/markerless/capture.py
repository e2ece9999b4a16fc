"""Single-video grasp capture end to end: 2D keypoints of one camera to a hand motion (``handcap markerless``).

:func:`capture_video` chains :mod:`~handcap.markerless.sfm`: undistort the
keypoints, structure from motion (eq. 1), the hand model fitted to the
structure (two-stage, the paper's Stage 3), then optionally the joint fit of
eq. 2 from there. The result is a hand motion in the camera's frame: the held
pose in every frame, moved by each frame's camera-from-hand pose.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from handcap.core.errors import HandcapError, HandcapWarning
from handcap.core.markers import MarkerSequence
from handcap.core.motion import HandMotion
from handcap.hand import OpenHand
from handcap.markerless.fit import fit_keypoints
from handcap.markerless.joint_model import KeypointModel
from handcap.markerless.keypoints import KEYPOINT_NAMES, split_hand_name
from handcap.markerless.jointfit import joint_fit
from handcap.markerless.sfm import (ROBUST_PX, VideoStructure, continuous_poses, project_points,
                                   structure_from_motion, template_points)
from handcap.quality.plausibility import attach, shape_warnings

METHODS = ("joint", "two-stage")
#: A median reprojection error above this (pixels) means the hand was not steady, or keypoints are wrong.
REPROJECTION_WARNING_PX = 10.0


@dataclass(frozen=True)
class VideoCapture:
    """What :func:`capture_video` found.

    Attributes
    ----------
    motion : HandMotion
        In the camera's frame (metres), the held pose in every frame; ``marker_fit`` holds the model's
        keypoints.
    structure : VideoStructure
        The final keypoints (hand frame) and camera poses, with the reprojection error per keypoint.
    two_stage : VideoStructure
        The free keypoints of eq. 1 (before the model).
    method : str
    """

    motion: HandMotion
    structure: VideoStructure
    two_stage: VideoStructure
    method: str

    def summary(self) -> str:
        """One line of figures."""
        r = self.structure.residual_px
        placed = self.structure.placed
        return (f"{int(placed.sum())} of {len(placed)} frames placed, reprojection error median "
                f"{np.nanmedian(r):.2f} px (mean {np.nanmean(r):.2f}), {self.method} fit")


def _camera_pose(model, orient, transl, rotation, translation):
    """Camera-from-model-frame poses (T, 3) for a hand placed by (orient, transl) in the structure's frame."""
    r0 = Rotation.from_rotvec(orient).as_matrix()
    j0 = model.rest_joints[0]
    t0 = j0 - r0 @ j0 + transl  # the model's positions(transl, r0, phi) = r0 x + t0
    rt = Rotation.from_rotvec(np.nan_to_num(rotation)).as_matrix()
    rot = Rotation.from_matrix(rt @ r0).as_rotvec()
    trans = np.einsum("tij,j->ti", rt, t0) + np.nan_to_num(translation)
    bad = ~np.isfinite(rotation).all(axis=1)
    rot[bad], trans[bad] = np.nan, np.nan
    return rot, trans


def _held(values, placed):
    """Rows of frames not placed take the nearest placed frame's row."""
    idx = np.flatnonzero(placed)
    nearest = idx[np.clip(np.searchsorted(idx, np.arange(len(values))), 0, len(idx) - 1)]
    before = idx[np.clip(np.searchsorted(idx, np.arange(len(values))) - 1, 0, len(idx) - 1)]
    pick = np.where(np.abs(before - np.arange(len(values))) <= np.abs(nearest - np.arange(len(values))), before,
                    nearest)
    return values[pick]


def capture_video(pixels, camera, *, side: str = "right", hand=None, method: str = "joint", rate: float = 30.0,
                  scale: float = 1.0, robust_px: float = ROBUST_PX) -> VideoCapture:
    """Hand pose and shape of a steady grasp from one camera's 2D keypoints.

    Parameters
    ----------
    pixels : ndarray (T, 21, 2)
        Keypoints in the distorted image (keypoint order), NaN where not given.
    camera : Camera
        The video camera's intrinsics (matrix and distortion; its pose is ignored: its frame is the world).
    side : {"right", "left"}
    hand : HandModel, optional
        Default: the OpenHand of ``side``.
    method : {"joint", "two-stage"}
        Eq. 2 after the two-stage start, or the paper's two stages only.
    rate : float
        Frames per second.
    scale : float
        The hand's size relative to the average adult's (one camera cannot measure it).
    robust_px : float
        Cauchy scale of the reprojection residuals, pixels.

    Returns
    -------
    VideoCapture

    Raises
    ------
    HandcapError
        Bad shapes, an unknown method, or too few frames with keypoints.
    """
    if method not in METHODS:
        raise HandcapError(f"unknown method {method!r}; choose one of {', '.join(METHODS)}")
    pixels = np.asarray(pixels, dtype=np.float64)
    if pixels.ndim != 3 or pixels.shape[1:] != (21, 2):
        raise HandcapError(f"keypoints must have shape (T, 21, 2), got {pixels.shape}")
    if not (np.isfinite(scale) and 0.5 <= scale <= 2.0):
        raise HandcapError(f"scale is the hand's size relative to an average adult's (0.5-2), got {scale}")
    hand = OpenHand(side) if hand is None else hand
    und = camera.undistort_pixels(pixels)
    matrix = np.asarray(camera.matrix, dtype=np.float64)
    template = scale * template_points(hand)
    two_stage = structure_from_motion(und, matrix, template, robust_px=robust_px)
    with warnings.catch_warnings():  # a start for eq. 2: the final result is checked below
        warnings.simplefilter("ignore", HandcapWarning)
        fitted = fit_keypoints(MarkerSequence(two_stage.points[None], KEYPOINT_NAMES, rate), hand=hand,
                               progress=False)
    phi, betas = fitted.phi[0], fitted.betas
    model = KeypointModel(hand, betas)
    rot, trans = _camera_pose(model, fitted.global_orient[0], fitted.transl[0], two_stage.rotation,
                              two_stage.translation)
    if method == "joint":
        phi, betas, final = joint_fit(und, matrix, hand, two_stage, phi, betas, rot, trans, robust_px=robust_px)
        rot, trans = final.rotation, final.translation
    else:
        final = VideoStructure(fitted.marker_fit[0], rot, trans, two_stage.residual_px)
        model_points = model.positions(np.zeros((1, 3)), np.eye(3)[None], phi[None])[0]
        final = _reprojected(final, model_points, und, matrix)
    final = continuous_poses(und, matrix, final)
    rot, trans = final.rotation, final.translation
    motion = video_motion(hand, betas, phi, rot, trans, rate, final.points - template_points(hand, betas, phi))
    median = float(np.nanmedian(final.residual_px))
    if median > REPROJECTION_WARNING_PX:
        motion = attach(motion, [f"reprojection error median {median:.1f} px is above {REPROJECTION_WARNING_PX:g} px: "
                                 f"the hand was not held steady, or many keypoints are wrong"])
    return VideoCapture(motion, final, two_stage, method)


def _reprojected(structure, points, pixels, matrix) -> VideoStructure:
    placed = structure.placed
    residual = np.full(pixels.shape[:2], np.nan)
    residual[placed] = np.linalg.norm(project_points(matrix, structure.rotation[placed], structure.translation[placed],
                                               points) - pixels[placed], axis=-1)
    return VideoStructure(points, structure.rotation, structure.translation, residual)


def video_motion(hand, betas, phi, rot, trans, rate, offsets=None) -> HandMotion:
    """A hand holding one pose, moved by a camera-from-hand pose per frame.

    Parameters
    ----------
    hand : HandModel
    betas : ndarray (10,)
    phi : ndarray (27,)
        The held angles, radians.
    rot, trans : ndarray (T, 3)
        Camera-from-model poses (axis-angle, metres: a point ``x`` of the model at rest goes to ``R x + t``);
        NaN in frames not placed, which hold the nearest placed frame's pose (with a warning).
    rate : float
    offsets : ndarray (21, 3), optional
        Each keypoint's constant offset from its model joint in the model's frame, metres (eq. 2 learns them).

    Returns
    -------
    HandMotion
        In the camera's frame, ``marker_fit`` the model's keypoints plus their offsets.
    """
    model = KeypointModel(hand, betas)
    placed = np.isfinite(rot).all(axis=1)
    rot, trans = _held(rot, placed), _held(trans, placed)
    j0 = model.rest_joints[0]
    r = Rotation.from_rotvec(rot).as_matrix()
    transl = trans - j0 + np.einsum("tij,j->ti", r, j0)  # positions(transl, r, phi) = r x + trans
    n = len(rot)
    phis = np.tile(phi, (n, 1))
    hand_pose = hand.hand_pose_from_phi(phis)
    joints = hand.forward(betas, rot, hand_pose, transl, vertices=False).joints
    fit = model.positions(transl, r, phis)
    if offsets is not None:
        fit = fit + np.einsum("tij,kj->tki", r, np.asarray(offsets, dtype=np.float64))
    motion = HandMotion(betas, rot, hand_pose, transl, rate, hand.side, phis, hand.name, joints, KEYPOINT_NAMES, fit)
    found = shape_warnings(betas)
    if (~placed).any():
        found.append(f"{int((~placed).sum())} of {n} frames had too few keypoints to place the hand; they hold "
                     f"the pose of the nearest placed frame")
    return attach(motion, found)


def video_keypoints(detections, camera: str | None = None, label: str | None = None) -> np.ndarray:
    """One camera's keypoints of one hand as an array (T, 21, 2), following the hand when labels flip.

    Detectors label a hand left or right per frame and flip it now and then; in a video of one grasp, per
    frame the candidate hand nearest to the hand of the frame before (mean keypoint, pixels) is taken,
    starting from ``label`` (default: the label given most often).

    Parameters
    ----------
    detections : Detections
        2D keypoints (marker names ``[LABEL:]keypoint``).
    camera : str, optional
        The camera (default: the only one).
    label : str, optional

    Returns
    -------
    ndarray (T, 21, 2)
        Distorted pixels, NaN where not given.

    Raises
    ------
    HandcapError
        Several cameras and none chosen, an unknown camera or label, or names that are no keypoints.
    """
    names = detections.camera_names
    if camera is None:
        if len(names) > 1:
            raise HandcapError(f"the keypoints come from {len(names)} cameras ({', '.join(names)}): choose one")
        camera = names[0]
    if camera not in names:
        raise HandcapError(f"no camera {camera!r} in the keypoints (they have {', '.join(names)})")
    parsed = [split_hand_name(n) for n in detections.marker_names]
    labels = sorted({p for p, _ in parsed})
    mine = detections.camera == names.index(camera)
    if label is None:
        counts = [int((mine & np.isin(detections.marker, [i for i, (p, _) in enumerate(parsed) if p == lab])).sum())
                  for lab in labels]
        label = labels[int(np.argmax(counts))]
    elif label not in labels:
        raise HandcapError(f"no hand {label!r} in the keypoints (they have {', '.join(map(repr, labels))})")
    point = np.array([KEYPOINT_NAMES.index(k) for _, k in parsed])
    of_label = np.array([labels.index(p) for p, _ in parsed])
    cand = np.full((len(labels), detections.n_frames, 21, 2), np.nan)
    rows = np.flatnonzero(mine)
    cand[of_label[detections.marker[rows]], detections.frame[rows], point[detections.marker[rows]]] = \
        detections.xy[rows]
    with np.errstate(all="ignore"), warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        centre = np.nanmean(cand, axis=2)  # (L, T, 2)
    out = np.full((detections.n_frames, 21, 2), np.nan)
    last = None
    current = labels.index(label)
    for t in range(detections.n_frames):
        present = np.flatnonzero(np.isfinite(centre[:, t, 0]))
        if not len(present):
            continue
        if last is None:
            pick = current if current in present else present[0]
        else:
            pick = present[np.argmin(np.linalg.norm(centre[present, t] - last, axis=1))]
        out[t], last = cand[pick, t], centre[pick, t]
    return out
