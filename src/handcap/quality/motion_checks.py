"""Plausibility of motion: jerk spikes, bone lengths, size (units), speed (issue 14)."""

from __future__ import annotations


import numpy as np

from handcap.hand.anthropometry import HAND_LENGTH as AVERAGE_HAND_LENGTH
from handcap.hand.anthropometry import rest_joints
from handcap.quality.limits import (BONE_RATIO, HAND_LENGTH_RANGE, HAND_SPREAD, MAX_SPEED, MM, SPIKE_JUMP,
                                    SPIKE_STRAY, SPIKE_Z, default_names, listed)


# -- motion: jerk spikes, bones, size, speed --------------------------------------------------------


def jerk_spikes(positions, rate: float, *, z: float = SPIKE_Z, min_jump: float = SPIKE_JUMP) -> np.ndarray:
    """Frames where the motion jerks far more than anywhere else in the take.

    Per frame t, the largest jerk over the points, ``j_t = max_m |x_{t+3} - 3 x_{t+2} + 3 x_{t+1} - x_t|
    * rate^3`` (m/s^3, as :func:`handcap.quality.metrics.jerk`). A frame is a spike when its jerk is more
    than ``z`` robust standard deviations (1.4826 x the median absolute deviation) above the take's median
    jerk, so the threshold follows the take's own noise and speed, and the jump it implies (the third
    difference / 3) is at least ``min_jump``, so a take with little noise does not report tiny wiggles.

    Parameters
    ----------
    positions : ndarray of shape (T, M, 3)
        Joints or markers, metres; NaN where missing (those frames are skipped).
    rate : float
        Hz.
    z, min_jump : float
        Defaults :data:`SPIKE_Z`, :data:`SPIKE_JUMP` (metres).

    Returns
    -------
    ndarray of int
        The first frame ``t`` of every spiking third difference (frames t..t+3 take part).
    """
    positions = np.asarray(positions, dtype=np.float64)
    if positions.ndim == 2:
        positions = positions[:, None]
    if len(positions) < 4:
        return np.zeros(0, dtype=int)
    third = np.linalg.norm(np.diff(positions, n=3, axis=0), axis=-1)  # (T-3, M), metres
    third = np.where(np.isfinite(third), third, -np.inf).max(axis=1)
    valid = np.isfinite(third)
    if valid.sum() < 8:
        return np.zeros(0, dtype=int)
    median = np.median(third[valid])
    spread = 1.4826 * np.median(np.abs(third[valid] - median))
    spike = valid & (third > median + z * spread) & (third >= 3 * min_jump)
    return np.flatnonzero(spike)


def spike_events(positions, rate: float, spikes, *, frames: int = 4) -> list[tuple[int, int, bool | None]]:
    """The jerk spikes of :func:`jerk_spikes` as events, each told a change of course or a jump.

    Spike frames no more than 3 apart are one event. Its point that jerks most (of those seen all around it) has
    a velocity over the ``frames`` frames before the event and over those after. The event is a change of course
    (an impact, a flick: the hand hits something and keeps its new velocity) when the velocity changed by at least
    half the event's third difference and, on its way, strayed no further from the old and new velocities than
    :data:`~handcap.quality.limits.SPIKE_STRAY` times the change. A point that jumps and comes back (a label swap
    or a lost fit for a few frames) or jumps and stays (a swap that lasts) leaves its velocity as it was, with a
    jump in between. On kineticstoolkit's wheelchair racing (70 Hz, the hands hitting the push rims; both gloves'
    and forearms' clusters, 52 events) the velocity changed by 1.1-4.3 times the event's third difference and
    strayed 0.2-1.1 times the change (a hand bouncing back off the rim faster than it then goes on); on a jump of
    2 cm for 1 to 4 frames and back, or to stay, it changed by 0.01-0.02 times and strayed 30-90 times the change.

    Parameters
    ----------
    positions : ndarray of shape (T, M, 3)
        Metres; NaN where missing.
    rate : float
        Hz.
    spikes : ndarray of int
        :func:`jerk_spikes` of ``positions``.
    frames : int
        Frames on each side that give the velocities before and after.

    Returns
    -------
    list of (first, last, changes_course)
        The event's first and last spike frames; ``changes_course`` is False where it jumps, None where no point
        of it is seen all around it or those frames lie outside the take.
    """
    positions = np.asarray(positions, dtype=np.float64)
    if positions.ndim == 2:
        positions = positions[:, None]
    runs: list[list[int]] = []
    for t in np.asarray(spikes, dtype=int):
        if runs and t - runs[-1][1] <= 3:
            runs[-1][1] = int(t)
        else:
            runs.append([int(t), int(t)])
    out = []
    for first, last in runs:
        low, high = first, last + 2  # the velocities (x[i + 1] - x[i]) the event's third differences use
        if low < frames or high + 2 + frames > len(positions):
            out.append((first, last, None))
            continue
        # Only the frames around the event: its third differences, and the velocities before, in and after it.
        third = np.linalg.norm(np.diff(positions[first:last + 4], n=3, axis=0), axis=-1)
        jerks = np.where(np.isfinite(third), third, -np.inf).max(axis=0)  # (M,), metres
        velocity = np.diff(positions[low - frames:high + 2 + frames], axis=0)  # metres per frame
        # The point that jerks most among those seen all around the event.
        seen = np.isfinite(velocity).all(axis=(0, 2)) & np.isfinite(jerks)
        if not seen.any():
            out.append((first, last, None))
            continue
        point = int(np.argmax(np.where(seen, jerks, -np.inf)))
        size = jerks[point]
        before = velocity[:frames, point].mean(axis=0)
        after = velocity[-frames:, point].mean(axis=0)
        inside = velocity[frames:-frames, point]
        change = float(np.linalg.norm(after - before))
        # How far the velocities inside stray from the segment between the old and the new velocity.
        along = np.clip((inside - before) @ (after - before) / max(change ** 2, 1e-24), 0.0, 1.0)
        stray = float(np.linalg.norm(inside - (before + along[:, None] * (after - before)), axis=1).max())
        out.append((first, last, bool(change >= 0.5 * size and stray <= SPIKE_STRAY * change)))
    return out


def jerk_warnings(positions, rate: float, *, what: str = "joint", z: float = SPIKE_Z,
                  min_jump: float = SPIKE_JUMP) -> list[str]:
    """One line when :func:`jerk_spikes` finds spikes in the motion, saying which of them change course at once
    and keep to it (:func:`spike_events`: an impact, a flick) and which jump.

    Parameters
    ----------
    positions : ndarray of shape (T, M, 3)
        Metres.
    rate : float
        Hz.
    what : str
        Names the points in the message (``"joint"``, ``"marker"``, ``"object"``).
    z, min_jump : float
        As for :func:`jerk_spikes`.

    Returns
    -------
    list of str
    """
    positions = np.asarray(positions, dtype=np.float64)
    if positions.ndim == 2:
        positions = positions[:, None]
    spikes = jerk_spikes(positions, rate, z=z, min_jump=min_jump)
    if not len(spikes):
        return []
    third = np.linalg.norm(np.diff(positions, n=3, axis=0), axis=-1)
    per_frame = np.where(np.isfinite(third), third, -np.inf).max(axis=1) if third.size else third
    per_frame = np.where(np.isfinite(per_frame), per_frame, np.nan)  # frames with every point missing
    median = float(np.nanmedian(per_frame)) * rate**3
    worst = float(np.nanmax(per_frame[spikes])) * rate**3
    events = spike_events(positions, rate, spikes)
    turns = sum(1 for *_, kind in events if kind)
    jumps = [first for first, _, kind in events if kind is False]
    untold = [first for first, _, kind in events if kind is None]
    line = (f"{what} jerk spikes in {len(spikes)} frames (first: frame {spikes[0]}, {spikes[0] / rate:.2f} s): "
            f"up to {worst:.3g} m/s^3 against a median of {median:.3g} m/s^3 (plausible: within {z:g} robust "
            f"deviations of the median)")
    if turns == len(events):
        return [line + f"; each of the {len(events)} changes course at once and keeps to it (an impact or a flick, "
                "not a jump): check them if nothing was hit there"]
    if turns:
        line += f"; {turns} of the {len(events)} change course at once and keep to it (an impact or a flick)"
    if jumps:
        line += f"; {len(jumps)} jump (first: frame {jumps[0]}, {jumps[0] / rate:.2f} s)"
    if untold:
        line += (f"; {len(untold)} cannot be told, points missing around them (first: frame {untold[0]}, "
                 f"{untold[0] / rate:.2f} s)")
    return [line + "; look for label swaps or a lost fit there"]


#: (parent, child) joints of the 20 bones: the 15 MANO bones, then the 5 tips off the last joint of their finger.
_BONES = [(0, 1), (1, 2), (2, 3), (0, 4), (4, 5), (5, 6), (0, 7), (7, 8), (8, 9), (0, 10), (10, 11), (11, 12),
          (0, 13), (13, 14), (14, 15), (15, 16), (3, 17), (6, 18), (12, 19), (9, 20)]
_JOINT_LABELS = ("wrist", "index1", "index2", "index3", "middle1", "middle2", "middle3", "pinky1", "pinky2",
                 "pinky3", "ring1", "ring2", "ring3", "thumb1", "thumb2", "thumb3", "thumb_tip", "index_tip",
                 "middle_tip", "ring_tip", "pinky_tip")


def bone_lengths(joints) -> np.ndarray:
    """Length of the 20 bones of handcap's 21 joints in every frame.

    Parameters
    ----------
    joints : ndarray of shape (T, 21, 3) or (21, 3)
        Metres (16 MANO joints, then the tips of thumb, index, middle, ring, pinky).

    Returns
    -------
    ndarray of shape (T, 20) or (20,)
        Metres, in the order of :data:`BONE_NAMES`.
    """
    joints = np.asarray(joints, dtype=np.float64)
    parent = [p for p, _ in _BONES]
    child = [c for _, c in _BONES]
    return np.linalg.norm(joints[..., child, :] - joints[..., parent, :], axis=-1)


#: Names of the bones of :func:`bone_lengths`, ``parent-child``.
BONE_NAMES = tuple(f"{_JOINT_LABELS[p]}-{_JOINT_LABELS[c]}" for p, c in _BONES)


def anthropometric_bone_lengths() -> np.ndarray:
    """The 20 bone lengths of the average adult hand (metres), from :mod:`handcap.hand.anthropometry`."""
    joints, tips = rest_joints()
    return bone_lengths(np.concatenate([joints, tips]))


def bone_warnings(joints, *, hand_length=HAND_LENGTH_RANGE, ratio: float = BONE_RATIO,
                  max_change: float = 0.2) -> list[str]:
    """Bones off the anthropometric range: the hand's size, each bone's proportion, and stretching bones.

    The expected lengths are those of the average adult hand (Buchholz et al. 1992 proportions,
    :mod:`handcap.hand.anthropometry`). The hand's scale is the median over its bones of measured / expected
    length (median over frames), which gives its hand length; each bone is then compared with its
    expected length at that scale. A hand motion from a hand model has rigid bones; joints from elsewhere
    (markers on the joints, keypoints) are also checked for bones that change length over the take.

    Parameters
    ----------
    joints : ndarray of shape (T, 21, 3)
        Metres; NaN where missing.
    hand_length : (float, float)
        Plausible hand lengths, metres (default :data:`HAND_LENGTH_RANGE`).
    ratio : float
        Plausible factor between a bone and its proportion (default :data:`BONE_RATIO`).
    max_change : float
        Largest plausible relative change of a bone's length over the take (10th to 90th percentile).

    Returns
    -------
    list of str
    """
    joints = np.asarray(joints, dtype=np.float64)
    if joints.ndim == 2:
        joints = joints[None]
    lengths = bone_lengths(joints)
    if not np.isfinite(lengths).any(axis=0).all():
        return []
    with np.errstate(all="ignore"):
        measured = np.nanmedian(lengths, axis=0)
    expected = anthropometric_bone_lengths()
    scale = float(np.median(measured / expected))
    out = []
    length = scale * AVERAGE_HAND_LENGTH
    if not hand_length[0] <= length <= hand_length[1]:
        out.append(f"hand length {MM * length:.4g} mm (from the bone lengths) is not an adult hand's (plausible: "
                   f"{MM * hand_length[0]:.0f}-{MM * hand_length[1]:.0f} mm); are the units right?")
    if scale > 0:
        factor = measured / (scale * expected)
        off = np.flatnonzero((factor > ratio) | (factor < 1 / ratio))
        if len(off):
            shown = ", ".join(f"{BONE_NAMES[i]} {MM * measured[i]:.1f} mm ({factor[i]:.2f} x)" for i in
                              off[np.argsort(-np.abs(np.log(factor[off])))][:4])
            out.append(f"{len(off)} bone(s) off the anthropometric proportions of a {MM * length:.0f} mm hand "
                       f"(plausible: {1 / ratio:.2f}-{ratio:.2f} x): {shown}")
    with np.errstate(all="ignore"):
        low, high = np.nanpercentile(lengths, [10, 90], axis=0)
        change = (high - low) / measured
    stretch = np.flatnonzero(change > max_change)
    if len(stretch):
        out.append(f"{len(stretch)} bone(s) change length over the take by more than {100 * max_change:g} %: "
                   + ", ".join(f"{BONE_NAMES[i]} {100 * change[i]:.0f} %" for i in stretch[:4])
                   + "; joints of a rigid skeleton keep their lengths")
    return out


def spread(positions) -> np.ndarray:
    """Extent of the points in every frame: the diagonal of their bounding box (metres), NaN with < 2 points.

    Parameters
    ----------
    positions : ndarray of shape (T, M, 3)

    Returns
    -------
    ndarray of shape (T,)
    """
    positions = np.asarray(positions, dtype=np.float64)
    seen = np.isfinite(positions).all(axis=-1)
    high = np.where(seen[..., None], positions, -np.inf).max(axis=1)
    low = np.where(seen[..., None], positions, np.inf).min(axis=1)
    with np.errstate(invalid="ignore"):
        out = np.linalg.norm(high - low, axis=-1)
    out[seen.sum(axis=1) < 2] = np.nan
    return out


def size_warnings(positions, *, plausible=HAND_SPREAD, what: str = "hand markers", min_markers: int = 3) -> list[str]:
    """Extent of a set of markers (one hand's, or a capture's) outside the plausible range.

    The median over frames with at least ``min_markers`` markers of the bounding-box diagonal
    (:func:`spread`); a hand's markers span 0.03-0.35 m. Units wrong by 1000 show here first.

    Parameters
    ----------
    positions : ndarray of shape (T, M, 3)
        Metres, NaN where missing.
    plausible : (float, float)
        Metres; default :data:`HAND_SPREAD` (use :data:`CAPTURE_SPREAD` for every marker of a capture).
    what : str
        Names the markers in the message.
    min_markers : int

    Returns
    -------
    list of str
    """
    positions = np.asarray(positions, dtype=np.float64)
    if positions.ndim != 3 or positions.shape[1] < min_markers:
        return []
    extent = spread(positions)
    enough = np.isfinite(positions).all(axis=-1).sum(axis=1) >= min_markers
    extent = extent[enough & np.isfinite(extent)]
    if not len(extent):
        return []
    size = float(np.median(extent))
    if plausible[0] <= size <= plausible[1]:
        return []
    hint = " (millimetres read as metres?)" if size > plausible[1] else " (metres read as millimetres?)"
    return [f"{what} span {size:.4g} m (median over frames; plausible: {plausible[0]:g}-{plausible[1]:g} m)"
            + hint]


def speeds(positions, rate: float) -> np.ndarray:
    """Speed of every marker between consecutive frames, metres per second; NaN where either is missing.

    Parameters
    ----------
    positions : ndarray of shape (T, M, 3)
    rate : float
        Hz.

    Returns
    -------
    ndarray of shape (T - 1, M)
    """
    positions = np.asarray(positions, dtype=np.float64)
    return np.linalg.norm(np.diff(positions, axis=0), axis=-1) * float(rate)


def speed_warnings(positions, rate: float, *, names=None, limit: float = MAX_SPEED) -> list[str]:
    """Markers moving faster than a hand can (between consecutive frames).

    Parameters
    ----------
    positions : ndarray of shape (T, M, 3)
        Metres, NaN where missing.
    rate : float
        Hz.
    names : sequence of str, optional
    limit : float
        Metres per second (default :data:`MAX_SPEED`).

    Returns
    -------
    list of str
        One line: how many samples are too fast, the worst markers, and, when the typical speed itself is
        too fast, that the units or the rate are wrong.
    """
    v = speeds(positions, rate)
    seen = np.isfinite(v)
    if not seen.any():
        return []
    typical = float(np.median(v[seen]))
    if typical > limit:
        return [f"markers move at {typical:.4g} m/s typically (median; plausible: <= {limit:g} m/s): the units or "
                f"the frame rate ({rate:g} Hz) are wrong"]
    fast = seen & (v > limit)
    if not fast.any():
        return []
    labels = default_names(names, v.shape[1])
    per_marker = np.where(fast, v, 0.0).max(axis=0)
    worst = np.flatnonzero(per_marker > 0)
    return [f"{int(fast.sum())} samples ({100 * fast.sum() / seen.sum():.2g} %) move faster than {limit:g} m/s: "
            f"{listed([labels[i] for i in worst], per_marker[worst], 'm/s', 1.0)}; label swaps or spikes?"]
