"""Labeling a 2x2x2 cube's markers in unlabeled points by following its cubies (issue 18).

Identical markers on a cube cannot be told apart by shape: every cubie carries the same triangle, and the
cube looks the same after any of its 24 turns. Which marker is which therefore comes from a start: one
labelled frame (the capture software's, or a hand-labelled one). From there every cubie is followed as a
rigid body turning about the cube's centre:

1. Each marker's place in the next frame is predicted from its cubie's last two poses (constant velocity),
   so a hidden marker is still predicted where its cubie carries it.
2. The frame's points are given to the predicted markers by minimum total distance (Hungarian), within
   ``gate`` metres; points farther from every prediction stay unlabelled (the hand's markers, ghosts).
3. Each cubie's pose is fitted to its labelled markers and the cube's centre (a point of every cubie, since
   they all turn about it), so two markers of a cubie are enough. A cubie with fewer moves with the seen
   cubie it last moved with (its layer's, or the cube body's): of the poses the seen cubies give it, the
   one nearest its prediction. So a cubie hidden for a whole move is found where it reappears.

The labelled markers then go to :func:`handcap.objects.cube_track.track_cube` like those of a capture system.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import linear_sum_assignment

from handcap.core.errors import HandcapError
from handcap.objects.articulated import ArticulatedObject
from handcap.objects.rigid import kabsch

#: Farthest a point may be from a marker's predicted place to take its label, metres.
GATE = 0.008
#: Most a cubie may turn from one frame to the next, degrees (a third of a turn swaps its markers).
MAX_TURN_DEG = 30.0


@dataclass(frozen=True)
class CubeLabels:
    """What :func:`label_cube` found.

    Attributes
    ----------
    positions : ndarray (T, M, 3)
        The cube's markers (description order), metres; NaN where not seen (and before the start frame).
    start : int
        The start frame.
    labelled : float
        Share of the frames from the start on in which each marker was labelled, averaged over markers.
    """

    positions: np.ndarray
    start: int
    labelled: float


def _fit(rest, observed, centre):
    """Cubie poses from their markers and the cube's centre: rest (8, K, 3), observed (8, K, 3) NaN where not
    labelled, centre (3,) or NaN. Returns rotations (8, 3, 3), translations (8, 3) and which cubies fitted."""
    seen = np.isfinite(observed).all(axis=2)
    source = np.concatenate([rest, np.zeros((8, 1, 3))], axis=1)
    target = np.concatenate([np.nan_to_num(observed), np.broadcast_to(np.nan_to_num(centre), (8, 1, 3))], axis=1)
    weights = np.concatenate([seen, np.full((8, 1), np.isfinite(centre).all())], axis=1).astype(float)
    ok = (seen.sum(axis=1) >= 3) | ((seen.sum(axis=1) >= 2) & (weights[:, -1] > 0))
    rot, trans = kabsch(source, target, weights)
    return rot, trans, ok


def _claim(labels, free, spots, cubies, gate) -> None:
    """Give the unlabelled markers of ``cubies`` (8,) bool the nearest ``free`` point within ``gate`` of their
    ``spots`` (8, K, 3), each point once; ``labels`` (M, 3) is updated in place."""
    k = spots.shape[1]
    want = [c * k + j for c in np.flatnonzero(cubies) for j in range(k) if not np.isfinite(labels[c * k + j, 0])]
    if not want:
        return
    cost = np.linalg.norm(spots.reshape(-1, 3)[want][:, None] - free[None], axis=-1)
    rows, cols = linear_sum_assignment(np.where(cost > gate, 1e3, cost))
    keep = cost[rows, cols] <= gate
    labels[np.array(want)[rows[keep]]] = free[cols[keep]]


def _markers(pose, rest):
    """Markers (8, K, 3) of cubies at poses (8, 4, 4) from their rest places (8, K, 3)."""
    return np.einsum("nij,nkj->nki", pose[:, :3, :3], rest) + pose[:, None, :3, 3]


def label_cube(frames, cube: ArticulatedObject, start_positions, start: int, *, gate: float = GATE) -> CubeLabels:
    """Label the cube's markers in every frame from ``start`` on (see the module docstring).

    Parameters
    ----------
    frames : sequence of ndarray (K_t, 3)
        Each frame's unlabelled points, metres (a :class:`~handcap.core.points.PointCloudSequence`'s frames).
    cube : ArticulatedObject
        Eight parts (:func:`handcap.objects.articulated.load_articulated`); every part the same number of
        markers.
    start_positions : ndarray (M, 3)
        The labelled markers of frame ``start``, metres, NaN where hidden; every cubie needs 3 (or 2 and
        most of the others).
    start : int
    gate : float
        Metres.

    Returns
    -------
    CubeLabels

    Raises
    ------
    HandcapError
        A start frame out of range or with too few labelled markers, or a description that is not a cube.
    """
    sizes = {len(p.marker_names) for p in cube.parts}
    if len(cube.parts) != 8 or len(sizes) != 1:
        raise HandcapError(f"{cube.name}: not a 2x2x2 cube with the same markers on each of its eight cubies")
    k = sizes.pop()
    n, m = len(frames), len(cube.marker_names)
    if not 0 <= start < n:
        raise HandcapError(f"the start frame {start} is not in the take's {n} frames")
    first = np.asarray(start_positions, dtype=np.float64).reshape(m, 3)
    rest = cube.markers.reshape(8, k, 3)
    rot, trans, ok = _fit(rest, first.reshape(8, k, 3), np.full(3, np.nan))
    if ok.sum() < 2:
        raise HandcapError(f"frame {start}: fewer than two cubies show 3 labelled markers; give a start frame in "
                           f"which the cube is seen")
    centre = trans[ok].mean(axis=0)
    rot, trans, ok = _fit(rest, first.reshape(8, k, 3), centre)
    if not ok.all():
        raise HandcapError(f"frame {start}: cubies {', '.join(p.name for p, o in zip(cube.parts, ok) if not o)} "
                           f"show fewer than 2 labelled markers; give a start frame in which every cubie is seen")
    out = np.full((n, m, 3), np.nan)
    out[start] = first
    pose = np.tile(np.eye(4), (8, 1, 1))
    pose[:, :3, :3], pose[:, :3, 3] = rot, trans
    relative = np.einsum("dij,cjk->cdik", np.linalg.inv(pose), pose)  # cubie c in cubie d's frame
    placed = [_markers(pose, rest)] * 2  # the last two frames' markers, as the cubies' poses put them
    centres = [centre] * 2
    for f in range(start + 1, n):
        predicted = 2 * placed[-1] - placed[-2]  # (8, K, 3), constant velocity
        points = np.asarray(frames[f], dtype=np.float64).reshape(-1, 3)
        cols = keep = np.zeros(0, dtype=int)
        if len(points):
            cost = np.linalg.norm(predicted.reshape(m, 1, 3) - points[None], axis=-1)
            rows, cols = linear_sum_assignment(np.where(cost > gate, 1e3, cost))
            keep = cost[rows, cols] <= gate
            out[f, rows[keep]] = points[cols[keep]]
        rot, trans, ok = _fit(rest, out[f].reshape(8, k, 3), 2 * centres[-1] - centres[-2])
        # a cubie's markers look alike after a third of a turn about its diagonal: a fit that turns it that
        # far in one frame swapped its labels; they are dropped and the cubie placed like a hidden one
        jump = np.einsum("nji,nji->n", rot, pose[:, :3, :3]) < 1 + 2 * np.cos(np.deg2rad(MAX_TURN_DEG))
        if (ok & jump).any():
            out[f].reshape(8, k, 3)[ok & jump] = np.nan
            ok &= ~jump
        pose[ok, :3, :3], pose[ok, :3, 3] = rot[ok], trans[ok]
        if ok.any() and not ok.all():
            # a hidden cubie moves with a seen cubie it moved with last (its layer's, or the cube body's): of
            # the poses those give it, the one that puts most of its markers on free points, then the one
            # nearest its prediction; the free points it explains take its labels
            candidates = np.einsum("dij,cdjk->cdik", pose[ok], relative[:, ok])  # (8, D, 4, 4)
            spots = np.einsum("cdij,ckj->cdki", candidates[..., :3, :3], rest) + candidates[..., None, :3, 3]
            free = points[~np.isin(np.arange(len(points)), cols[keep])] if len(points) else points
            score = -np.linalg.norm(spots - predicted[:, None], axis=-1).mean(axis=2) / (10 * gate)
            if len(free):
                gaps = np.linalg.norm(spots[..., None, :] - free, axis=-1).min(axis=-1)  # (8, D, K)
                score = score + (gaps <= gate).sum(axis=2)
            best = np.argmax(score, axis=1)
            pose[~ok] = candidates[np.arange(8), best][~ok]
            if len(free):
                _claim(out[f], free, _markers(pose, rest), ~ok, gate)
        both = ok[:, None] & ok[None, :]
        relative[both] = np.einsum("dij,cjk->cdik", np.linalg.inv(pose), pose)[both]
        centre = trans[ok].mean(axis=0) if ok.any() else 2 * centres[-1] - centres[-2]
        placed = [placed[-1], _markers(pose, rest) if ok.any() else predicted]
        centres = [centres[-1], centre]
    seen = np.isfinite(out[start:]).all(axis=2)
    return CubeLabels(out, start, float(seen.mean()))
