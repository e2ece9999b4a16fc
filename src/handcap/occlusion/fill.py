"""Batch gap filling of a recorded take: ``handcap fill``.

    filled, report = fill_gaps(markers, "nn", model="glove-13", max_gap_s=0.5)

Methods:

``linear``, ``spline``
    Interpolation in time (straight line, or a cubic spline through every
    sample of the marker); interior gaps only.
``lk``, ``ma``, ``ac``, ``nn``
    The paper's predictors (last known position, moving average, affine
    combination, the autoencoder of an :class:`OcclusionModel`). A recorded
    take has a future, so each is run forwards and backwards in time and the
    two are blended linearly across the gap: the fill meets the measurement at
    both ends, with no re-entry jump. Gaps at the start (end) of the take get
    the backward (forward) pass only.

No gap longer than ``max_gap_s`` seconds is touched: beyond it the data stays
missing rather than invented. Markers the method cannot use (not in the model)
pass through unchanged. The input is never modified.

Never a silent wrong fill (issue 14): where the forward and backward passes of
a gap part by more than :data:`DISAGREE_M`, the fill is a guess between two
inconsistent predictions; such gaps are counted in a warning, stored on the
filled sequence with the model's own warnings.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from handcap.core.errors import HandcapError, warn
from handcap.core.checks import check_positive
from handcap.core.markers import MarkerSequence, runs
from handcap.occlusion.baselines import MA_WINDOW_S, ac_apply, ac_weights, ma_velocity
from handcap.occlusion.takes import marker_columns
from handcap.occlusion.filler import OcclusionFiller
from handcap.occlusion.history import HISTORY_S, check_history
from handcap.occlusion.model import OcclusionModel

FILL_METHODS = ("linear", "spline", "lk", "ma", "ac", "nn")
MAX_GAP_S = 0.5
#: Forward and backward predictions of a gap further apart than this (metres) make a warning; the
#: predictors' own errors over 0.5 s gaps of the real glove are a few millimetres.
DISAGREE_M = 0.02


@dataclass(frozen=True)
class FillReport:
    """What :func:`fill_gaps` did.

    Attributes
    ----------
    method : str
    max_gap_frames : int
    filled_gaps, filled_samples : int
    left_gaps, left_samples : int
        Gaps (samples) left missing: too long, or not fillable by the method.
    untouched : tuple of str
        Markers the method does not handle (not in the model).
    warnings : tuple of str
        Implausible fills (forward and backward passes far apart), and the model's warnings.
    """

    method: str
    max_gap_frames: int
    filled_gaps: int
    filled_samples: int
    left_gaps: int
    left_samples: int
    untouched: tuple = ()
    warnings: tuple = ()

    def summary(self) -> str:
        """One line: what was filled and what was left missing."""
        return (f"{self.filled_samples} samples in {self.filled_gaps} gaps filled ({self.method}, gaps up to "
                f"{self.max_gap_frames} frames), {self.left_gaps} gaps ({self.left_samples} samples) left missing"
                + (f"; not in the model, left as they were: {', '.join(self.untouched)}" if self.untouched else ""))


def _gaps(missing: np.ndarray):
    """(marker, start, length) of every run of missing samples."""
    out = []
    for m in range(missing.shape[1]):
        starts, lengths = runs(missing[:, m])
        out += [(m, int(s), int(n)) for s, n in zip(starts, lengths)]
    return out


def fill_gaps(markers: MarkerSequence, method: str, *, max_gap_s: float = MAX_GAP_S, model=None,
              progress=None, history_s: float = HISTORY_S) -> tuple[MarkerSequence, FillReport]:
    """Fill the gaps of a labeled take, up to ``max_gap_s`` seconds long.

    Parameters
    ----------
    markers : MarkerSequence
        Metres, NaN where missing.
    method : {"linear", "spline", "lk", "ma", "ac", "nn"}
    max_gap_s : float
        Longest gap filled, seconds.
    model : OcclusionModel, str or path, optional
        Needed by ``nn`` (a shipped layout name or a model file).
    progress : bool, optional
        Progress bar for ``nn`` (default: on a terminal only).
    history_s : float
        Seconds before a gap from which ``nn`` learns its error (:mod:`~handcap.occlusion.history`; 0: off).

    Returns
    -------
    filled : MarkerSequence
    report : FillReport

    Raises
    ------
    HandcapError
        Unknown method, bad ``max_gap_s`` or ``history_s``, ``nn`` without a model or with a take lacking the
        model's markers.
    """
    if method not in FILL_METHODS:
        raise HandcapError(f"unknown fill method {method!r}; choose one of {', '.join(FILL_METHODS)}")
    max_gap_s = check_positive(max_gap_s, "max_gap_s (seconds)")
    history_s = check_history(history_s)
    limit = int(np.floor(max_gap_s * markers.rate + 1e-9))
    positions = markers.positions
    t_count = markers.n_frames
    missing = np.isnan(positions).any(axis=-1)
    columns = np.arange(markers.n_markers)
    untouched = ()
    if method == "nn":
        if model is None:
            raise HandcapError("the nn method needs a trained model (--model, or a shipped layout name)")
        model = OcclusionModel.resolve(model)
        # The same name matching as train-occlusion (issue 14): exact, or without a Subject: prefix.
        columns = np.array(marker_columns(markers.names, model.names,
                                          f"the take (for the occlusion model {model.layout or 'model'})"))
        untouched = tuple(n for i, n in enumerate(markers.names) if i not in set(columns.tolist()))
    out = positions.copy()
    parted = []  # (distance, column, first frame) of gaps whose two passes disagree
    gaps = [(m, s, n) for (m, s, n) in _gaps(missing[:, columns])]
    fillable = [(m, s, n) for (m, s, n) in gaps if n <= limit and n < t_count]
    if method in ("linear", "spline"):
        fillable = [(m, s, n) for (m, s, n) in fillable if s > 0 and s + n < t_count]
    if fillable:
        sub = positions[:, columns]
        if method in ("linear", "spline"):
            values = _interpolate(sub, fillable, method)
        else:
            forward = _causal(sub, method, markers.rate, model, progress, history_s)
            backward = _causal(sub[::-1], method, markers.rate, model, progress, history_s)[::-1]
            values = {}
            for m, s, n in fillable:
                frames = np.arange(s, s + n)
                if s == 0:
                    values[m, s] = backward[frames, m]
                elif s + n == t_count:
                    values[m, s] = forward[frames, m]
                else:
                    w = ((frames - s + 1) / (n + 1))[:, None]
                    values[m, s] = (1 - w) * forward[frames, m] + w * backward[frames, m]
                    apart = np.linalg.norm(forward[frames, m] - backward[frames, m], axis=-1).max()
                    if apart > DISAGREE_M:
                        parted.append((apart, columns[m], s))
        done = []
        for m, s, n in fillable:
            v = values[m, s]
            if np.isfinite(v).all():
                out[s:s + n, columns[m]] = v
                done.append(n)
    else:
        done = []
    found = list(model.warnings) if method == "nn" else []
    if parted:
        apart, column, start = max(parted)
        found.append(warn(f"{len(parted)} of {len(done)} gaps filled ({method}) where the forward and backward "
                          f"predictions part by more than {100 * DISAGREE_M:g} cm (up to {100 * apart:.1f} cm, "
                          f"{markers.names[column]} from frame {start}): check them, or fill with a shorter "
                          "--max-gap"))
    report = FillReport(method, limit, len(done), int(sum(done)), len(gaps) - len(done),
                        int(sum(n for _, _, n in gaps) - sum(done)), untouched, tuple(found))
    filled = MarkerSequence(out, markers.names, markers.rate, markers.residuals, markers.warnings)
    return filled.with_warnings(*found), report


def _interpolate(positions, gaps, method):
    from scipy.interpolate import CubicSpline
    values, splines = {}, {}
    t = np.arange(len(positions))
    for m, s, n in gaps:
        frames = np.arange(s, s + n)
        seen = ~np.isnan(positions[:, m, 0])
        if method == "linear":
            values[m, s] = np.stack([np.interp(frames, t[seen], positions[seen, m, i]) for i in range(3)], axis=1)
        else:
            if m not in splines:
                splines[m] = CubicSpline(t[seen], positions[seen, m]) if seen.sum() >= 4 else None
            if splines[m] is None:  # too few samples for a cubic: a straight line
                values[m, s] = np.stack([np.interp(frames, t[seen], positions[seen, m, i]) for i in range(3)], 1)
            else:
                values[m, s] = splines[m](frames)
    return values


def _causal(positions, method, rate, model, progress, history_s=HISTORY_S):
    """The forward (causal) prediction of every missing sample, (T, M, 3), NaN where none."""
    if method == "nn":
        from tqdm import tqdm

        filler = OcclusionFiller(model, rate=rate, method="nn", reentry_speed=np.inf, regress=False,
                                 history_s=history_s)
        out = np.full(positions.shape, np.nan)
        hidden = None if progress is None else not progress
        for t in tqdm(range(len(positions)), desc="fill", unit="frame", disable=hidden, leave=False):
            result = filler.update(positions[t])
            if not result.lost:
                out[t] = result.markers
        return out
    t_count, m_count = positions.shape[:2]
    missing = np.isnan(positions).any(axis=-1)
    out = positions.copy()
    k = int(round(MA_WINDOW_S * rate))
    for m, s, n in _gaps(missing):
        if s == 0:
            continue
        frames = np.arange(s, s + n)
        last = positions[s - 1, m]
        if method == "lk":
            out[frames, m] = last
        elif method == "ma":
            history = positions[max(0, s - 1 - k):s, m][:, None]
            out[frames, m] = last + ma_velocity(history, rate)[0] * (frames - s + 1)[:, None]
        else:  # ac: weights on the last frame the marker was seen, over the markers seen then and now
            before = positions[s - 1]
            for t in frames:
                known = ~missing[s - 1] & ~missing[t]
                known[m] = False
                if known.sum() < 1:
                    continue
                w = ac_weights(before[known], before[m][None])
                out[t, m] = ac_apply(w, positions[t, known])[0]
    return out
