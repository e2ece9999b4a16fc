"""Single-video capture of a steady grasp: structure from motion on hand keypoints (the paper's eq. 1 and eq. 2).

The participant holds the grasp still and turns the hand in front of one
camera. The problem is inverted, as in the paper: a stationary hand seen by a
moving virtual camera, one pose per frame.

* **Two-stage** (the paper's pipeline, :func:`structure_from_motion` then
  :func:`~handcap.markerless.fit.fit_keypoints`): eq. 1, a sparse bundle
  adjustment of the 21 keypoints ``X`` and the camera poses (scipy's
  ``least_squares`` with the Jacobian's sparsity, a Cauchy loss against wrong
  keypoints), then the hand model fitted to ``X``.
* **Joint** (the paper's future work, :func:`~handcap.markerless.jointfit.joint_fit`): eq. 2, the same
  reprojection error with the keypoints given by the hand model,
  ``X = J(phi, betas) + o``, so pose and shape are the unknowns instead of 63 free
  coordinates; the solver's anatomical priors (joint limits, DIP-PIP coupling) and a shape prior join
  the residuals. ``o`` is each keypoint's constant offset from its model joint (a detector's
  keypoint is not the joint's centre of rotation), learned under a 3 mm Gaussian prior: without
  it the pose bent to explain the offsets (joint angles 5.1 degrees off on the benchmark's
  videos, 3.0 with it, the two stages 4.7). The robust loss acts on the pixels only
  (Triggs' square-root form of the Cauchy loss), so the priors stay quadratic.
  It starts from the two-stage result.

After either, a frame whose pose turns more than 45 degrees from both its
neighbours' (a flat hand seen edge-on fits its mirrored pose almost as well) is
solved again from theirs (:func:`continuous_poses`).

Scale: one camera cannot tell a large hand far away from a small one near. The
bundle adjustment's scale is fixed by its anchor frame; the result is then
scaled (points and every camera's translation: the pixels do not change) to the
template's palm size, the average hand's; the joint fit keeps the overall size
(the first shape value is not fitted, and the keypoints' palm size with their
offsets is held to eq. 1's). Pass ``scale`` when the hand's size is
known (:func:`capture_video`). (A palm-size residual inside the adjustment did
not hold the scale: under the Cauchy loss a large residual counts as an outlier,
and a power grasp's structure came out 13 % too large.)

Frames: the camera of the video is the world; a hand pose is camera-from-hand,
``x_camera = R x_hand + t``.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
from scipy.optimize import least_squares
from scipy.sparse import lil_matrix
from scipy.spatial.transform import Rotation

from handcap.core.errors import HandcapError
from handcap.hand.anatomy import relaxed_pose
from handcap.markerless.joint_model import KeypointModel
from handcap.markerless.keypoints import PALM
from handcap.markerless.numdiff import sparse_differences

#: Cauchy scale of the reprojection residuals, pixels: keypoint detectors are 2-5 px off on a hand 200 px tall.
ROBUST_PX = 4.0
#: Least keypoints a frame needs to be placed (PnP and the bundle adjustment).
MIN_POINTS = 6


@dataclass(frozen=True)
class VideoStructure:
    """A stationary hand and the camera poses that see it.

    Attributes
    ----------
    points : ndarray (21, 3)
        Keypoints in the hand's frame, metres (keypoint order).
    rotation, translation : ndarray (T, 3)
        Camera-from-hand pose per frame (axis-angle, metres); NaN for frames with too few keypoints.
    residual_px : ndarray (T, 21)
        Reprojection error of every given keypoint, pixels; NaN where not given or the frame not placed.
    """

    points: np.ndarray
    rotation: np.ndarray
    translation: np.ndarray
    residual_px: np.ndarray

    @property
    def placed(self) -> np.ndarray:
        """Frames with a camera pose, (T,) bool."""
        return np.isfinite(self.rotation).all(axis=1)


def project_points(matrix, rotvec, trans, points):
    """Pixels of hand points seen by an ideal pinhole camera from each frame's pose.

    Parameters
    ----------
    matrix : ndarray (3, 3)
        Camera matrix.
    rotvec, trans : ndarray (T, 3)
        Camera-from-hand rotation (axis-angle) and translation (metres) of each frame.
    points : ndarray (K, 3) or (T, K, 3)
        Points in the hand's frame, metres.

    Returns
    -------
    ndarray (T, K, 2)
        Undistorted pixels.
    """
    rot = Rotation.from_rotvec(rotvec).as_matrix()
    pts = points if points.ndim == 3 else np.broadcast_to(points, (len(rotvec),) + points.shape)
    cam = np.einsum("tij,tkj->tki", rot, pts) + trans[:, None]
    z = cam[..., 2:]
    z = np.where(np.abs(z) < 1e-9, 1e-9, z)
    return cam[..., :2] / z * matrix[[0, 1], [0, 1]] + matrix[:2, 2]


def template_points(hand, betas=None, phi=None) -> np.ndarray:
    """The hand model's keypoints at a pose, in its own frame.

    Parameters
    ----------
    hand : HandModel
    betas : ndarray (10,), optional
        Shape (default: the average hand).
    phi : ndarray (27,), optional
        Pose, radians (default: the relaxed hand).

    Returns
    -------
    ndarray (21, 3)
        Metres, keypoint order.
    """
    model = KeypointModel(hand, betas)
    phi = relaxed_pose() if phi is None else phi
    return model.positions(np.zeros((1, 3)), np.eye(3)[None], np.asarray(phi)[None])[0]


def initial_poses(pixels, matrix, points) -> tuple[np.ndarray, np.ndarray]:
    """Camera-from-hand pose of every frame by RANSAC PnP of its keypoints against ``points``.

    Parameters
    ----------
    pixels : ndarray (T, 21, 2)
        Undistorted pixels, NaN where not given.
    matrix : ndarray (3, 3)
    points : ndarray (21, 3)
        A template of the hand's keypoints, metres.

    Returns
    -------
    rotation, translation : ndarray (T, 3)
        NaN where fewer than :data:`MIN_POINTS` keypoints are given or PnP fails.
    """
    n = len(pixels)
    rot, trans = np.full((n, 3), np.nan), np.full((n, 3), np.nan)
    size = np.ptp(points, axis=0).max()
    for t in range(n):
        seen = np.isfinite(pixels[t]).all(axis=1)
        if seen.sum() < MIN_POINTS:
            continue
        img = pixels[t, seen]
        extent = max(np.ptp(img, axis=0).max(), 1.0)
        ok, rv, tv, _ = cv2.solvePnPRansac(points[seen].astype(np.float64), img.astype(np.float64), matrix, None,
                                           reprojectionError=0.15 * extent, iterationsCount=200,
                                           flags=cv2.SOLVEPNP_EPNP)
        if ok:
            ok, rv, tv = cv2.solvePnP(points[seen], img, matrix, None, rv, tv, True, cv2.SOLVEPNP_ITERATIVE)
        if ok and tv[2, 0] > size:
            rot[t], trans[t] = rv[:, 0], tv[:, 0]
    return rot, trans


def palm_size(points):
    """Root mean square distance of the palm's keypoints (..., 21, 3) from their centre: (...,), metres."""
    palm = points[..., PALM, :]
    return np.sqrt(((palm - palm.mean(axis=-2, keepdims=True)) ** 2).sum(axis=-1).mean(axis=-1))


def structure_from_motion(pixels, matrix, template, *, robust_px: float = ROBUST_PX,
                          max_nfev: int = 60) -> VideoStructure:
    """Eq. 1: keypoints of a stationary hand and the virtual camera poses, by sparse bundle adjustment.

    Parameters
    ----------
    pixels : ndarray (T, 21, 2)
        Undistorted pixels of one camera's keypoints, NaN where not given.
    matrix : ndarray (3, 3)
        The camera matrix.
    template : ndarray (21, 3)
        A hand of the expected size and a plausible pose (the start, and the palm size the result is scaled to).
    robust_px : float
        Cauchy scale of the residuals, pixels.
    max_nfev : int
        Most evaluations of the bundle adjustment.

    Returns
    -------
    VideoStructure

    Raises
    ------
    HandcapError
        Fewer than 3 frames could be placed.
    """
    pixels = np.asarray(pixels, dtype=np.float64)
    matrix = np.asarray(matrix, dtype=np.float64)
    rot0, trans0 = initial_poses(pixels, matrix, template)
    placed = np.isfinite(rot0).all(axis=1)
    if placed.sum() < 3:
        raise HandcapError(f"only {int(placed.sum())} frames show {MIN_POINTS} keypoints that place the hand: no "
                           f"structure from motion (is the hand in the video?)")
    frames = np.flatnonzero(placed)
    obs = pixels[frames]
    seen = np.isfinite(obs).all(axis=2)  # (F, 21)
    anchor = int(np.argmax(seen.sum(axis=1)))  # the paper anchors one camera: the best seen frame's
    free = np.array([f for f in range(len(frames)) if f != anchor])
    size0 = palm_size(template)
    t_idx, k_idx = np.nonzero(seen)

    def unpack(p):
        x = p[:63].reshape(21, 3)
        rv, tv = rot0[frames].copy(), trans0[frames].copy()
        poses = p[63:].reshape(-1, 6)
        rv[free], tv[free] = poses[:, :3], poses[:, 3:]
        return x, rv, tv

    def residual(p):
        x, rv, tv = unpack(p)
        proj = project_points(matrix, rv, tv, x)
        r = (proj - np.nan_to_num(obs))[t_idx, k_idx].reshape(-1)
        return r

    sparsity = lil_matrix((2 * len(t_idx), 63 + 6 * len(free)), dtype=int)
    row = np.arange(len(t_idx))
    column_of_frame = np.full(len(frames), -1)
    column_of_frame[free] = 63 + 6 * np.arange(len(free))
    for a in range(2):
        for c in range(3):
            sparsity[2 * row + a, 3 * k_idx + c] = 1
        has = column_of_frame[t_idx] >= 0
        for c in range(6):
            sparsity[2 * row[has] + a, column_of_frame[t_idx[has]] + c] = 1
    start = np.r_[template.reshape(-1), np.c_[rot0[frames][free], trans0[frames][free]].reshape(-1)]
    x, rv, tv = unpack(graduated_fit(residual, start, sparsity, robust_px, max_nfev, 2 * len(t_idx)))
    k = size0 / palm_size(x)  # the scale is a gauge of the pixels: set it exactly, outside the robust loss
    return video_structure(pixels, matrix, k * x, frames, rv, k * tv)


#: A frame whose pose turns more than this from both its placed neighbours' (degrees) is solved again from
#: theirs: a hand does not turn 90 degrees in a frame, and a nearly flat hand seen edge-on has a mirrored
#: pose that fits its keypoints almost as well.
JUMP_DEG = 45.0


def continuous_poses(pixels, matrix, structure: VideoStructure, *, jump_deg: float = JUMP_DEG,
                     robust_px: float = ROBUST_PX) -> VideoStructure:
    """The structure with every frame whose pose jumps away from both neighbours solved again from theirs.

    The frame's pose is solved again from each neighbour's pose (least squares with a Cauchy loss against the
    structure's points: wrong keypoints count little), and the candidate that reprojects best (median)
    replaces the jump unless it reprojects more than 1.5 times worse (a fast turn the neighbours do not
    explain).

    Parameters
    ----------
    pixels : ndarray (T, 21, 2)
        Undistorted pixels, NaN where not given.
    matrix : ndarray (3, 3)
    structure : VideoStructure
    jump_deg : float
    robust_px : float
        Cauchy scale of the pixels, pixels.

    Returns
    -------
    VideoStructure
    """
    placed = np.flatnonzero(structure.placed)
    if len(placed) < 3:
        return structure
    rot, trans = structure.rotation.copy(), structure.translation.copy()
    mats = Rotation.from_rotvec(rot[placed])
    step = np.degrees((mats[1:] * mats[:-1].inv()).magnitude())
    before, after = np.r_[np.inf, step], np.r_[step, np.inf]
    jumps = placed[np.minimum(before, after) > jump_deg]  # at the ends, the one neighbour
    points = np.asarray(structure.points, dtype=np.float64)
    for t in jumps:
        seen = np.isfinite(pixels[t]).all(axis=1)
        i = int(np.searchsorted(placed, t))
        neighbours = [placed[j] for j in (i - 1, i + 1) if 0 <= j < len(placed)]
        best, best_err = None, np.inf
        for n in neighbours:
            fit = least_squares(_pose_residual, np.r_[rot[n], trans[n]], loss="cauchy", f_scale=robust_px,
                                x_scale="jac", max_nfev=50, args=(matrix, points[seen], pixels[t, seen]))
            err = _median_px(matrix, fit.x[:3], fit.x[3:], points[seen], pixels[t, seen])
            if err < best_err:
                best, best_err = (fit.x[:3], fit.x[3:]), err
        if best is not None and best_err <= 1.5 * _median_px(matrix, rot[t], trans[t], points[seen], pixels[t, seen]):
            rot[t], trans[t] = best
    return video_structure(pixels, matrix, points, placed, rot[placed], trans[placed])


def _pose_residual(q, matrix, points, pixels):
    return (project_points(matrix, q[None, :3], q[None, 3:], points)[0] - pixels).ravel()


def _median_px(matrix, rv, tv, points, pixels) -> float:
    proj = project_points(matrix, rv[None], tv[None], points)[0]
    return float(np.median(np.linalg.norm(proj - pixels, axis=1)))


def video_structure(pixels, matrix, points, frames, rv, tv) -> VideoStructure:
    """A :class:`VideoStructure` of fitted keypoints and the poses of the frames fitted, with its residuals.

    Parameters
    ----------
    pixels : ndarray (T, 21, 2)
        Undistorted pixels, NaN where not given.
    matrix : ndarray (3, 3)
    points : ndarray (21, 3)
        Keypoints in the hand's frame, metres.
    frames : ndarray (F,) int
        The frames fitted.
    rv, tv : ndarray (F, 3)
        Their camera-from-hand poses (axis-angle, metres).

    Returns
    -------
    VideoStructure
    """
    n = len(pixels)
    rot, trans = np.full((n, 3), np.nan), np.full((n, 3), np.nan)
    rot[frames], trans[frames] = rv, tv
    residual = np.full((n, 21), np.nan)
    residual[frames] = np.linalg.norm(project_points(matrix, rv, tv, points) - pixels[frames], axis=-1)
    return VideoStructure(points, rot, trans, residual)


def graduated_fit(residual, start, sparsity, robust_px, max_nfev, n_obs, batched=None) -> np.ndarray:
    """Least squares with a Cauchy loss whose scale falls from the start's typical residual to ``robust_px``.

    A robust loss far narrower than the start's errors is flat there (every residual counts as an outlier)
    and the solver stops where it began; so the scale starts at the median residual and falls by thirds to
    ``robust_px``, each stage starting from the last.

    Parameters
    ----------
    residual : callable
        Residuals (m,) of a parameter vector (n,): the ``n_obs`` pixel residuals first, then the priors.
    start : ndarray (n,)
    sparsity : scipy sparse (m, n)
        Where a residual depends on a parameter.
    robust_px : float
        The Cauchy scale of the last stage, pixels.
    max_nfev : int
        Most residual evaluations of each stage.
    n_obs : int
        Pixel residuals, under the robust loss.
    batched : callable, optional
        Residuals (B, m) of parameter vectors (B, n): then the Jacobian's forward differences are taken in one
        call of it (:func:`~handcap.markerless.numdiff.sparse_differences`), else by scipy one group of columns
        at a time.

    Returns
    -------
    ndarray (n,)
    """
    r = np.abs(residual(start)[:n_obs])
    scale = max(float(np.median(r)) if len(r) else robust_px, robust_px)
    p = start

    def cauchy(res):  # Cauchy on the pixels only (Triggs' square-root form): the priors stay quadratic
        pix = res[..., :n_obs]
        res[..., :n_obs] = np.sign(pix) * scale * np.sqrt(np.log1p((pix / scale) ** 2))
        return res

    jac = {"jac_sparsity": sparsity} if batched is None else \
        {"jac": sparse_differences(lambda q: cauchy(batched(q)), sparsity)}
    while True:
        p = least_squares(lambda q: cauchy(residual(q)), p, x_scale="jac", max_nfev=max_nfev, method="trf", **jac).x
        if scale <= robust_px:
            return p
        scale = max(scale / 3.0, robust_px)
