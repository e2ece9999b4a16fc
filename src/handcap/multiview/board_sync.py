"""Cameras not triggered together, before the rig is calibrated: their offsets from the board's motion.

:mod:`handcap.multiview.sync` needs the rig's calibration; a rig of cameras started one by one cannot be
calibrated from a moving board until its cameras are synchronised. The board itself tells: each camera sees the
board's pose in its own frame (from its intrinsics alone, :func:`handcap.multiview.intrinsics.board_poses`), and
one rigid transform (the cameras' relative pose) maps camera b's view of the board onto camera a's at every
moment, but only when their frames are paired at the right offset. For every pair of cameras that see the board
in common, :func:`board_offsets` slides b's frames against a's, fits that one transform to the board's corners of
every frame by least squares (Kabsch), and keeps the offset with the least residual; then to a twentieth of a frame
with b's board interpolated between its frames. The pairs join into one offset per camera as in
:func:`handcap.multiview.offsets.join_offsets`. :func:`shift_boards` puts every camera on the reference's frames,
which :func:`handcap.multiview.calibration.calibrate_rig` takes.

Offsets count as :class:`handcap.multiview.sync.Sync` counts them: camera c's frame f shows the moment of the
reference camera's frame ``f + offset[c]``.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from handcap.core.cameras import Camera
from handcap.core.errors import HandcapError
from handcap.multiview.board_recordings import BoardDetections
from handcap.multiview.intrinsics import board_poses
from handcap.multiview.offsets import clear_least, join_offsets, least_on_grid
from handcap.multiview.sync import Sync
from handcap.objects.rigid import kabsch

#: Frames of the board a pair of cameras must both see at an offset to be judged there.
MIN_SHARED = 8


def board_offsets(detections: Sequence[BoardDetections], cameras: Sequence[Camera], *, max_offset: int,
                  names: Sequence[str] | None = None) -> Sync:
    """Each camera's time offset from the board's motion as the cameras see it (see the module docstring).

    Parameters
    ----------
    detections : sequence of BoardDetections
        One per camera, each with its own frames (frame numbers as their recordings count them).
    cameras : sequence of Camera
        Their intrinsics (extrinsics unused).
    max_offset : int
        Search range, frames either way.
    names : sequence of str or None
        Camera names (default ``cam_0``, ...); the first is the reference.

    Returns
    -------
    Sync
        ``before`` and ``after`` are the median residual of the pairs' fits at offset 0 and at the offsets found,
        millimetres.
    """
    detections, cameras = list(detections), list(cameras)
    if len(cameras) != len(detections):
        raise HandcapError(f"{len(cameras)} cameras for {len(detections)} recordings; give one per camera")
    names = [f"cam_{c}" for c in range(len(detections))] if names is None else list(names)
    if max_offset < 1:
        raise HandcapError(f"the search range must be at least one frame, got {max_offset}")
    tracks = [_board_points(d, camera) for d, camera in zip(detections, cameras)]
    found, warnings = [], []
    for a in range(len(tracks)):
        for b in range(a + 1, len(tracks)):
            pair = _pair(tracks[a], tracks[b], max_offset)
            if pair == "edge":
                warnings.append(f"cameras {names[a]} and {names[b]} agree best at the end of the search range "
                                f"({max_offset} frames); search further (--max-offset)")
            elif pair is not None:
                found.append((a, b, pair))
    offsets, used, disagree = join_offsets(found, len(tracks), 0)
    if disagree:
        warnings.append(f"{disagree} pairs of cameras disagreed with the joined offsets and were left out")
    lost = [names[c] for c in range(len(tracks)) if np.isnan(offsets[c])]
    if lost:
        warnings.append(f"no offset found for camera {', '.join(lost)}: it sees the board in too few frames "
                        f"with the other cameras, or the board moves too little to tell one offset from another")
    before = [_residual(tracks[a], tracks[b], 0.0) for a, b, _ in used]
    after = [_residual(tracks[a], tracks[b], offsets[a] - offsets[b]) for a, b, _ in used]
    return Sync(tuple(names), offsets, names[0], 1000 * _median(before), 1000 * _median(after), len(used),
                tuple(warnings), "residual of the board's fit between cameras", "mm")


def shift_boards(detections: Sequence[BoardDetections], offsets) -> list[BoardDetections]:
    """Every camera's board on the reference camera's frames (the first camera's), interpolated between a
    camera's frames for a fractional offset; NaN where a camera has no view then.

    Parameters
    ----------
    detections : sequence of BoardDetections
    offsets : array_like (C,)
        Frames; the first camera's is the reference's, a camera with NaN sees nothing.

    Returns
    -------
    list of BoardDetections
        All with the reference's frame numbers.
    """
    detections = list(detections)
    offsets = np.asarray(offsets, dtype=np.float64).reshape(-1)
    if offsets.shape != (len(detections),):
        raise HandcapError(f"need one offset per camera ({len(detections)}), got {offsets.shape}")
    frames = detections[0].frames
    out = []
    for d, offset in zip(detections, offsets):
        pixels = np.full((len(frames), d.board.n_corners, 2), np.nan)
        if np.isfinite(offset):
            pixels = _at_times(d.pixels.reshape(d.n_frames, -1), d.frames, frames - (offset - offsets[0]))
            pixels = pixels.reshape(len(frames), d.board.n_corners, 2)
            few = np.isfinite(pixels[..., 0]).sum(axis=1) < d.board.min_corners  # corners lost to a neighbour
            pixels[few] = np.nan
        labels = tuple(f"{d.source} at {f - offset + offsets[0]:.2f}" for f in frames)
        out.append(BoardDetections(d.board, pixels, d.size, d.source, labels, frames))
    return out


def _board_points(detections: BoardDetections, camera: Camera) -> tuple[np.ndarray, np.ndarray]:
    """(frames (T,), points (T, 4, 3)): the board's middle and three points along its axes in the camera's frame,
    metres, NaN where its pose is unknown."""
    board2camera, _ = board_poses(detections, camera)
    corners = detections.board.object_points
    middle = corners.mean(axis=0)
    size = max(float(np.ptp(corners, axis=0).max()), 1e-3)
    local = np.vstack([middle, middle + np.eye(3) * size / 2])
    points = np.einsum("tij,pj->tpi", board2camera[:, :3, :3], local) + board2camera[:, None, :3, 3]
    return detections.frames, points


def _at_times(values: np.ndarray, frames: np.ndarray, times: np.ndarray) -> np.ndarray:
    """``values`` (T, ...) of ``frames`` at ``times`` (S,), linear between consecutive frames; NaN elsewhere."""
    frames = np.asarray(frames)
    i = np.clip(np.searchsorted(frames, times, side="right") - 1, 0, len(frames) - 1)
    j = np.minimum(i + 1, len(frames) - 1)
    exact = np.isclose(frames[i], times, atol=1e-9)
    step = np.maximum(frames[j] - frames[i], 1)
    weight = np.clip((times - frames[i]) / step, 0, 1)
    inside = exact | ((frames[i] <= times) & (frames[j] > times) & (j == i + 1))
    if len(frames) > 1:  # a step wider than the usual one is a gap, not a frame
        inside &= exact | (step <= np.min(np.diff(frames)))
    weight = weight.reshape(-1, *([1] * (values.ndim - 1)))
    out = np.where(exact.reshape(weight.shape), values[i], (1 - weight) * values[i] + weight * values[j])
    out[~inside] = np.nan
    return out


def _fit(track_a, track_b, shift: float) -> tuple[np.ndarray, np.ndarray] | None:
    """Each shared frame's residual (F,) of the one rigid transform from b's board ``shift`` frames later onto
    a's, metres, and the frames' weights; None with fewer than :data:`MIN_SHARED` shared frames."""
    frames_a, points_a = track_a
    frames_b, points_b = track_b
    moved = _at_times(points_b, frames_b, frames_a + shift)
    both = np.isfinite(points_a).all(axis=(1, 2)) & np.isfinite(moved).all(axis=(1, 2))
    if both.sum() < MIN_SHARED:
        return None
    source, target = moved[both].reshape(-1, 3), points_a[both].reshape(-1, 3)
    weights = np.ones(len(source))
    for _ in range(2):  # a robust refit: frames far off (a bad pose) are left out of the second fit
        rotation, translation = kabsch(source, target, weights)
        error = np.linalg.norm(source @ rotation.T + translation - target, axis=1).reshape(-1, 4)
        per_frame = np.sqrt((error ** 2).mean(axis=1))
        weights = np.repeat(per_frame <= 3 * np.median(per_frame) + 1e-6, 4).astype(float)
    return per_frame, weights[::4]


def _residual(track_a, track_b, shift: float) -> float:
    fit = _fit(track_a, track_b, shift)
    return np.nan if fit is None else float(np.median(fit[0]))


def _pair(track_a, track_b, max_offset: int):
    """b's offset minus a's (frames), 'edge', or None where no offset is clearly best."""
    shifts = np.arange(-max_offset, max_offset + 1)
    best = clear_least(shifts, np.array([_residual(track_a, track_b, float(s)) for s in shifts]))
    if best is None:
        return None
    if best in (0, len(shifts) - 1):
        return "edge"
    grid = shifts[best] + np.linspace(-1, 1, 41)
    shift = least_on_grid(grid, np.array([_residual(track_a, track_b, float(s)) for s in grid]))
    return -shift  # a's frame f and b's frame f + shift show one moment


def _median(values) -> float:
    values = np.asarray(values, dtype=np.float64)
    values = values[np.isfinite(values)]
    return float(np.median(values)) if len(values) else np.nan
