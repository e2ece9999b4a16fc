"""Plausibility checks: the figures of a result turned into one-line warnings (issue 14).

handcap never gives a silent wrong answer. Every stage that writes a result runs the checks below on it;
each check is a pure function that returns a list of one-line warnings (empty when the result looks
plausible). A warning names the figure, its value and the plausible range, so a user can judge it without
reading the code, e.g. ``"solve: MRE 13.1 mm is above 5 mm (plausible: <= 5 mm); ..."``.

The caller decides what to do with them: library code issues them with :func:`handcap.core.errors.warn`
and stores them on its result (:func:`attach` does both for the containers); the command line prints them
and, with ``handcap --strict``, exits with code 2.

Every limit is a module constant with the reason for its value; none is fitted to one file:

==================  =====================================================================================
``MRE_LIMIT``       5 mm: a marker fit worse than a marker's own radius means the model, the attachment
                    or the labels are wrong (issue 14; DexterCap and the real glove reach 1-3 mm).
``SHAPE_BOUND``     3: shape values are in standard deviations of adult hands (OpenHand); 3 is the bound
                    of the shape fit of ``calibrate_attachment`` and the edge of 99.7 % of adults.
``MIN_LABELED``     95 % of the visible points labelled (issue 14).
``SPIKE_Z``         10 robust standard deviations above the take's median jerk, and ``SPIKE_JUMP``
``SPIKE_JUMP``      5 mm: the one-frame jump a spike implies (a third difference of 3 x 5 mm).
``HAND_SPREAD``     0.03-0.35 m: the extent of the markers of one hand (a fist to a spread adult hand).
``MAX_SPEED``       10 m/s: faster than a hand moves (the fastest throws reach ~10 m/s at the wrist).
``HAND_LENGTH_RANGE`` average adult hand length +- 5 standard deviations (SD 5.2 %, Pheasant & Haslegrave
                    2006, as in :mod:`handcap.hand.anthropometry`): 135-230 mm.
``BONE_RATIO``      1.5: a bone longer or shorter than its anthropometric proportion by more than this
                    factor; OpenHand's shape space with every value at +-3 SD reaches 1.50.
``REPROJECTION_PX`` camera calibration RMS above 1 px (a well-detected board gives 0.1-0.5 px).
==================  =====================================================================================
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence

import numpy as np

from handcap.core.errors import merge_warnings, warn
from handcap.hand.anthropometry import HAND_LENGTH as AVERAGE_HAND_LENGTH
from handcap.hand.anthropometry import rest_joints

#: Largest plausible mean marker error (solve, calibration), metres.
MRE_LIMIT = 0.005
#: Shape values (standard deviations of adult hands) at or beyond this are reported.
SHAPE_BOUND = 3.0
#: Smallest plausible fraction of visible points that get a label.
MIN_LABELED = 0.95
#: A jerk spike: this many robust standard deviations above the take's median jerk ...
SPIKE_Z = 10.0
#: ... and a one-frame jump of at least this many metres (its third difference is 3 x the jump).
SPIKE_JUMP = 0.005
#: Plausible extent (bounding-box diagonal) of the markers of one hand, metres.
HAND_SPREAD = (0.03, 0.35)
#: Plausible extent of all markers of a capture, metres (no capture volume is larger; a hand is not smaller).
CAPTURE_SPREAD = (0.01, 30.0)
#: Fastest plausible marker speed, metres per second.
MAX_SPEED = 10.0
#: Plausible adult hand length, metres: 182.5 mm +- 5 SD of 5.2 % (Pheasant & Haslegrave 2006).
HAND_LENGTH_RANGE = (0.1825 * (1 - 5 * 0.052), 0.1825 * (1 + 5 * 0.052))
#: Largest plausible factor between a bone's length and its anthropometric proportion of the hand.
BONE_RATIO = 1.5
#: Largest plausible reprojection RMS of a camera calibration, pixels.
REPROJECTION_PX = 1.0

_MM = 1000.0


def _listed(names: Sequence[str], values, unit: str = "mm", scale: float = _MM, most: int = 4) -> str:
    """``a (6.1 mm), b (5.5 mm) and 3 more``: the worst ``most`` entries first."""
    order = np.argsort(-np.asarray(values, dtype=np.float64), kind="stable")
    shown = [f"{names[i]} ({scale * values[i]:.1f} {unit})" for i in order[:most]]
    rest = len(order) - len(shown)
    return ", ".join(shown) + (f" and {rest} more" if rest > 0 else "")


def _names(names, count: int, prefix: str = "marker") -> list[str]:
    names = list(names) if names is not None else []
    return names if len(names) == count else [f"{prefix} {i}" for i in range(count)]


# -- fits: residuals, limits, shape -----------------------------------------------------------------


def residual_warnings(residuals, *, names=None, what: str = "MRE", limit: float = MRE_LIMIT) -> list[str]:
    """Mean marker error of a fit, overall and per marker, against ``limit``.

    Parameters
    ----------
    residuals : ndarray of shape (T, M)
        Distance between fitted and observed markers, metres; NaN where unobserved.
    names : sequence of str, optional
        The M marker names (for the per-marker warning).
    what : str
        Names the figure in the message, e.g. ``"solve MRE"`` or ``"calibration MRE"``.
    limit : float
        Metres (default :data:`MRE_LIMIT`).

    Returns
    -------
    list of str
        One warning when the mean over every observed sample exceeds ``limit``, and one naming the
        markers whose own mean exceeds it (at most one line each).
    """
    residuals = np.asarray(residuals, dtype=np.float64)
    if residuals.ndim == 1:
        residuals = residuals[None]
    seen = np.isfinite(residuals)
    if not seen.any():
        return []
    out = []
    mre = float(residuals[seen].mean())
    if mre > limit:
        out.append(f"{what} {_MM * mre:.2f} mm is above {_MM * limit:g} mm (plausible: <= {_MM * limit:g} mm); "
                   f"check the labels, the layout's segments and the attachment")
    counts = seen.sum(axis=0)
    per_marker = np.where(counts > 0, np.where(seen, residuals, 0.0).sum(axis=0) / np.maximum(counts, 1), 0.0)
    bad = np.flatnonzero(per_marker > limit)
    if len(bad) and len(bad) < residuals.shape[1]:
        labels = _names(names, residuals.shape[1])
        out.append(f"{what} of {len(bad)} marker(s) above {_MM * limit:g} mm: "
                   f"{_listed([labels[i] for i in bad], per_marker[bad])}")
    return out


def limit_warnings(values, limit: float, *, names=None, what: str = "shift from the layout position",
                   advice: str = "its layout position or segment may be wrong", scale: float = _MM,
                   unit: str = "mm", tolerance: float = 1e-3) -> list[str]:
    """Markers whose value ended at the limit a fit allows it (it wanted to go further).

    For example the distance each calibrated marker moved from its layout position, against the cap
    ``handcap.solve.calibration.MAX_SHIFT``: a marker held at the cap did not find its place.

    Parameters
    ----------
    values : ndarray of shape (M,)
        The figure per marker (metres by default), NaN where undefined.
    limit : float
        The largest value the fit allows.
    names : sequence of str, optional
    what, advice : str
        Name the figure and say what to check, in the message.
    scale, unit : float, str
        How to print values (default millimetres).
    tolerance : float
        Relative: values within ``limit * (1 - tolerance)`` of the limit count as at it.

    Returns
    -------
    list of str
        At most one line, naming the markers at the limit.
    """
    values = np.abs(np.asarray(values, dtype=np.float64).ravel())
    stuck = np.flatnonzero(np.isfinite(values) & (values >= abs(limit) * (1 - tolerance)))
    if not len(stuck):
        return []
    labels = _names(names, len(values))
    return [f"{len(stuck)} marker(s) at the limit of their {what} ({scale * limit:g} {unit}): "
            f"{_listed([labels[i] for i in stuck], values[stuck], unit, scale)}; {advice}"]


def shape_warnings(betas, *, bound: float = SHAPE_BOUND) -> list[str]:
    """Shape values at or beyond ``bound`` standard deviations of adult hands.

    Parameters
    ----------
    betas : ndarray of shape (10,)
    bound : float
        Default :data:`SHAPE_BOUND` (the shape fit's bound).

    Returns
    -------
    list of str
        At most one line naming the values; the shape fit pushed against its bound (the model cannot
        take the hand's proportions), or a hand given outside the adult range.
    """
    betas = np.asarray(betas, dtype=np.float64).ravel()
    if not np.isfinite(betas).all():
        return [f"shape values (betas) are not finite: {np.round(betas, 2).tolist()}"]
    at = np.flatnonzero(np.abs(betas) >= bound * (1 - 1e-3))
    if not len(at):
        return []
    listed = ", ".join(f"betas[{i}] = {betas[i]:.2f}" for i in at)
    return [f"shape value(s) at or beyond +-{bound:g} standard deviations of adult hands: {listed} (plausible: "
            f"|betas| < {bound:g}); a fit that ends there could not take the hand's proportions (check the labels "
            f"and the layout)"]


# -- labels ---------------------------------------------------------------------------------------


def labeling_warnings(points, labeled, *, n_labels: int | None = None, lost_frames=(),
                      min_fraction: float = MIN_LABELED) -> list[str]:
    """Labels given to too few of the visible points, and frames where the hand frame was lost.

    Parameters
    ----------
    points : int or ndarray of shape (T,)
        Visible (unlabeled) points, in total or per frame.
    labeled : int or ndarray of shape (T,)
        Points that received a label, in total or per frame.
    n_labels : int, optional
        Labels the layout has (M). A frame can have at most M labelled points, so with per-frame counts the
        fraction is ``sum labeled / sum min(points, M)``: ghosts beyond M do not count as missed labels.
    lost_frames : sequence of int
        Frames in which the labeler could not find the hand frame (e.g. ``LabelingResult.lost_frames``).
    min_fraction : float
        Default :data:`MIN_LABELED`.

    Returns
    -------
    list of str
    """
    if n_labels is not None:
        points = np.minimum(points, int(n_labels))
    n_points = float(np.sum(points))
    n_labeled = float(np.sum(labeled))
    n_frames = int(np.size(points)) if np.ndim(points) else 0
    out = []
    if n_points > 0 and n_labeled / n_points < min_fraction:
        out.append(f"labels for {100 * n_labeled / n_points:.1f} % of the visible points (plausible: >= "
                   f"{100 * min_fraction:g} %); the take may differ from the training take (marker placement, "
                   f"layout)")
    lost = np.asarray(list(lost_frames), dtype=int)
    if len(lost):
        of = f" of {n_frames}" if n_frames else ""
        out.append(f"hand frame lost in {len(lost)}{of} frames (first: {lost.min()}); the rigid markers did not "
                   f"match the training take there")
    return out


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


def jerk_warnings(positions, rate: float, *, what: str = "joint", z: float = SPIKE_Z,
                  min_jump: float = SPIKE_JUMP) -> list[str]:
    """One line when :func:`jerk_spikes` finds spikes in the motion.

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
    per_frame = np.nanmax(np.where(np.isfinite(third), third, np.nan), axis=1) if third.size else third
    median = float(np.nanmedian(per_frame)) * rate**3
    worst = float(np.nanmax(per_frame[spikes])) * rate**3
    return [f"{what} jerk spikes in {len(spikes)} frames (first: frame {spikes[0]}, {spikes[0] / rate:.2f} s): "
            f"up to {worst:.3g} m/s^3 against a median of {median:.3g} m/s^3 (plausible: within {z:g} robust "
            f"deviations of the median); look for label swaps or a lost fit there"]


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
        out.append(f"hand length {_MM * length:.4g} mm (from the bone lengths) is not an adult hand's (plausible: "
                   f"{_MM * hand_length[0]:.0f}-{_MM * hand_length[1]:.0f} mm); are the units right?")
    if scale > 0:
        factor = measured / (scale * expected)
        off = np.flatnonzero((factor > ratio) | (factor < 1 / ratio))
        if len(off):
            shown = ", ".join(f"{BONE_NAMES[i]} {_MM * measured[i]:.1f} mm ({factor[i]:.2f} x)" for i in
                              off[np.argsort(-np.abs(np.log(factor[off])))][:4])
            out.append(f"{len(off)} bone(s) off the anthropometric proportions of a {_MM * length:.0f} mm hand "
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
    labels = _names(names, v.shape[1])
    per_marker = np.where(fast, v, 0.0).max(axis=0)
    worst = np.flatnonzero(per_marker > 0)
    return [f"{int(fast.sum())} samples ({100 * fast.sum() / seen.sum():.2g} %) move faster than {limit:g} m/s: "
            f"{_listed([labels[i] for i in worst], per_marker[worst], 'm/s', 1.0)}; label swaps or spikes?"]


# -- results of whole stages -----------------------------------------------------------------------------


def marker_warnings(markers, *, hand=None) -> list[str]:
    """Checks of a marker take: the capture's extent, one hand's extent, marker speeds.

    Parameters
    ----------
    markers : MarkerSequence
    hand : sequence of str, optional
        Names of the markers of one hand (a layout's ``names``); with them, their extent must be a hand's.

    Returns
    -------
    list of str
    """
    out = size_warnings(markers.positions, plausible=CAPTURE_SPREAD, what="all markers")
    if hand is not None:
        short = list(markers.short_names)
        wanted = {str(n).split(":")[-1] for n in hand}
        idx = [i for i, n in enumerate(short) if n in wanted]
        if len(idx) >= 3:
            out += size_warnings(markers.positions[:, idx], what="the hand's markers")
    if not out:  # wrong units already said; speeds would repeat it
        out += speed_warnings(markers.positions, markers.rate, names=markers.names)
    return out


def clean_warnings(report, missing_before, *, limit: float = 0.1) -> list[str]:
    """Cleaning that removed more than ``limit`` of the observed samples.

    Spikes and points away from their patch are the exception in a capture; when cleaning removes a tenth
    of what was observed, the layout, the cluster radius or the outlier threshold does not fit the take.

    Parameters
    ----------
    report : CleanReport
        From :func:`handcap.multiview.clean.clean_markers` (``cluster_removed``, ``outlier_removed``: (T, M)).
    missing_before : ndarray of shape (T, M) bool
        The input's missing samples.
    limit : float
        Largest plausible fraction removed.

    Returns
    -------
    list of str
    """
    observed = int((~np.asarray(missing_before, dtype=bool)).sum())
    removed = int(np.sum(report.cluster_removed) + np.sum(report.outlier_removed))
    if not observed or removed <= limit * observed:
        return []
    return [f"cleaning removed {100 * removed / observed:.1f} % of the observed samples (plausible: <= "
            f"{100 * limit:g} %); the layout, --radius-mm or --z may not fit this take"]


def motion_warnings(motion, *, what: str = "solve MRE") -> list[str]:
    """Checks of a :class:`~handcap.core.motion.HandMotion`: MRE, shape at bounds, bones, jerk spikes.

    Parameters
    ----------
    motion : HandMotion
    what : str
        Names the residual figure.

    Returns
    -------
    list of str
    """
    out = []
    if motion.marker_residuals is not None:
        out += residual_warnings(motion.marker_residuals, names=motion.marker_names, what=what)
    out += shape_warnings(motion.betas)
    if motion.joints is not None:
        out += bone_warnings(motion.joints)
        out += jerk_warnings(motion.joints, motion.rate, what="joint")
    return out


def object_warnings(track, *, threshold: float, rate: float | None = None) -> list[str]:
    """Checks of a rigid object's track (:class:`handcap.objects.rigid.RigidTrack`).

    The residual of a rigid fit is the markers' noise; crowding against the inlier distance (more than
    half of it on average) means the object is not rigid or its markers are mislabelled. Also: frames
    left unsolved, and jerk spikes of the object's origin.

    Parameters
    ----------
    track : RigidTrack
    threshold : float
        The RANSAC inlier distance used, metres.
    rate : float, optional
        Hz; default the motion's.

    Returns
    -------
    list of str
    """
    out = []
    residual = track.mean_residual
    if np.isfinite(residual) and residual > 0.5 * threshold:
        out.append(f"object {track.motion.name!r}: mean residual {_MM * residual:.2f} mm is more than half the "
                   f"inlier distance {_MM * threshold:g} mm (plausible: <= {_MM * 0.5 * threshold:g} mm); is the "
                   f"object rigid and are its markers labelled right?")
    n = track.motion.n_frames
    if n and len(track.unsolved) > 0.05 * n:
        out.append(f"object {track.motion.name!r}: no pose in {len(track.unsolved)} of {n} frames "
                   f"({100 * len(track.unsolved) / n:.0f} %; plausible: < 5 %) with fewer than 3 markers")
    out += jerk_warnings(track.motion.translation[:, None], rate or track.motion.rate,
                         what=f"object {track.motion.name!r}")
    return out


def triangulation_warnings(error_px, views, *, threshold_px: float, used=None, min_fraction: float = 0.5
                           ) -> list[str]:
    """Checks of triangulated markers: reprojection error against the inlier threshold, rejected views,
    markers rarely reconstructed.

    Parameters
    ----------
    error_px : ndarray of shape (T, M)
        Mean reprojection error over the inlier views, pixels; NaN where no point.
    views : ndarray of shape (T, M)
        Inlier views (0 where no point).
    threshold_px : float
        The inlier threshold used, pixels.
    used : ndarray of shape (N,) bool, optional
        Per detection: kept as an inlier.
    min_fraction : float
        Fewest plausible fraction of frames in which a marker is reconstructed.

    Returns
    -------
    list of str
    """
    error_px = np.asarray(error_px, dtype=np.float64)
    out = []
    found = np.isfinite(error_px)
    if not found.any():
        return ["no marker was triangulated in any frame; check that the cameras file matches the detections"]
    mean = float(error_px[found].mean())
    if mean > 0.5 * threshold_px:
        out.append(f"mean reprojection error {mean:.2f} px is more than half the inlier threshold "
                   f"{threshold_px:g} px (plausible: <= {0.5 * threshold_px:g} px); the camera calibration may "
                   f"be off (units, distortion) or belong to another session")
    if used is not None:
        used = np.asarray(used, dtype=bool)
        rejected = 1 - used.mean() if used.size else 0.0
        if rejected > 0.25:
            out.append(f"{100 * rejected:.0f} % of the detections were rejected as outliers (plausible: <= 25 %)")
    return out


def camera_warnings(rms, *, names=None, limit: float = REPROJECTION_PX) -> list[str]:
    """Cameras whose calibration reprojects the board worse than ``limit`` pixels (RMS).

    Parameters
    ----------
    rms : float or ndarray of shape (C,)
        Reprojection RMS per camera, pixels.
    names : sequence of str, optional
    limit : float
        Default :data:`REPROJECTION_PX`.

    Returns
    -------
    list of str
    """
    rms = np.atleast_1d(np.asarray(rms, dtype=np.float64))
    bad = np.flatnonzero(~(rms <= limit))
    if not len(bad):
        return []
    labels = _names(names, len(rms), "camera")
    return [f"reprojection RMS above {limit:g} px (plausible: <= {limit:g} px) for "
            f"{_listed([labels[i] for i in bad], np.nan_to_num(rms[bad], nan=np.inf), 'px', 1.0)}; "
            f"check the board's size and the detections"]


# -- the figures the checks look at, for summaries ------------------------------------------------------


def marker_figures(markers, *, hand=None) -> dict:
    """The figures :func:`marker_warnings` judges, for a summary (label -> value).

    Parameters
    ----------
    markers : MarkerSequence
    hand : sequence of str, optional
        Names of one hand's markers.

    Returns
    -------
    dict
        ``missing (%)``, ``extent (m)`` (median bounding-box diagonal of all markers), ``hand extent (m)``
        (with ``hand``), ``speed p99 (m/s)`` (99th percentile over every sample).
    """
    positions = markers.positions
    out = {"missing (%)": round(100 * float(np.isnan(positions[..., 0]).mean()), 2) if positions.size else None}
    with np.errstate(all="ignore"):
        extent = spread(positions)
        out["extent (m)"] = float(np.nanmedian(extent)) if np.isfinite(extent).any() else None
        if hand is not None:
            wanted = {str(n).split(":")[-1] for n in hand}
            idx = [i for i, n in enumerate(markers.short_names) if n in wanted]
            if len(idx) >= 2:
                extent = spread(positions[:, idx])
                out["hand extent (m)"] = float(np.nanmedian(extent)) if np.isfinite(extent).any() else None
        v = speeds(positions, markers.rate)
        out["speed p99 (m/s)"] = float(np.percentile(v[np.isfinite(v)], 99)) if np.isfinite(v).any() else None
    return out


def motion_figures(motion) -> dict:
    """The figures :func:`motion_warnings` judges, for a summary (label -> value).

    Parameters
    ----------
    motion : HandMotion

    Returns
    -------
    dict
        ``MRE (mm)``, ``largest |betas|``, ``hand length (mm)`` (from the bones), ``jerk spike frames``.
    """
    out = {}
    if motion.marker_residuals is not None and np.isfinite(motion.marker_residuals).any():
        out["MRE (mm)"] = _MM * float(np.nanmean(motion.marker_residuals))
    out["largest |betas|"] = float(np.abs(motion.betas).max())
    if motion.joints is not None and np.isfinite(motion.joints).any():
        with np.errstate(all="ignore"):
            measured = np.nanmedian(bone_lengths(motion.joints), axis=0)
        out["hand length (mm)"] = _MM * AVERAGE_HAND_LENGTH * float(np.median(measured / anthropometric_bone_lengths()))
        out["jerk spike frames"] = int(len(jerk_spikes(motion.joints, motion.rate)))
    return out


# -- attaching and summarising ------------------------------------------------------------------------


def attach(result, warnings: Iterable[str], *, issue: bool = True):
    """``result`` with ``warnings`` stored on it, each also issued as a :class:`~handcap.core.errors.HandcapWarning`.

    Parameters
    ----------
    result : MarkerSequence, HandMotion, ObjectMotion or MarkerAttachment
        Anything with ``with_warnings``.
    warnings : iterable of str
    issue : bool
        Also issue each with :func:`handcap.core.errors.warn` (the command line prints them once).

    Returns
    -------
    The same kind of object, with the warnings appended (repeats dropped).
    """
    lines = merge_warnings(list(warnings))
    if issue:
        for line in lines:
            warn(line, stacklevel=2)  # points at the caller of attach
    return result.with_warnings(*lines) if lines else result


def summary(title: str, figures, warnings: Sequence[str] = ()) -> str:
    """A compact, one-screen summary of a result: a title, aligned figures and the count of warnings.

    Parameters
    ----------
    title : str
        First line, e.g. the output path and what it holds.
    figures : dict of str to object, or sequence of (str, object)
        Label -> value; floats print with 4 significant digits, other values as they are; None is skipped.
    warnings : sequence of str
        Only counted here (the command line prints them on stderr).

    Returns
    -------
    str
        At most ``2 + len(figures)`` lines.
    """
    items = list(figures.items()) if isinstance(figures, dict) else list(figures)
    items = [(str(k), v) for k, v in items if v is not None]
    width = max([len(k) for k, _ in items] + [0])
    lines = [title]
    for key, value in items:
        text = f"{value:.4g}" if isinstance(value, (float, np.floating)) else str(value)
        lines.append(f"  {key:<{width}}  {text}")
    n = len(merge_warnings(list(warnings)))
    lines.append(f"  {'quality':<{width}}  " + (f"{n} warning(s), see below" if n else "no warnings"))
    return "\n".join(lines)
