"""Scoring a labeling against the truth (the categories of Tables 1 and 2 of the paper).

For every label and frame (an instance), comparing the labeled output with the
truth (both :class:`MarkerSequence`, matched by name):

- **correct**: the output has the label on the true marker's point, or both
  report a gap (a correctly reported gap);
- **erroneous**: the output has the label on another point while the true
  marker is visible;
- **false marker**: the output has the label on a point while the true marker
  is missing (an occlusion labelled as a marker);
- **false occlusion**: the output reports a gap while the true marker is
  visible.

Points are the same floats in both (the output's points come from the
unlabeled input the truth was made with), so "the true marker's point" means
within ``tolerance`` (default 0.1 mm, above the rounding of any file format).

Fragmentation of the truth, per label: gaps are runs of missing frames between
two visible ones; segments are runs of visible frames.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from handcap.core.errors import HandcapError
from handcap.core.markers import MarkerSequence

CATEGORIES = ("correct", "erroneous", "false_marker", "false_occlusion")


@dataclass(frozen=True)
class LabelScore:
    """Counts per label (arrays (M,)) and fragmentation of the truth.

    Attributes
    ----------
    names : tuple of str
    correct, erroneous, false_marker, false_occlusion : ndarray (M,) int
    gaps : ndarray (M,) int
    gap_frames, segment_frames : list of ndarray
        Lengths of every gap and every segment of each label, frames.
    """

    names: tuple
    correct: np.ndarray
    erroneous: np.ndarray
    false_marker: np.ndarray
    false_occlusion: np.ndarray
    gaps: np.ndarray
    gap_frames: list
    segment_frames: list

    @property
    def instances(self) -> int:
        """Number of (label, frame) instances scored: the four categories summed over every label."""
        return int(sum(getattr(self, c).sum() for c in CATEGORIES))

    def fraction(self, category: str) -> float:
        """Share of all instances in a category (0..1)."""
        return float(getattr(self, category).sum()) / max(self.instances, 1)

    def summary(self) -> str:
        """The Table-1 style table of :meth:`table`, without a title."""
        return self.table()

    def table(self, title: str = "") -> str:
        """A Table-1 style text table: overall, then per label."""
        def row(label, counts, n, gaps, gap_len, seg_len):
            cells = [f"{counts[c]:7d} ({100 * counts[c] / max(n, 1):6.2f}%)" for c in CATEGORIES]
            return (f"{label:16s} {n:9d} " + " ".join(cells)
                    + f" {gaps:5d} {gap_len:8.1f} {seg_len:8.1f}")
        head = (f"{'':16s} {'instances':>9s} " + " ".join(f"{c.replace('_', ' '):>17s}" for c in CATEGORIES)
                + f" {'gaps':>5s} {'mean gap':>8s} {'mean seg':>8s}")
        lines = [title] if title else []
        lines.append(head)
        all_gaps = np.concatenate(self.gap_frames) if self.gap_frames else np.zeros(0)
        all_segs = np.concatenate(self.segment_frames) if self.segment_frames else np.zeros(0)
        lines.append(row("all", {c: int(getattr(self, c).sum()) for c in CATEGORIES}, self.instances,
                         int(self.gaps.sum()), _mean(all_gaps), _mean(all_segs)))
        for i, name in enumerate(self.names):
            counts = {c: int(getattr(self, c)[i]) for c in CATEGORIES}
            lines.append(row(name, counts, sum(counts.values()), int(self.gaps[i]), _mean(self.gap_frames[i]),
                             _mean(self.segment_frames[i])))
        return "\n".join(lines)

    def to_dict(self) -> dict:
        """The score as plain numbers for JSON.

        Returns
        -------
        dict
            ``instances``; per category its count and ``<category>_percent`` (0..100);
            ``per_marker``: {name: {category: count}}.
        """
        out = {"instances": self.instances}
        for c in CATEGORIES:
            out[c] = int(getattr(self, c).sum())
            out[f"{c}_percent"] = 100 * self.fraction(c)
        out["per_marker"] = {n: {c: int(getattr(self, c)[i]) for c in CATEGORIES} for i, n in enumerate(self.names)}
        return out


def _mean(values) -> float:
    return float(np.mean(values)) if len(values) else 0.0


def runs(mask) -> tuple[np.ndarray, np.ndarray]:
    """Lengths of the runs of True in a 1-D mask, and whether each touches an end of the take."""
    m = np.asarray(mask, dtype=np.int8)
    edges = np.diff(np.r_[0, m, 0])
    starts, stops = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)
    return stops - starts, (starts == 0) | (stops == len(m))


def score_labels(labeled: MarkerSequence, truth: MarkerSequence, names=None, *,
                 tolerance: float = 1e-4) -> LabelScore:
    """Compare a labeled take with the truth, label by label and frame by frame.

    Parameters
    ----------
    labeled, truth : MarkerSequence
        Same number of frames; labels matched by name (``Subject:`` prefixes ignored).
    names : sequence of str, optional
        Labels to score (default: the truth's).
    tolerance : float
        Distance under which the output's point is the true one, metres.
    """
    if labeled.n_frames != truth.n_frames:
        raise HandcapError(f"the labeled take has {labeled.n_frames} frames, the truth {truth.n_frames}")
    names = list(truth.short_names if names is None else names)
    counts = {c: np.zeros(len(names), dtype=np.int64) for c in CATEGORIES}
    gaps, gap_frames, segment_frames = np.zeros(len(names), dtype=np.int64), [], []
    for i, name in enumerate(names):
        true = truth.positions[:, truth.index(name)]
        try:
            out = labeled.positions[:, labeled.index(name)]
        except HandcapError:
            out = np.full_like(true, np.nan)  # a label the output never gives: all gaps
        t_seen, o_seen = ~np.isnan(true[:, 0]), ~np.isnan(out[:, 0])
        same = np.linalg.norm(np.nan_to_num(out) - np.nan_to_num(true), axis=1) < tolerance
        counts["correct"][i] = ((t_seen & o_seen & same) | (~t_seen & ~o_seen)).sum()
        counts["erroneous"][i] = (t_seen & o_seen & ~same).sum()
        counts["false_marker"][i] = (~t_seen & o_seen).sum()
        counts["false_occlusion"][i] = (t_seen & ~o_seen).sum()
        gap_len, gap_edge = runs(~t_seen)
        seg_len, _ = runs(t_seen)
        inner = gap_len[~gap_edge]
        gaps[i] = len(inner)
        gap_frames.append(inner)
        segment_frames.append(seg_len)
    return LabelScore(tuple(names), counts["correct"], counts["erroneous"], counts["false_marker"],
                      counts["false_occlusion"], gaps, gap_frames, segment_frames)
