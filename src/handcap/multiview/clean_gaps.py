"""Step 3 of the cleaning: gap filling, each method with its own longest gap (frames).

The methods are applied in turn to what is still missing: :func:`fill_rigid` (the rigid motion of the
marker's patch, from patch-mates seen both in the gap frame and next to the gap), :func:`fill_linear`
(short gaps; DexterCap fills one or two frames) and :func:`fill_spline` (a cubic spline in time). Only
interior gaps are filled: nothing is extrapolated past the first or last sample of a marker, and a gap
longer than a method's maximum is left to the next method or stays missing.
"""

from __future__ import annotations

import numpy as np

from handcap.core.checks import check_frames, check_positions, check_positive
from handcap.core.markers import MarkerSequence, runs
from handcap.multiview.clean_groups import BLOCK_ELEMENTS, MarkerGroups, check_groups
from handcap.objects.rigid import kabsch
from handcap.occlusion.fill import fill_gaps

#: Longest gaps, frames, each method fills: linear and spline at 100 Hz (their defaults follow the take's rate, from
#: :data:`MAX_LINEAR_S` and :data:`MAX_SPLINE_S`); the rigid fill at any rate (it moves a marker with its patch-mates
#: seen in the same frame, which does not depend on the time between frames).
MAX_LINEAR, MAX_RIGID, MAX_SPLINE = 2, 30, 10
#: Longest gaps, seconds, that linear interpolation and a cubic spline fill by default: 2 and 10 frames at 100 Hz.
#: Between two frames of a take filmed at 4 frames a second a finger moves tens of millimetres, and an
#: interpolated fill there put the image demo's solve at 11 mm MRE against 0.27 mm without it (2026-11-30).
MAX_LINEAR_S, MAX_SPLINE_S = 0.02, 0.1
RIGID_TOLERANCE = 0.003
# A rigid fit needs markers off a line: RMS distance from their principal axis, metres.
RIGID_MIN_SPREAD = 0.001


def gap_frames(seconds: float, rate: float) -> int:
    """The frames of a gap of ``seconds`` at ``rate`` frames per second, rounded (0 where under half a frame).

    Parameters
    ----------
    seconds : float
    rate : float
        Frames per second.

    Returns
    -------
    int
    """
    return int(round(seconds * rate))


def _interpolated(positions, max_gap_frames, method):
    """Reuse handcap.occlusion.fill_gaps, whose gaps are in seconds: at 1 Hz they are frames."""
    if max_gap_frames == 0 or positions.shape[0] < 3:
        return positions.copy(), np.zeros(positions.shape[:2], bool)
    names = [str(i) for i in range(positions.shape[1])]
    filled, _ = fill_gaps(MarkerSequence(positions, names, 1.0), method, max_gap_s=max_gap_frames)
    out = filled.positions
    return out, np.isnan(positions[..., 0]) & ~np.isnan(out[..., 0])


def fill_linear(positions, *, max_gap_frames: int = MAX_LINEAR) -> tuple[np.ndarray, np.ndarray]:
    """Fill interior gaps of at most ``max_gap_frames`` frames by straight-line interpolation.

    Parameters
    ----------
    positions : ndarray of shape (T, M, 3)
        Metres, NaN where missing.
    max_gap_frames : int
        Frames; 0 fills nothing.

    Returns
    -------
    filled : ndarray of shape (T, M, 3)
    mask : ndarray of bool, shape (T, M)
        Samples filled.

    See Also
    --------
    handcap.occlusion.fill_gaps : does the interpolation (method ``linear``).
    """
    return _interpolated(check_positions(positions), check_frames(max_gap_frames, "max_gap_frames (linear)"), "linear")


def fill_spline(positions, *, max_gap_frames: int = MAX_SPLINE) -> tuple[np.ndarray, np.ndarray]:
    """Fill interior gaps of at most ``max_gap_frames`` frames with a cubic spline in time.

    The spline (``scipy.interpolate.CubicSpline``) runs through every sample of
    the marker; a marker with fewer than four samples is interpolated linearly.

    Parameters
    ----------
    positions : ndarray of shape (T, M, 3)
        Metres, NaN where missing.
    max_gap_frames : int
        Frames; 0 fills nothing.

    Returns
    -------
    filled : ndarray of shape (T, M, 3)
    mask : ndarray of bool, shape (T, M)

    See Also
    --------
    handcap.occlusion.fill_gaps : does the interpolation (method ``spline``).
    """
    return _interpolated(check_positions(positions), check_frames(max_gap_frames, "max_gap_frames (spline)"), "spline")


def fill_rigid(positions, groups: MarkerGroups, *, max_gap_frames: int = MAX_RIGID,
               tolerance: float = RIGID_TOLERANCE) -> tuple[np.ndarray, np.ndarray]:
    """Fill gaps by carrying the marker along with the rigid motion of its group.

    For a gap of marker m from frame s to s + n - 1, the frames next to it,
    s - 1 and s + n, see m. In each gap frame t and for each of these reference
    frames r, the rotation and translation taking the group's other markers
    seen in both r and t from r to t (Kabsch, at least 3 markers, not all on a
    line) carry m's position at r to t. The two estimates are blended linearly
    across the gap (weight of r = s + n: (t - s + 1) / (n + 1)); where only one
    is available it is used alone. A fit whose RMS residual exceeds
    ``tolerance`` (the group is not rigid there, or holds a wrong point) is
    not used.

    Parameters
    ----------
    positions : ndarray of shape (T, M, 3)
        Metres, NaN where missing.
    groups : MarkerGroups
        Markers that move as one rigid body (patches; see :func:`layout_groups`).
    max_gap_frames : int
        Frames; longer gaps and gaps at the start or end of the take are not filled.
    tolerance : float
        Metres, largest RMS residual of the rigid fit.

    Returns
    -------
    filled : ndarray of shape (T, M, 3)
    mask : ndarray of bool, shape (T, M)

    See Also
    --------
    handcap.objects.rigid.kabsch
    """
    positions = check_positions(positions)
    groups = check_groups(groups, positions.shape[1])
    max_gap_frames = check_frames(max_gap_frames, "max_gap_frames (rigid)")
    tolerance = check_positive(tolerance, "rigid tolerance (metres)")
    out = positions.copy()
    mask = np.zeros(positions.shape[:2], bool)
    present = ~np.isnan(positions[..., 0])
    n_frames = positions.shape[0]
    for g in range(len(groups.names)):
        cols = groups.members(g)
        if len(cols) < 4 or max_gap_frames == 0:
            continue
        frames, member, first, length = [], [], [], []
        for j, col in enumerate(cols):
            starts, lengths = runs(~present[:, col])
            ok = (starts > 0) & (starts + lengths < n_frames) & (lengths <= max_gap_frames)
            for s, n in zip(starts[ok], lengths[ok]):
                frames.append(np.arange(s, s + n))
                member += [j] * n
                first += [s] * n
                length += [n] * n
        if not frames:
            continue
        t = np.concatenate(frames)
        member, first, length = np.array(member), np.array(first), np.array(length)
        step = max(1, BLOCK_ELEMENTS // (3 * len(cols)))  # gap samples at a time: arrays are (samples, n, 3)
        for a in range(0, len(t), step):
            k = slice(a, a + step)
            value, done = _rigid_fill(positions[:, cols], present[:, cols], t[k], member[k], first[k], length[k],
                                      tolerance)
            out[t[k][done], cols[member[k][done]]] = value[done]
            mask[t[k][done], cols[member[k][done]]] = True
    return out, mask


def _rigid_fill(pts, seen, t, member, first, length, tolerance):
    """Rigid-fill estimates (K, 3) of gap samples (frame t, member) of one group, and where they exist."""
    others = np.ones((len(t), pts.shape[1]), bool)
    others[np.arange(len(t)), member] = False
    estimates, valid = [], []
    for ref in (first - 1, first + length):
        shared = seen[ref] & seen[t] & others
        src, tgt = np.nan_to_num(pts[ref]), np.nan_to_num(pts[t])
        rot, trans = kabsch(src, tgt, shared.astype(np.float64))
        moved = np.einsum("kij,knj->kni", rot, src) + trans[:, None]
        count = shared.sum(axis=1)
        rms = np.sqrt((np.sum((moved - tgt) ** 2, axis=2) * shared).sum(axis=1) / np.maximum(count, 1))
        # The fit must pin down rotations about every axis: not all shared markers on a line.
        centred = np.where(shared[..., None], src - (src * shared[..., None]).sum(1, keepdims=True)
                           / np.maximum(count, 1)[:, None, None], 0.0)
        second = np.linalg.eigvalsh(np.einsum("kni,knj->kij", centred, centred))[:, 1]
        spread = second / np.maximum(count, 1) > RIGID_MIN_SPREAD ** 2
        valid.append((count >= 3) & (rms <= tolerance) & spread)
        estimates.append(np.einsum("kij,kj->ki", rot, pts[ref, member]) + trans)
    w = ((t - first + 1) / (length + 1))[:, None]
    both = valid[0] & valid[1]
    value = np.where(valid[0][:, None], estimates[0], estimates[1])
    value[both] = ((1 - w) * estimates[0] + w * estimates[1])[both]
    return value, valid[0] | valid[1]


__all__ = ["MAX_LINEAR", "MAX_LINEAR_S", "MAX_RIGID", "MAX_SPLINE", "MAX_SPLINE_S", "RIGID_MIN_SPREAD",
           "RIGID_TOLERANCE", "fill_linear", "fill_rigid", "fill_spline", "gap_frames"]
