"""Chains of unexplained points that move like markers: where a track may start (the paper's tracks that
"start from points that are temporally consistent though spatially unlikely").

The online labeler's spatial model filters out every pairing less likely
than clutter (``theta_min``), so a marker in a pose the training take barely
covered, or on a hand the model does not quite fit yet, is never labelled:
no track can start on it, and continuity (which carries a label onto such
points) never begins. A :class:`PointChains` follows, with the labeler's own
Kalman model, the points a frame's best hypothesis leaves without a
spatially accepted label. A point that continues a chain of ``length``
updates, each inside the gate of the chain's prediction, is kinematically
consistent: the labeler may start a label's track on it (a birth), see
:class:`handcap.labeling.OnlineLabeler` (``birth``); :func:`birth_pairings`
gives the label each such point would start.

A born point takes the label without a track (never seen, warming up, or lost
for over ``max_coast`` frames) whose spatial model explains it best, scored
spatially at ``theta_min`` (as likely as the least likely pairing the model
accepts: the chain is evidence that it is no clutter). Only while the labeler
adapts to the take (``adapt``), once the take's rigid shape is checked and the
model aligned: before, an unlikely point may as well mean a wrong hand frame;
without adaptation (and in the offline second pass, whose model is refit to
labels that include the born tracks) a birth started before any track was
confirmed began a 400-frame swap of two fingers on a synthetic take. Off by
default online: on another subject's synthetic take, where many points fit no
label, born tracks took wrong labels (wrong 0.14 -> 1.79 %); off in the offline
first pass too (``label_take``'s ``FIRST_PASS_BIRTH``).
"""

from __future__ import annotations

import numpy as np

from handcap.labeling.kalman import KalmanBatch, KalmanSettings


class PointChains:
    """Kalman-tracked chains of points the labeler left unexplained.

    Parameters
    ----------
    settings : KalmanSettings
        The labeler's filter model (noise learned from the training take).
    gate : float
        A point continues a chain when it is within this many standard
        deviations (per axis, isotropic) of the chain's prediction.
    max_coast : int
        Frames a chain survives without a point.

    Attributes
    ----------
    length : ndarray (C,) int
        Points each chain has taken (its filter's updates).
    """

    def __init__(self, settings: KalmanSettings, *, gate: float, max_coast: int = 1):
        self.settings = settings
        self.gate = float(gate)
        self.max_coast = int(max_coast)
        self._filters = KalmanBatch(settings, 0)
        self._match = np.full(0, -1)
        self._predicted = None

    @property
    def length(self) -> np.ndarray:
        """Points each chain has taken (its filter's updates), ndarray (C,) int."""
        return self._filters.age

    def match(self, world) -> np.ndarray:
        """Which chain each point of a new frame continues.

        Parameters
        ----------
        world : ndarray (K, 3)
            The frame's candidate points, metres.

        Returns
        -------
        ndarray (K,) int
            Updates of the chain the point continues (0: none), counting the
            point itself. Kept for :meth:`advance`.
        """
        filters = self._filters
        n = len(filters.age)
        self._match = np.full(len(world), -1)
        self._predicted = None
        if not n or not len(world):
            return np.zeros(len(world), dtype=np.int64)
        state, cov = self._predicted = filters.predicted()
        var = filters.innovation_variance(cov)  # (C,)
        d2 = ((world[:, None] - state[None, :, 0]) ** 2).sum(axis=-1) / var[None]  # (K, C)
        d2 = np.where(d2 <= self.gate**2, d2, np.inf)
        # Greedy one-to-one by distance (few chains: a handful of unexplained points per frame).
        while np.isfinite(d2).any():
            k, c = np.unravel_index(np.argmin(d2), d2.shape)
            self._match[k] = c
            d2[k, :] = np.inf
            d2[:, c] = np.inf
        out = np.zeros(len(world), dtype=np.int64)
        got = self._match >= 0
        out[got] = filters.age[self._match[got]] + 1
        return out

    def advance(self, world, free) -> None:
        """Step the chains with the frame's unexplained points (after :meth:`match` on the same points).

        Parameters
        ----------
        world : ndarray (K, 3)
        free : ndarray (K,) bool
            Points the frame's best hypothesis gave no spatially accepted
            label: they continue their chains or start new ones; a chain
            whose point was explained ends, and one without a point coasts
            at most ``max_coast`` frames.
        """
        filters = self._filters
        n = len(filters.age)
        measured = np.full((n, 3), np.nan)
        taken = np.zeros(n, dtype=bool)
        if len(self._match) != len(world):
            raise RuntimeError("PointChains.advance needs match() on the same frame's points first")
        go = (self._match >= 0) & free
        measured[self._match[go]] = world[go]
        taken[self._match[(self._match >= 0) & ~free]] = True
        new = free & (self._match < 0)
        if n:
            filters.step(measured, self._predicted)
            keep = ~taken & (filters.missed <= self.max_coast)
            filters.copy_from(filters, np.flatnonzero(keep))
        if new.any():
            born = KalmanBatch(self.settings, int(new.sum()))
            born.restart(np.ones(len(born.age), dtype=bool), world[new])
            merged = KalmanBatch(self.settings, 0)
            merged.state = np.concatenate([filters.state, born.state])
            merged.cov = np.concatenate([filters.cov, born.cov])
            merged.age = np.concatenate([filters.age, born.age])
            merged.missed = np.concatenate([filters.missed, born.missed])
            self._filters = merged
        self._match = np.full(0, -1)
        self._predicted = None

    def clear(self) -> None:
        """Forget every chain."""
        self._filters = KalmanBatch(self.settings, 0)
        self._match = np.full(0, -1)
        self._predicted = None


def birth_pairings(ll, chained, trackable, theta_min: float) -> np.ndarray:
    """Pairings that would start a track: each point at the end of a long enough chain that no label accepts
    spatially, with the label without a track that explains it best.

    Parameters
    ----------
    ll : ndarray (F, K)
        Spatial log-likelihood (per m^3) of each free label at each candidate point.
    chained : ndarray (K,) bool
        Points at the end of a chain of at least the labeler's ``birth`` updates (:meth:`PointChains.match`).
    trackable : ndarray (F,) bool
        Labels with a track (of the best hypothesis' filters): the others may take a born point.
    theta_min : float
        Least log-likelihood (per m^3) of a spatially accepted pairing.

    Returns
    -------
    ndarray (F, K) bool
        The pairings (at most one label per point).
    """
    free = ~trackable
    born = np.zeros(ll.shape, dtype=bool)
    if not free.any():
        return born
    k = np.flatnonzero(chained & (ll.max(axis=0) < theta_min))  # points no label accepts
    if not len(k):
        return born
    which = np.flatnonzero(free)[np.argmax(ll[free][:, k], axis=0)]  # the best label without a track
    born[which, k] = True
    return born
