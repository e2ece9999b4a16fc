"""Labels checked against the solved hand: a labelled take's markers that the hand cannot have made are removed,
and markers it left unlabelled are given the point where the hand puts them.

A labeler (:mod:`handcap.labeling`) judges each frame by where markers usually sit around the back of the hand
and by how they moved; it knows nothing of the fingers' bones. Solving the hand from its labels
(:func:`handcap.solve.solve_hand`, whose robust loss lets a few wrong labels pull little) gives where every
marker must be in every frame. Then, in each frame the solve explains well (median residual under
``frame_ok``):

- a label further from its model marker than ``max(floor, spread x`` that marker's median residual ``)`` is
  removed (a fingertip label on the neighbouring finger, a ghost taken for a hidden marker);
- an unlabelled point within ``max(reach, 2 x`` the median residual ``)`` of a marker the frame lacks takes
  its label (one point per marker, nearest first; points with a label stay theirs), the hand solved again
  without the labels removed.

Frames the solve does not explain (all labels wrong at once: a wrong hand frame for a few frames) take the
model's markers carried over from the well-explained frames around them (linear between two, at most
``carry`` frames apart, or held from one within a third of that) and are judged the same way against
``carry_floor``. The markers of the hand's rigid set are removed only there: their labels come from the
rigid shape itself, and on a real glove the back's markers stray from a rigid palm by more than a finger's
do (the real Qualisys glove: 34-44 correct ``hand_left`` labels over 10 mm).

Measured with ``handcap label --offline`` (fingers untangled, then this check, its attachment calibrated as
:data:`CALIBRATION_PRIOR` says) on synthetic ``joints-19`` takes (``benchmarks/labeling.py``, 2026-12-02, the solve
looking for swapped labels): of another day (section 7), correct 99.21-99.79 % -> 99.77-99.91 %, wrong
0.027-0.045 % -> 0.000-0.018 %; of 11 other subjects (section 8), mean correct 99.65 -> 99.87 %, every subject's
up and none's wrong labels up (subject 19: a 34-frame swap the untangling leaves, found by the solve: 99.45 / 0.33
-> 99.95 / 0.014 % correct / wrong; 99.69 / 0.155 without the search).
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np
from scipy.optimize import linear_sum_assignment

from handcap.core.errors import HandcapError, warn
from handcap.core.markers import MarkerSequence
from handcap.core.motion import HandMotion
from handcap.solve.motion import solve_hand

#: Least share of frames the solve must explain for the check to judge anything.
MIN_EXPLAINED = 0.5
#: Share of the labels removed above which the labels are called into doubt (a warning): on synthetic takes of
#: another day 0.4-0.9 % go, on another subject's (wrongly labelled) take 10 %.
REMOVED_WARNING = 0.02
#: Pull to the open hand (metres per radian) of the attachment calibration that the check runs on the labelled
#: take itself. The calibration's default (``OPEN_HAND_WEIGHT``, 0.02) is for calibration takes that stay near
#: the open hand; a take's poses are any, and that pull fitted a synthetic random take's attachment with a
#: calibration MRE of 5.5 mm (0.8 mm with this), the solve then 10 mm off the fingertips in its most bent poses
#: and the check removing their right labels. Chosen on synthetic joints-19 takes of subjects 3-15 (0.02, 0.005,
#: 0.001 and 0 tried; the last three alike), checked on subjects 17-25, the real glove and glove-13 takes (where
#: 0 was worse): ``benchmarks/labeling.py`` sections 7 and 8. It is the solve's own weak pull (``Priors``).
CALIBRATION_PRIOR = 0.001
#: Share of the frames left unjudged (the solve explains neither them nor frames near them) above which a warning
#: says their labels went unchecked.
UNJUDGED_WARNING = 0.05


@dataclass(frozen=True)
class LabelCheck:
    """What the solved hand made of a labelled take.

    Attributes
    ----------
    markers : MarkerSequence
        The labels after the check, metres (the attachment's markers, in its order).
    removed, added : ndarray (T, M) bool
        Labels removed, and labels given to points that had none.
    explained : ndarray (T,) bool
        Frames the solve explained (median residual under ``frame_ok``).
    judged : ndarray (T,) bool
        Frames judged: explained, or carried over from explained frames around them.
    motion : HandMotion
        The solve of the labels before the check.
    warnings : tuple of str
        The solve explains too few frames to check any, leaves many unchecked, or the check removed many
        labels.
    """

    markers: MarkerSequence
    removed: np.ndarray
    added: np.ndarray
    explained: np.ndarray
    judged: np.ndarray
    motion: HandMotion
    warnings: tuple = ()

    def summary(self) -> str:
        """One line: labels removed and added, frames explained."""
        return (f"checked against the solved hand: {int(self.removed.sum())} labels removed, {int(self.added.sum())} "
                f"added; {100 * self.explained.mean():.1f} % of frames explained, {100 * self.judged.mean():.1f} % "
                f"judged")


def check_labels(markers: MarkerSequence, points, attachment, hand=None, *, rigid=(), frame_ok: float = 0.003,
                 floor: float = 0.010, spread: float = 4.0, reach: float = 0.005, carry: int = 12,
                 carry_floor: float = 0.015) -> LabelCheck:
    """Remove the labels the solved hand cannot have made and label the points it puts where markers are missing.

    Parameters
    ----------
    markers : MarkerSequence
        Labelled take (T frames), metres; the attachment's markers are checked (others are dropped).
    points : PointCloudSequence, MarkerSequence or ndarray (T, K, 3)
        The take's unlabelled points, metres (NaN rows ignored; a MarkerSequence's columns are its points).
    attachment : MarkerAttachment
        Where the markers sit on the hand (calibrated on this take's labels, say).
    hand : HandModel, optional
        The attachment's model.
    rigid : sequence of str
        The hand's rigid-set markers: removed only in frames the solve did not explain, or beyond
        ``max(carry_floor, limit)`` in those it did.
    frame_ok : float
        Median marker residual (metres) under which the solve explains a frame.
    floor, spread : float
        A label is removed beyond ``max(floor, spread x median residual of its marker)``, metres.
    reach : float
        An unlabelled point takes a missing marker's label within ``max(reach, 2 x median residual)``, metres.
    carry : int
        Frames between two explained frames over which their model markers are interpolated.
    carry_floor : float
        ``floor`` in carried-over frames, metres.

    Returns
    -------
    LabelCheck
    """
    names = list(attachment.marker_names)
    labelled = markers.select(names)
    if isinstance(points, MarkerSequence):  # a marker file read as unlabelled points: its columns
        points = points.positions
    pts = np.asarray(points.padded() if hasattr(points, "padded") else points, dtype=np.float64)
    if pts.ndim != 3 or pts.shape[0] != labelled.n_frames or pts.shape[-1] != 3:
        raise HandcapError(f"points must be (T, K, 3) with the take's {labelled.n_frames} frames, got {pts.shape}")
    motion = solve_hand(labelled, attachment, hand)
    pos = labelled.positions.copy()
    model = motion.marker_fit.copy()
    seen = np.isfinite(pos[..., 0])
    # Each label against where the hand puts its marker (the solve may have exchanged two swapped labels: its own
    # residuals are of the labels it solved).
    residual = np.where(seen, np.linalg.norm(np.nan_to_num(pos) - model, axis=-1), np.nan)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # frames or markers with no label
        frame_median = np.nanmedian(residual, axis=1)
        explained = frame_median < frame_ok
        scale = np.nan_to_num(np.nanmedian(np.where(explained[:, None], residual, np.nan), axis=0), nan=floor)
    n = len(explained)
    removed, added = np.zeros_like(seen), np.zeros_like(seen)
    if explained.mean() < MIN_EXPLAINED:
        line = warn(f"the hand solved from the labels explains {100 * explained.mean():.0f} % of the frames (median "
                    f"residual under {1000 * frame_ok:g} mm; plausible >= {100 * MIN_EXPLAINED:.0f} %): labels not "
                    f"checked; check the labels and the layout")
        return LabelCheck(labelled.with_warnings(line), removed, added, explained, explained.copy(), motion, (line,))
    judged = explained.copy()
    good = np.flatnonzero(explained)
    after = np.searchsorted(good, np.arange(n))
    for t in np.flatnonzero(~explained):
        b = good[after[t] - 1] if after[t] > 0 else None
        a = good[after[t]] if after[t] < len(good) else None
        if b is not None and a is not None and a - b <= carry:
            w = (t - b) / (a - b)
            model[t] = (1 - w) * model[b] + w * model[a]
        elif b is not None and t - b <= carry // 3:
            model[t] = model[b]
        elif a is not None and a - t <= carry // 3:
            model[t] = model[a]
        else:
            continue
        judged[t] = True
        residual[t] = np.where(seen[t], np.linalg.norm(np.nan_to_num(pos[t]) - model[t], axis=-1), np.nan)
    limit = np.maximum(floor, spread * scale)
    with np.errstate(invalid="ignore"):
        removed = seen & explained[:, None] & (residual > limit)
        # a rigid-set label goes only where the hand is not explained, or where it is and that label lies further
        # than a carried frame allows (the solve, kept on course by the frames around, outvoted it)
        fixed = [names.index(r) for r in rigid if r in names]
        removed[:, fixed] &= residual[:, fixed] > np.maximum(limit[fixed], carry_floor)
        removed |= seen & (judged & ~explained)[:, None] & (residual > np.maximum(limit, carry_floor))
    pos[removed] = np.nan
    if removed.any():  # the hand solved again without them: the wrong labels pulled it a little their way (a swap
        # the first solve found is gone with them: its labels lie off the hand it solved exchanged)
        again = solve_hand(MarkerSequence(pos, tuple(names), labelled.rate), attachment, hand,
                           mend_swaps=False).marker_fit
        model[explained] = again[explained]
    gate = np.maximum(reach, 2 * scale)
    for t in np.flatnonzero(judged):
        missing = np.flatnonzero(~np.isfinite(pos[t, :, 0]))
        free = pts[t][np.isfinite(pts[t, :, 0])]
        if not len(missing) or not len(free):
            continue
        taken = pos[t][np.isfinite(pos[t, :, 0])]
        if len(taken):
            free = free[np.linalg.norm(free[:, None] - taken[None], axis=-1).min(axis=1) > 1e-9]
        distance = np.linalg.norm(model[t, missing][:, None] - free[None], axis=-1)
        cost = np.where(distance < gate[missing][:, None], distance, np.inf)
        near = np.isfinite(cost).any(axis=1)
        if not near.any():
            continue
        rows, cols = linear_sum_assignment(np.where(np.isfinite(cost[near]), cost[near], 1e3))
        ok = np.isfinite(cost[near][rows, cols])
        marker = missing[near][rows[ok]]
        pos[t, marker] = free[cols[ok]]
        added[t, marker] = True
    lines = ()
    if (~judged).mean() > UNJUDGED_WARNING:
        lines += (warn(f"the hand solved from the labels does not explain {100 * (~judged).mean():.0f} % of the "
                       f"frames (median residual over {1000 * frame_ok:g} mm, none explained within {carry} frames; "
                       f"plausible <= {100 * UNJUDGED_WARNING:g} %): their labels were not checked and may be wrong"),)
    if removed.sum() > REMOVED_WARNING * max(seen.sum(), 1):
        lines += (warn(f"the check against the solved hand removed {int(removed.sum())} labels ("
                      f"{100 * removed.sum() / seen.sum():.1f} % of them; plausible < {100 * REMOVED_WARNING:g} %): "
                      f"many labels did not fit the hand (another subject or marker placement? train on a take of "
                      f"it)"),)
    out = MarkerSequence(pos, tuple(names), labelled.rate, warnings=(*labelled.warnings, *lines))
    return LabelCheck(out, removed, added, explained, judged, motion, lines)
