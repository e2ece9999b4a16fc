"""Labels released to the spatial model when their tracks keep disagreeing with it (``OnlineLabeler(release=...)``).

Once two labels' tracks hold each other's points, and both points are plausible
for either label, the tracks' continuity keeps the swap for good: a label moved
to a new point scores as a jump, its fresh track scores nothing for its first
updates, and the old tracks earn their tight filters' likelihood every frame.
The spatial model's preference, a few units (natural log) per frame, never wins
a single frame's comparison (another subject's synthetic take: a middle-finger
DIP and a ring-finger tip swapped for 850 of 1,000 frames).

:class:`TrackEvidence` adds that preference up per label, as a one-sided
cumulative sum (Page's CUSUM): each frame where the best hypothesis gives a
label another point than the spatially best assignment (both a point), the two
assignments' spatial difference is added, a drift is taken off every frame, and
the sum never drops below 0 (an ambiguity the spatial model barely prefers never
adds up). At the threshold the label is released together with the labels the
two assignments place otherwise in that frame on at least half as much evidence
(the rest of the swap: released one at a time, the other's track would take the
point back). In every hypothesis, each released label then takes over the
track of the released label that holds the point the spatial model gives it
(:meth:`TrackEvidence.hand_over`): a swap is exchanged, and continuity keeps it
right. A released label whose point no released track holds starts afresh, its
next updates scoring no transition, so that the spatial model decides its
point. (Restarted instead, both labels of a swap were left to the spatial model
frame by frame, whose preference is a few units, noisy: on seed 39 of
``benchmarks/labeling.py`` section 9 the tracks took the swap back after each
release.) Each release is a :class:`Release`;
:func:`release_warning` says them in one line (the labels were probably swapped
before it).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from handcap.core.errors import HandcapError


@dataclass(frozen=True)
class Release:
    """Labels released to the spatial model at ``frame``, their evidence adding up since frame ``since``."""

    frame: int
    since: int
    labels: tuple


def release_warning(releases, rate: float) -> str | None:
    """One line naming the releases (at most five), None for none: the labels may be swapped before each.

    Parameters
    ----------
    releases : sequence of Release
    rate : float
        Frames per second.
    """
    if not releases:
        return None
    told = "; ".join(f"{' and '.join(r.labels)} at frame {r.frame} (since frame {r.since}: {r.since / rate:.2f}-"
                     f"{r.frame / rate:.2f} s)" for r in releases[:5])
    more = f"; and {len(releases) - 5} more" if len(releases) > 5 else ""
    return (f"labels released to the spatial model {len(releases)} time(s), their tracks having held points it gives "
            f"other labels: {told}{more}; those labels are probably swapped in the frames named: check them, or "
            "train on a take of this subject")


class TrackEvidence:
    """Evidence (natural log) against each label's track, and the labels due for release.

    Parameters
    ----------
    names : sequence of str
        The free labels (F).
    release : float
        Evidence at which a label is released (``inf``: never).
    drift : float
        Evidence taken off per frame.
    """

    def __init__(self, names, release: float, drift: float):
        if not (release > 0 and drift >= 0):
            raise HandcapError(f"release must be > 0 and release_drift >= 0, got {release} and {drift}")
        self.names = np.array([str(n) for n in names])
        self.release, self.drift = float(release), float(drift)
        self.evidence = np.zeros(len(self.names))
        self.start = np.full(len(self.names), -1)  # frame each label's evidence began to add up, -1 at 0
        self.pending = np.zeros(len(self.names), dtype=bool)  # released, filters not yet restarted
        self.target = np.full((len(self.names), 3), np.nan)  # each pending label's point as the spatial model puts it

    def weigh(self, hyps, emission, best: int, frame: int, world=None) -> Release | None:
        """Add one frame's evidence; the labels released by it.

        Parameters
        ----------
        hyps : ndarray (N, F) int
            The frame's hypotheses: each label's candidate point, -1 for none.
        emission : ndarray (N,)
            Their spatial scores (natural log).
        best : int
            The hypothesis the labeler rates best (spatial and temporal evidence).
        frame : int
            The frame's index.
        world : ndarray (K, 3), optional
            The frame's candidate points (metres): where a released label's point is, for :meth:`hand_over`.

        Returns
        -------
        Release or None
            The labels released in this frame (also kept in ``pending``), None when none is.
        """
        top = int(np.argmax(emission))
        mine, theirs = hyps[best], hyps[top]
        other = (mine != theirs) & (mine >= 0) & (theirs >= 0)
        gain = float(emission[top] - emission[best])
        self.evidence = np.maximum(self.evidence + np.where(other, gain, 0.0) - self.drift, 0.0)
        self.start = np.where(self.evidence > 0, np.where(self.start < 0, frame, self.start), -1)
        due = self.evidence >= self.release
        if not due.any():
            return None
        due |= other & (self.evidence >= 0.5 * self.release)
        found = Release(int(frame), int(self.start[due].min()), tuple(str(n) for n in self.names[due]))
        self.evidence[due] = 0.0
        self.start[due] = -1
        self.pending |= due
        if world is not None:
            self.target[due] = np.where((theirs[due] >= 0)[:, None], world[np.maximum(theirs[due], 0)], np.nan)
        return found

    def take_pending(self) -> np.ndarray:
        """The labels (F,) bool released since the last call, whose filters restart now; cleared."""
        out = self.pending.copy()
        self.pending[:] = False
        return out

    def hand_over(self, obs, released) -> tuple[np.ndarray, np.ndarray]:
        """Which filter each label keeps once ``released`` labels are released: a released label takes over the
        track of the released label that holds its point (in each hypothesis), so that a swap is exchanged
        rather than decided afresh by the spatial model in the noisy frames after it; one whose point no
        released track holds starts afresh.

        Parameters
        ----------
        obs : ndarray (N, F, 3)
            Each new hypothesis's point per label (metres, NaN for none), which its filters were stepped with.
        released : ndarray (F,) bool
            The labels released (:meth:`take_pending`).

        Returns
        -------
        index : ndarray (N * F,) int
            The filter (of the N x F, hypothesis-major) each takes.
        fresh : ndarray (N, F) bool
            Filters to start afresh.
        """
        n, f = obs.shape[:2]
        index = np.arange(n * f).reshape(n, f)
        holds = (obs[:, None] == self.target[None, :, None]).all(axis=-1) & released[None, None, :]  # (N, x, y)
        holds &= released[None, :, None]
        found = holds.any(axis=2)
        index = np.where(found, index[:, :1] + holds.argmax(axis=2), index)
        self.target[released] = np.nan
        return index.ravel(), released[None, :] & ~found
