"""Labeled marker trajectories: ``MarkerSequence`` and gap statistics."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from handcap.core.checks import check_positions, check_rate
from handcap.core.errors import HandcapError, merge_warnings


def runs(mask: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Start indices and lengths of the runs of True in a 1-D boolean mask."""
    padded = np.concatenate([[False], np.asarray(mask, dtype=bool), [False]])
    edges = np.flatnonzero(np.diff(padded.astype(np.int8)))
    starts, stops = edges[0::2], edges[1::2]
    return starts, stops - starts


@dataclass(frozen=True)
class MarkerGaps:
    """Gap statistics of one marker trajectory.

    A *gap* is a run of missing frames with a visible frame on both sides;
    missing frames at the start or end of the take are counted separately as
    ``leading`` and ``trailing`` because nothing can be interpolated there.
    A *segment* is a run of visible frames.

    Attributes
    ----------
    name : str
    gap_lengths : ndarray of int, shape (G,)
        Length of each interior gap in frames.
    segment_lengths : ndarray of int, shape (S,)
        Length of each visible run in frames.
    leading, trailing : int
        Missing frames before the first and after the last visible frame.
    """

    name: str
    gap_lengths: np.ndarray
    segment_lengths: np.ndarray
    leading: int
    trailing: int

    @property
    def n_gaps(self) -> int:
        """Number of interior gaps."""
        return int(len(self.gap_lengths))

    @property
    def max_gap(self) -> int:
        """Length of the longest interior gap, frames (0 when there is none)."""
        return int(self.gap_lengths.max()) if len(self.gap_lengths) else 0

    @property
    def mean_gap(self) -> float:
        """Mean length of the interior gaps, frames (0.0 when there is none)."""
        return float(self.gap_lengths.mean()) if len(self.gap_lengths) else 0.0

    @property
    def mean_segment(self) -> float:
        """Mean length of the visible runs, frames (0.0 when the marker is never seen)."""
        return float(self.segment_lengths.mean()) if len(self.segment_lengths) else 0.0


def marker_gaps(missing: np.ndarray, name: str = "") -> MarkerGaps:
    """Gap statistics of one trajectory from its (T,) boolean missing mask.

    Parameters
    ----------
    missing : array_like of bool, shape (T,)
        True on the frames where the marker is missing.
    name : str
        Marker name stored in the result.

    Returns
    -------
    MarkerGaps
        Lengths in frames; a marker never seen has all T frames ``leading``.
    """
    missing = np.asarray(missing, dtype=bool)
    seg_starts, seg_lengths = runs(~missing)
    if len(seg_starts) == 0:
        return MarkerGaps(name, np.zeros(0, int), np.zeros(0, int), len(missing), 0)
    first, last = seg_starts[0], seg_starts[-1] + seg_lengths[-1]
    gap_starts, gap_lengths = runs(missing[first:last])
    return MarkerGaps(name, gap_lengths.astype(int), seg_lengths.astype(int),
                      int(first), int(len(missing) - last))


@dataclass(frozen=True, eq=False)
class MarkerSequence:
    """Labeled 3D marker trajectories.

    Parameters
    ----------
    positions : ndarray of shape (T, M, 3)
        Marker positions in metres, NaN where a marker is missing.
    names : sequence of str, length M
        Marker labels, unique. Labels may carry a ``Subject:`` prefix.
    rate : float
        Frames per second.
    residuals : ndarray of shape (T, M), optional
        Per-marker residual of the capture system (metres), NaN where missing.
    warnings : tuple of str
        One-line warnings about the data (units guessed, implausible values),
        kept by every method that derives a new sequence and stored in files.

    Notes
    -----
    Instances are immutable: methods return new sequences and never change the
    caller's arrays. A frame is missing for a marker when any of its three
    coordinates is NaN; the constructor makes all three NaN in that case.
    """

    positions: np.ndarray
    names: tuple[str, ...]
    rate: float
    residuals: np.ndarray | None = field(default=None)
    warnings: tuple[str, ...] = field(default=())

    def __post_init__(self):
        positions = check_positions(self.positions).copy()
        names = tuple(str(n) for n in self.names)
        if len(names) != positions.shape[1]:
            raise HandcapError(f"{len(names)} marker names for {positions.shape[1]} markers")
        duplicates = sorted({n for n in names if names.count(n) > 1})
        if duplicates:
            raise HandcapError(f"marker names must be unique, repeated: {', '.join(duplicates)}")
        positions[np.isnan(positions).any(axis=2)] = np.nan
        if np.isinf(positions).any():
            raise HandcapError("positions contain infinite values; use NaN for missing markers")
        residuals = self.residuals
        if residuals is not None:
            residuals = np.asarray(residuals, dtype=np.float64).copy()
            if residuals.shape != positions.shape[:2]:
                raise HandcapError(f"residuals must have shape {positions.shape[:2]}, got {residuals.shape}")
            residuals[np.isnan(positions[..., 0])] = np.nan
        object.__setattr__(self, "positions", positions)
        object.__setattr__(self, "names", names)
        object.__setattr__(self, "rate", check_rate(self.rate))
        object.__setattr__(self, "residuals", residuals)
        object.__setattr__(self, "warnings", merge_warnings(self.warnings))

    def with_warnings(self, *messages) -> "MarkerSequence":
        """The same sequence with ``messages`` (one-line strings) added to its warnings."""
        return MarkerSequence(self.positions, self.names, self.rate, self.residuals,
                              merge_warnings(self.warnings, messages))

    # -- sizes -------------------------------------------------------------
    @property
    def n_frames(self) -> int:
        """Number of frames T."""
        return self.positions.shape[0]

    @property
    def n_markers(self) -> int:
        """Number of markers M."""
        return self.positions.shape[1]

    @property
    def duration(self) -> float:
        """Length of the take in seconds."""
        return self.n_frames / self.rate

    @property
    def times(self) -> np.ndarray:
        """Time of each frame in seconds from the first, shape (T,)."""
        return np.arange(self.n_frames) / self.rate

    @property
    def missing(self) -> np.ndarray:
        """Boolean (T, M), True where a marker is missing."""
        return np.isnan(self.positions[..., 0])

    def __len__(self) -> int:
        return self.n_frames

    def __repr__(self) -> str:
        return (f"MarkerSequence({self.n_frames} frames x {self.n_markers} markers "
                f"at {self.rate:g} Hz, {100 * self.missing.mean() if self.positions.size else 0:.1f}% missing)")

    def summary(self) -> str:
        """One line: frames, markers, rate and the share of samples missing."""
        return (f"{self.n_frames} frames, {self.n_markers} markers at {self.rate:g} Hz, "
                f"{100 * self.missing.mean() if self.positions.size else 0:.1f}% missing")

    # -- names -------------------------------------------------------------
    @property
    def short_names(self) -> tuple[str, ...]:
        """Names without a ``Subject:`` prefix."""
        return tuple(n.rsplit(":", 1)[-1] for n in self.names)

    def index(self, name: str) -> int:
        """Column of marker ``name``; an unprefixed name matches ``Subject:name``.

        Raises
        ------
        HandcapError
            If no marker, or more than one after stripping prefixes, matches.
        """
        if name in self.names:
            return self.names.index(name)
        matches = [i for i, n in enumerate(self.short_names) if n == name]
        if len(matches) == 1:
            return matches[0]
        if len(matches) > 1:
            raise HandcapError(f"marker name {name!r} is ambiguous: "
                               f"{', '.join(self.names[i] for i in matches)}; give the prefix")
        raise HandcapError(f"no marker named {name!r}; markers are: {', '.join(self.names)}")

    def select(self, names) -> "MarkerSequence":
        """Sequence with only the markers ``names``, in that order."""
        if isinstance(names, str):
            names = [names]
        idx = [self.index(n) for n in names]
        return MarkerSequence(self.positions[:, idx], [self.names[i] for i in idx], self.rate,
                              None if self.residuals is None else self.residuals[:, idx], self.warnings)

    def positions_of(self, names) -> np.ndarray:
        """Positions (T, N, 3) of the markers ``names``, in that order; NaN throughout for a name the sequence lacks
        (a marker never seen, left out of the file)."""
        index = {n: k for k, n in enumerate(self.names)}
        out = np.full((self.n_frames, len(names), 3), np.nan)
        present = [k for k, n in enumerate(names) if n in index]
        out[:, present] = self.positions[:, [index[names[k]] for k in present]]
        return out

    def renamed(self, names) -> "MarkerSequence":
        """Same trajectories under new names (e.g. ``short_names``)."""
        return MarkerSequence(self.positions, names, self.rate, self.residuals, self.warnings)

    # -- frames ------------------------------------------------------------
    def frames(self, start: int = 0, stop: int | None = None, step: int = 1) -> "MarkerSequence":
        """Frames ``start:stop:step``; the rate is divided by ``step``.

        Parameters
        ----------
        start : int
            First frame kept (frame index; Python slice semantics, negative counts from the end).
        stop : int, optional
            Frame index one past the last kept; None for the end of the take.
        step : int
            Keep every ``step``-th frame, 1 or more.

        Returns
        -------
        MarkerSequence
            Positions (T', M, 3) in metres, rate ``rate / step`` Hz, warnings kept.

        Raises
        ------
        HandcapError
            ``step`` below 1.
        """
        if step < 1:
            raise HandcapError(f"frame step must be a positive integer, got {step}")
        sl = slice(start, stop, step)
        return MarkerSequence(self.positions[sl], self.names, self.rate / step,
                              None if self.residuals is None else self.residuals[sl], self.warnings)

    def __getitem__(self, item) -> "MarkerSequence":
        if isinstance(item, slice):
            return self.frames(item.start or 0, item.stop, item.step or 1)
        if isinstance(item, str):
            return self.select([item])
        raise HandcapError("index a MarkerSequence with a frame slice or a marker name")

    def time_range(self, start: float, stop: float | None = None) -> "MarkerSequence":
        """Frames between ``start`` and ``stop`` seconds (half-open).

        Parameters
        ----------
        start : float
            Seconds from the first frame; the first frame at or after it is kept.
        stop : float, optional
            Seconds from the first frame; frames at or after it are dropped. None for the end.

        Returns
        -------
        MarkerSequence
            The frames whose time ``t`` satisfies ``start <= t < stop``, same rate.
        """
        first = int(np.ceil(start * self.rate - 1e-9))
        last = None if stop is None else int(np.ceil(stop * self.rate - 1e-9))
        return self.frames(max(first, 0), last)

    # -- gaps --------------------------------------------------------------
    def gaps(self) -> list[MarkerGaps]:
        """Gap statistics for every marker, in column order."""
        missing = self.missing
        return [marker_gaps(missing[:, m], name) for m, name in enumerate(self.names)]

    def gap_summary(self) -> dict:
        """Whole-take gap statistics: fraction missing, gap and segment lengths (frames)."""
        stats = self.gaps()
        gaps = np.concatenate([s.gap_lengths for s in stats]) if stats else np.zeros(0)
        segments = np.concatenate([s.segment_lengths for s in stats]) if stats else np.zeros(0)
        return {
            "frames": self.n_frames,
            "markers": self.n_markers,
            "missing_fraction": float(self.missing.mean()) if self.positions.size else 0.0,
            "gaps": int(len(gaps)),
            "mean_gap_frames": float(gaps.mean()) if len(gaps) else 0.0,
            "max_gap_frames": int(gaps.max()) if len(gaps) else 0,
            "mean_segment_frames": float(segments.mean()) if len(segments) else 0.0,
            "never_seen": [s.name for s in stats if len(s.segment_lengths) == 0],
        }


def expand_names(available, request) -> list[str]:
    """Marker names picked by names or shell-style patterns; ``Subject:`` prefixes are understood.

    Every verb that takes marker names (``track-object --markers``, ``label
    --object``, the layouts of ``fill`` and ``train-occlusion``) resolves them
    here, so ``index_tip`` finds ``Hand:index_tip`` everywhere.

    Parameters
    ----------
    available : sequence of str or MarkerSequence
        The names in a file, possibly prefixed (``Subject:name``).
    request : str or sequence of str
        Comma-separated names and patterns (``"boite:*"``, ``"index_*"``), or a
        sequence of them. A name matches itself, else the one available name
        whose part after the last ``:`` equals it. A pattern (``*``, ``?``,
        ``[...]``, :func:`fnmatch.fnmatchcase`) matches whole names or the part
        after the prefix.

    Returns
    -------
    list of str
        The available names picked, spelled as in ``available``, in the order
        asked, each once.

    Raises
    ------
    HandcapError
        An empty request, a name that is not available or matches several
        prefixed names, or a pattern that matches nothing.
    """
    from fnmatch import fnmatchcase
    names = [str(n) for n in (available.names if isinstance(available, MarkerSequence) else available)]
    short = [n.rsplit(":", 1)[-1] for n in names]
    items = request.split(",") if isinstance(request, str) else [str(r) for r in request]
    items = [item.strip() for item in items if item.strip()]
    if not items:
        raise HandcapError(f"no marker names given in {request!r}; give names or patterns such as 'boite:*'")
    picked: list[str] = []
    for item in items:
        if any(c in item for c in "*?["):
            found = [n for n, s in zip(names, short) if fnmatchcase(n, item) or fnmatchcase(s, item)]
            if not found:
                raise HandcapError(f"no marker matches {item!r}; markers are: {', '.join(names)}")
        elif item in names:
            found = [item]
        else:
            found = [n for n, s in zip(names, short) if s == item]
            if len(found) > 1:
                raise HandcapError(f"marker name {item!r} is ambiguous: {', '.join(found)}; give the prefix")
            if not found:
                raise HandcapError(f"no marker named {item!r}; markers are: {', '.join(names)}")
        picked += [n for n in found if n not in picked]
    return picked
