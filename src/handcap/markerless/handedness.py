"""Handedness repair of multi-view 2D hand keypoints: which candidate hand of each view is which hand.

2D keypoint detectors label each hand they find ``left`` or ``right`` from a
single image, and they swap the labels often (a hand seen from its back, a
fist, a hand cut by the image border): in one camera and frame the hand called
``left`` is the right one. Triangulating by label then mixes two hands.

:func:`repair_handedness` decides, per camera and frame, which of the
candidate hands (the name prefixes of the 2D detections File contract) is
which physical hand, from what the views agree on, without trusting the
labels at all:

1. **Hands by hand-level RANSAC**, per frame: every pair of candidates in two
   cameras triangulates a whole hand (21 keypoints); the candidates of other
   cameras it reprojects onto (median keypoint error under a threshold, one
   candidate per camera) support it. The best supported hand is kept with its
   candidates, which are then removed, and the next hand is found the same
   way. A keypoint-by-keypoint triangulation by label would instead mix the two
   hands wherever half of the views swapped the labels.
2. **Hands followed through time**: each frame's hands are matched to the
   hands of the frames before by their mean position.
3. **Names by majority**: each hand is named by the label most of its views
   gave it over the whole take, so a hand keeps its name in a frame where most
   views swapped it, as long as most views of the take did not.

Candidates that support no hand (a false detection, a hand seen by one camera
only) are dropped and counted.
"""

from __future__ import annotations

import itertools
import warnings
from dataclasses import dataclass

import numpy as np

from handcap.core.errors import HandcapError
from handcap.markerless.keypoints import KEYPOINT_NAMES, hand_names, split_hand_name
from handcap.multiview.detections import Detections

#: Least keypoints a candidate hand and a hypothesis must share to be compared.
MIN_COMMON = 4
#: Default least reprojection threshold of a supporting view, undistorted pixels.
THRESHOLD_PX = 8.0
#: ... or this share of the candidate's bounding-box diagonal, when larger (keypoint errors grow with the hand's
#: size in the image).
REL_THRESHOLD = 0.1
#: What starting a new hand track costs against continuing one, metres (a hand moves far less between frames).
NEW_TRACK = 0.15


@dataclass(frozen=True)
class HandednessRepair:
    """What :func:`repair_handedness` did.

    Attributes
    ----------
    detections : Detections
        The keypoints relabelled: marker names ``HAND:keypoint`` for each hand found, a row per keypoint of each
        candidate given to a hand.
    hands : tuple of str
        The hands' labels.
    relabelled : int
        Candidate hands (camera and frame) whose label changed.
    dropped : int
        Candidate hands given to no hand (far from every triangulated hand).
    candidates : int
        Candidate hands in the input.
    assignment : ndarray (T, C, P) int
        Hand index (into ``hands``) of input label p in camera c and frame t; -1 where none or absent.
    labels : tuple of str
        The input labels (P of them), in ``assignment``'s order.
    """

    detections: Detections
    hands: tuple
    relabelled: int
    dropped: int
    candidates: int
    assignment: np.ndarray
    labels: tuple

    def summary(self) -> str:
        """One line: candidates, how many relabelled and dropped."""
        share = 100.0 * self.relabelled / max(self.candidates, 1)
        return (f"handedness: {self.candidates} candidate hands in {len(self.hands)} hand(s) "
                f"({', '.join(self.hands)}); {self.relabelled} relabelled ({share:.1f} %), {self.dropped} given to "
                f"no hand")


def _candidates(detections: Detections, rig) -> tuple[tuple, np.ndarray, np.ndarray]:
    """Labels (P,), undistorted pixels (P, T, C, 21, 2) NaN-filled, and row numbers (P, T, C, 21) (-1 for none)."""
    parsed = [split_hand_name(n) for n in detections.marker_names]
    labels = tuple(sorted({p for p, _ in parsed}))
    label_of = np.array([labels.index(p) for p, _ in parsed])
    point_of = np.array([KEYPOINT_NAMES.index(k) for _, k in parsed])
    to_rig = detections.camera_order(rig)
    n_frames, n_cams = detections.n_frames, len(detections.camera_names)
    pixels = np.full((len(labels), n_frames, n_cams, 21, 2), np.nan)
    rows = np.full((len(labels), n_frames, n_cams, 21), -1)
    und = np.empty_like(detections.xy)
    for c in range(n_cams):
        mine = detections.camera == c
        und[mine] = rig[int(to_rig[c])].undistort_pixels(detections.xy[mine])
    where = (label_of[detections.marker], detections.frame, detections.camera, point_of[detections.marker])
    if len(set(zip(*where))) != len(detections):
        raise HandcapError(f"{detections.source}: a keypoint is detected twice for one hand label in one camera and "
                           f"frame; give each candidate hand its own name prefix")
    pixels[where] = und
    rows[where] = np.arange(len(detections))
    return labels, pixels, rows


def _two_view(pixels_a, pixels_b, proj_a, proj_b) -> np.ndarray:
    """Linear triangulation (..., 3) of points seen at undistorted pixels (..., 2) by two cameras (..., 3, 4).

    Least squares on the four DLT rows with the point's fourth coordinate set to 1; NaN where a pixel is.
    """
    rows = np.stack([pixels_a[..., :1] * proj_a[..., 2, :] - proj_a[..., 0, :],
                     pixels_a[..., 1:] * proj_a[..., 2, :] - proj_a[..., 1, :],
                     pixels_b[..., :1] * proj_b[..., 2, :] - proj_b[..., 0, :],
                     pixels_b[..., 1:] * proj_b[..., 2, :] - proj_b[..., 1, :]], axis=-2)  # (..., 4, 4)
    a, b = rows[..., :3], -rows[..., 3]
    ata = np.einsum("...ki,...kj->...ij", a, a)
    atb = np.einsum("...ki,...k->...i", a, b)
    ok = np.isfinite(ata).all(axis=(-1, -2)) & (np.abs(np.linalg.det(np.nan_to_num(ata))) > 1e-18)
    out = np.full(ata.shape[:-1], np.nan)
    out[ok] = np.linalg.solve(ata[ok], atb[ok][..., None])[..., 0]
    return out


def _errors(points, pixels, projections, cam_of):
    """Median reprojection error (T, Q, K) of hypotheses (T, Q, 21, 3) against candidates (T, K, 21, 2).

    Infinite where the two share fewer than :data:`MIN_COMMON` keypoints or a point is behind the camera.
    """
    p = projections[cam_of]  # (K, 3, 4)
    h = np.einsum("kij,tqnj->tqkni", p[..., :3], points) + p[None, None, :, None, :, 3]
    with np.errstate(all="ignore"), warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        uv = h[..., :2] / h[..., 2:]
        err = np.linalg.norm(uv - pixels[:, None], axis=-1)  # (T, Q, K, 21)
        err[~(h[..., 2] > 0) & np.isfinite(err)] = np.inf
        common = np.isfinite(err).sum(axis=-1) + np.isinf(err).sum(axis=-1)
        med = np.nanmedian(np.where(np.isnan(err), np.nan, err), axis=-1)
    return np.where(common >= MIN_COMMON, np.nan_to_num(med, nan=np.inf), np.inf)


def _group(pixels, cam_of, projections, n_hands, threshold_px, rel_threshold, min_views, chunk=32):
    """Hands found in each frame: group (T, K) of every candidate (-1: none) and each group's mean point (G, T, 3).

    Hand-level RANSAC: every pair of candidates in two cameras triangulates a whole hand; the candidates it
    reprojects onto (median keypoint error under the threshold, one per camera) support it; the best
    supported hand is taken, its candidates removed, and the next found the same way.
    """
    n_frames, n_cand = pixels.shape[:2]
    i, j = np.triu_indices(n_cand, 1)
    pair = cam_of[i] != cam_of[j]
    i, j = i[pair], j[pair]
    with np.errstate(all="ignore"), warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        lo, hi = np.nanmin(pixels, axis=2), np.nanmax(pixels, axis=2)
    size = np.nan_to_num(np.linalg.norm(hi - lo, axis=-1))  # (T, K) bounding-box diagonal, pixels
    limit = np.maximum(threshold_px, rel_threshold * size)
    group = np.full((n_frames, n_cand), -1)
    centre = np.full((n_hands, n_frames, 3), np.nan)
    for first in range(0, n_frames, chunk):
        sl = slice(first, min(first + chunk, n_frames))
        px = pixels[sl]
        points = _two_view(px[:, i], px[:, j], projections[cam_of[i]][None, :, None],
                           projections[cam_of[j]][None, :, None])
        err = _errors(points, px, projections, cam_of)  # (t, Q, K)
        inlier = err <= limit[sl][:, None, :]
        free = np.ones((len(px), n_cand), bool)
        for g in range(n_hands):
            ok = inlier & free[:, None, :] & free[:, i][:, :, None] & free[:, j][:, :, None]
            # one candidate per camera: the nearest of each camera's inliers
            e = np.where(ok, err, np.inf)
            best_in_cam = np.full(e.shape[:2] + (cam_of.max() + 1,), np.inf)
            for c in np.unique(cam_of):
                best_in_cam[..., c] = e[..., cam_of == c].min(axis=-1)
            ok &= e <= best_in_cam[..., cam_of]
            support = ok.sum(axis=-1) - 1e-6 * np.where(ok, e, 0.0).sum(axis=-1) / np.maximum(limit[sl].max(), 1)
            q = np.argmax(support, axis=1)  # (t,)
            take = ok[np.arange(len(px)), q]  # (t, K)
            found = take.sum(axis=1) >= min_views
            take &= found[:, None]
            group[sl][take] = g
            free &= ~take
            with np.errstate(all="ignore"), warnings.catch_warnings():
                warnings.simplefilter("ignore", RuntimeWarning)
                centre[g, sl] = np.where(found[:, None], np.nanmean(points[np.arange(len(px)), q], axis=1), np.nan)
    return group, centre


def _link(centre) -> np.ndarray:
    """Track (T, H) of each frame's hand slot: slots matched to the tracks' last positions, frame by frame.

    ``centre`` (H, T, 3) holds each slot's mean keypoint, NaN where the slot has no hand. Each frame's slots
    go to the tracks by the least total distance to each track's last seen position (every one-to-one choice
    tried; a track never seen costs :data:`NEW_TRACK`).
    """
    n_hands, n_frames = centre.shape[:2]
    track = np.tile(np.arange(n_hands), (n_frames, 1))
    last = np.full((n_hands, 3), np.nan)
    perms = [np.array(p) for p in itertools.permutations(range(n_hands))]
    for t in range(n_frames):
        here = centre[:, t]
        seen = np.isfinite(here).all(axis=1)
        best, best_cost = track[t - 1] if t else track[0], np.inf
        for perm in perms:  # slot s -> track perm[s]
            d = np.linalg.norm(here - last[perm], axis=1)
            cost = np.where(seen, np.where(np.isfinite(d), d, NEW_TRACK), 0.0).sum()
            if cost < best_cost - 1e-12 or (cost <= best_cost + 1e-12 and (perm == best).all()):
                best, best_cost = perm, cost
        track[t] = best
        last[best[seen]] = here[seen]
    return track


def repair_handedness(detections: Detections, rig, *, threshold_px: float = THRESHOLD_PX,
                      rel_threshold: float = REL_THRESHOLD, min_views: int = 3,
                      n_hands: int | None = None) -> HandednessRepair:
    """Relabel the candidate hands of each camera and frame by agreement with the other views.

    Parameters
    ----------
    detections : Detections
        2D keypoints: marker names ``LABEL:keypoint`` (a candidate hand per label; no prefix is one label).
    rig : CameraRig
        Calibrated cameras, metres.
    threshold_px : float
        A candidate supports a hand when its median keypoint reprojection error is under this (undistorted
        pixels) or under ``rel_threshold`` of its own bounding-box diagonal, whichever is larger.
    rel_threshold : float
    min_views : int
        Cameras that must agree on a hand (at least 2; with fewer cameras than this, all of them).
    n_hands : int, optional
        Most hands in a frame (default: the number of labels).

    Returns
    -------
    HandednessRepair

    Raises
    ------
    HandcapError
        Marker names that are no hand keypoints, a camera the rig lacks, or a keypoint given twice.
    """
    if not isinstance(detections, Detections):
        raise HandcapError(f"need Detections, got {type(detections).__name__}")
    if not (np.isfinite(threshold_px) and threshold_px > 0):
        raise HandcapError(f"threshold_px must be a positive number of pixels, got {threshold_px!r}")
    labels, pixels, rows = _candidates(detections, rig)
    projections = rig.projections[detections.camera_order(rig)]
    n_labels, n_frames, n_cams = pixels.shape[:3]
    n_hands = n_labels if n_hands is None else int(n_hands)
    min_views = max(2, min(int(min_views), n_cams))
    flat = np.swapaxes(pixels, 0, 1).reshape(n_frames, n_labels * n_cams, 21, 2)  # candidate k = p * C + c
    cam_of = np.tile(np.arange(n_cams), n_labels)
    present = (np.isfinite(flat[..., 0]).sum(axis=-1) >= MIN_COMMON)
    flat = np.where(present[..., None, None], flat, np.nan)
    group, centre = _group(flat, cam_of, projections, n_hands, threshold_px, rel_threshold, min_views)
    # Hands are followed through time (a frame whose views mostly swapped the labels keeps its hands), then
    # each is named by the label most of its candidates carried over the whole take.
    track = _link(centre)  # (T, H)
    group = np.where(group >= 0, np.take_along_axis(track, np.maximum(group, 0), axis=1), -1)
    assignment = group.reshape(n_frames, n_labels, n_cams).transpose(0, 2, 1)  # (T, C, P)
    used = sorted({int(h) for h in np.unique(assignment) if h >= 0})
    names = [max((int((assignment[:, :, p] == h).sum()), labels[p]) for p in range(n_labels))[1] for h in used]
    if len(set(names)) != len(names):  # two hands most views called the same: numbered
        names = [f"{n}{k}" if names.count(n) > 1 else n for k, n in enumerate(names)]
    relabel = {h: k for k, h in enumerate(used)}
    marker_names = tuple(n for name in names for n in hand_names(name))
    frame, camera, marker, xy, score = [], [], [], [], []
    for p in range(n_labels):
        for h in used:
            t, c, k = np.nonzero((assignment[:, :, p] == h)[..., None] & (rows[p] >= 0))
            r = rows[p][t, c, k]
            frame.append(t)
            camera.append(c)
            marker.append(21 * relabel[h] + k)
            xy.append(detections.xy[r].reshape(-1, 2))
            score.append(detections.score[r])
    empty = [np.zeros(0, int)]
    out = Detections(detections.camera_names, marker_names, np.concatenate(frame or empty),
                     np.concatenate(camera or empty), np.concatenate(marker or empty),
                     np.concatenate(xy or [np.zeros((0, 2))]), np.concatenate(score or [np.zeros(0)]),
                     detections.rate, detections.n_frames, source=detections.source)
    label_of_hand = np.full(max(n_labels, 1) + 1, -1)
    for h in used:
        name = names[relabel[h]]
        label_of_hand[h] = labels.index(name) if name in labels else -1
    present = present.reshape(n_frames, n_labels, n_cams).transpose(0, 2, 1)
    hand_label = np.where(assignment >= 0, label_of_hand[np.maximum(assignment, 0)], -1)
    moved = present & (assignment >= 0) & (hand_label != np.arange(n_labels))
    dropped = present & (assignment < 0)
    return HandednessRepair(out, tuple(names), int(moved.sum()), int(dropped.sum()), int(present.sum()),
                            assignment, labels)
