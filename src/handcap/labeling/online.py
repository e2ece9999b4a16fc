"""Online labeling of unlabeled finger markers (Alexanderson, Beskow et al.; see the module docs).

Per frame:

1. The hand frame from its rigid back markers (:mod:`handcap.labeling.frame`),
   or a transform the caller gives; the other points are moved into it.
2. The (labels x points) log-likelihoods of the spatial model (Eq. 1-2).
3. The N best assignments of labels to points (Murty), where a label may be
   occluded (score ``log(1/M)``) and a point may be a ghost; pairings below
   ``theta_min`` are not allowed (the paper's filter, made exact).
4. Kalman filters per label per hypothesis (constant acceleration) score
   every transition from the previous frame's hypotheses (Eq. 3); a label
   occluded in the new hypothesis scores as a residual at the gate (``gate``
   standard deviations), so a match must be better than that to be preferred
   to a gap; a label coasts at most ``max_coast`` frames and is started afresh
   after longer gaps, without a temporal score for its first ``warmup``
   updates.
5. Viterbi: every new hypothesis takes its best predecessor. Online, frame
   t is decided ``lag`` frames later (0: at once) by tracing back from the
   best hypothesis; offline, on the whole take.

This module owns the stream: the labeler's state from frame to frame (hand
frame, filters, trellis, open frames) and its decisions; the hypotheses of
steps 3-4 and their scores are built in :mod:`handcap.labeling.hypotheses`.

Beyond the paper: each frame also gets the assignment that is best for spatial and temporal evidence together
given the best previous hypothesis (a tracking hypothesis; from every previous hypothesis labels no better on the
real glove and synthetic takes), so a correct but spatially unlikely assignment (a finger in a pose the training
take barely covered) is not lost when it is outside the N spatially best; a track carries its label onto
spatially filtered points for at most ``max_unlikely`` frames (a swap kept by continuity alone ends there), and
labels whose tracks hold points the spatial model would give them otherwise, frame after frame, are released to
it (``release``, :mod:`handcap.labeling.release`: a swap of two plausible points, which the tracks' continuity
would keep for good). A point no label accepts spatially but that has moved as a marker for ``birth`` frames may
start the track of the best label without one (:mod:`handcap.labeling.birth`; the paper's tracks started from
temporally consistent, spatially unlikely points; off by default).
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass, field

import numpy as np

from handcap.core.errors import HandcapError
from handcap.labeling.adapt import StreamAdaptation
from handcap.labeling.birth import PointChains, birth_pairings
from handcap.labeling.frame import HandFrameFinder, find_objects
from handcap.labeling.hypotheses import emission_scores, spatial_hypotheses, tracking_hypothesis, transition_scores
from handcap.labeling.kalman import KalmanBatch
from handcap.labeling.model import LabelingModel
from handcap.labeling.release import Release, TrackEvidence
from handcap.labeling.spatial import median_fit
from handcap.labeling.viterbi import backtrack, viterbi_step


@dataclass
class _Frame:
    """What is kept of a frame until it is decided."""

    n_points: int
    rigid_points: np.ndarray  # (R,) point index per rigid label, -1
    hypotheses: np.ndarray  # (N, F) point index per free label, -1 occluded
    back: np.ndarray  # (N,) best predecessor in the frame before
    scores: np.ndarray = field(default_factory=lambda: np.zeros(0))
    valid: np.ndarray = field(default_factory=lambda: np.zeros(0, bool))  # (K,) rows that were points
    object_points: np.ndarray = field(default_factory=lambda: np.zeros(0, int))  # (O,) point per object label
    doubtful: bool = False  # the hand frame unconfirmed: its hand labels are withheld


class OnlineLabeler:
    """Streaming labeler: ``update(points) -> labels``.

    Parameters
    ----------
    model : LabelingModel
    hypotheses : int
        N, the assignment hypotheses per frame (the paper: 5).
    lag : int
        Frames of look-ahead before a frame is decided (0: strictly online).
    theta_min : float
        Least log-likelihood (per m^3) of a label-point pairing (the paper: -2).
    max_coast : int
        Frames a label's filter runs on prediction alone (the paper: 10).
    warmup : int
        Updates of a restarted filter before it scores transitions (the paper: 2).
    gate : float
        A label occluded in a hypothesis scores like a measurement this many
        standard deviations off its prediction.
    jump_cost : float
        A measurement further off than the gate scores ``jump_cost`` below a
        gap (log-likelihood), however far: real markers do jump, and a
        spatially convincing point should still be kept.
    tracking : bool
        Add the tracking hypothesis (see the module docs).
    max_hold : int
        Frames the hand frame is carried over when its markers are lost.
    objects : sequence of RigidSet
        Rigid objects whose markers are in the stream (a held cylinder, a
        box): found by their marker distances like the hand's back markers,
        labelled with their own names (after the hand's), and kept out of the
        fingers' candidates. Without them, an object marker near a hidden
        fingertip is a plausible finger marker that moves smoothly with the
        hand.
    adapt : bool
        Re-align the spatial model to the take as it streams in (:mod:`handcap.labeling.adapt`): after
        ``adapt_every`` frames, a label-free registration of the points seen so far (provisional ones every 10
        frames before it: ``adapt.PROVISIONAL_EVERY``); then every ``adapt_every`` frames, a registration of the
        labelled points of the recent frames (weighted by ``forget`` per frame of age; the mixture means stay as
        trained online). When the hand frame is lost in most
        recent frames, the rigid markers' shape is re-learned from them.
        Strictly online (``lag`` 0), until this has settled, a frame whose
        points fit the model far worse than it typically fits
        (:meth:`StreamAdaptation.doubtful`) gets no hand labels and counts as
        lost: none rather than wrong.
    adapt_every : int
        Frames between re-estimations.
    release, release_drift : float
        Evidence (natural log) at which labels whose tracks hold other points
        than the spatially best assignment gives them are released to the
        spatial model (their filters restart in every hypothesis), and the
        evidence taken off per frame (:mod:`handcap.labeling.release`; a swap
        of two plausible points otherwise lasts as long as the tracks).
    max_unlikely : int
        Frames a track may carry a label on points the spatial model filters
        out (the tracking hypothesis); after that the spatial model decides
        again (two tracks swapped in a crossing would otherwise stay swapped).
    forget : float
        Weight kept per frame of age by a labelled point (0.999: a half-life
        of about 700 frames; a short memory sees one pose only).
    defer : bool
        Leave what only the next frame needs (the filters' step, the
        re-alignment) for :meth:`idle` (a live stream calls it once the frame
        is sent), else for the next :meth:`update`; same labels either way.
    birth : int
        A point the spatial model filters out for every label may still
        start a track (the tracking hypothesis) when it has moved as a marker
        moves for this many frames (:mod:`handcap.labeling.birth`, which says
        when and why); only while adapting, once the model is aligned. 0
        (default): never (offline first pass: ``label_take``'s ``FIRST_PASS_BIRTH``).

    Attributes
    ----------
    names : tuple of str
        Label of each index in the returned arrays.
    lost_frames : list of int
        Frames where the hand frame could not be found (every free label
        reported as a gap there).
    released : list of Release
        Labels released to the spatial model (``release``): when, since when, which.
    """

    def __init__(self, model: LabelingModel, *, hypotheses: int = 5, lag: int = 0, theta_min: float = -2.0,
                 max_coast: int = 10, warmup: int = 2, gate: float = 6.0, jump_cost: float = 6.0,
                 tracking: bool = True, max_hold: int = 10, objects=(), adapt: bool = True,
                 adapt_every: int = 25, forget: float = 0.999, max_unlikely: int = 50, birth: int = 0,
                 defer: bool = False, release: float = 1000.0, release_drift: float = 2.0):
        if not (isinstance(hypotheses, (int, np.integer)) and hypotheses >= 1):
            raise HandcapError(f"hypotheses must be a whole number >= 1, got {hypotheses}")
        if not (isinstance(lag, (int, np.integer)) and lag >= 0):
            raise HandcapError(f"lag must be a whole number of frames >= 0, got {lag}")
        self.model = model
        self.objects = tuple(objects)
        self.names = model.names + tuple(n for o in self.objects for n in o.names)
        self._object_finders = [HandFrameFinder(o, max_hold=0) for o in self.objects]
        self._n_object_markers = sum(len(o.names) for o in self.objects)
        self.n_hyp = int(hypotheses)
        self.lag = int(lag)
        self.theta_min = float(theta_min)
        self.max_coast = int(max_coast)
        self.warmup = int(warmup)
        self.gate = float(gate)
        self.jump_cost = float(jump_cost)
        self.tracking = bool(tracking)
        self.n_rigid = 0 if model.rigid is None else len(model.rigid.names)
        self.n_free = len(model.free_names)
        self.finder = None if model.rigid is None else HandFrameFinder(model.rigid, max_hold=max_hold)
        self.lost_frames, self.frame_index = [], 0  # frames whose hand frame was lost; frames taken so far
        self._filters = KalmanBatch(model.kalman, self.n_free)  # one hypothesis to start with
        self._scores = np.zeros(1)
        self._unlikely = np.zeros((1, self.n_free), dtype=np.int64)  # (P, F) frames on spatially filtered points
        self._pending: deque[_Frame] = deque()
        self._occluded_score = np.log(1.0 / self.n_free)
        self.tracked_predecessors = 100
        self._fit_level = None  # running mean of the per-point spatial fit
        self._typical_fit = None  # the model's median best log-likelihood of its points (SpatialModel.typical_fit)
        self.suspect_drop = 4.0  # a fit this far below it has the hand frame searched afresh
        if not (isinstance(adapt_every, (int, np.integer)) and adapt_every >= 1):
            raise HandcapError(f"adapt_every must be a whole number of frames >= 1, got {adapt_every}")
        if not 0.0 < forget <= 1.0:
            raise HandcapError(f"forget must be in (0, 1], got {forget}")
        self.max_unlikely = int(max_unlikely)
        self._evidence = TrackEvidence(model.free_names, release, release_drift)
        self.released: list[Release] = []
        self.widened: tuple = ()  # labels hardly given and so searched for wider (StreamAdaptation, strictly online)
        if not (isinstance(birth, (int, np.integer)) and birth >= 0):
            raise HandcapError(f"birth must be a whole number of frames >= 0, got {birth}")
        self.birth = int(birth)
        self._chains = PointChains(model.kalman, gate=self.gate) if self.birth and self.tracking else None
        self._born = None  # (F, K) pairings of the frame that would start a track on a chain
        self.spatial = model.spatial  # the spatial model in the take's hand frame (adapted when adapt)
        self.adapt = bool(adapt)
        self._adaptation = StreamAdaptation(self, int(adapt_every), float(forget)) if self.adapt else None
        self.defer = bool(defer)
        self._step_filters = None  # (back, obs) of the last frame while its filters wait for idle()
        if self._adaptation is not None:
            self._adaptation.deferred = self.defer

    # -- public ---------------------------------------------------------------------------
    def update(self, points, transform=None):
        """Label one frame.

        Parameters
        ----------
        points : ndarray (K, 3)
            Unlabeled points of the frame, metres, any order (NaN rows are ignored).
        transform : (ndarray (3, 3), ndarray (3,)), optional
            The hand frame (``world = R @ local + t``); required when the model
            has no rigid markers.

        Returns
        -------
        ndarray (K_d,) int or None
            Labels of the points of the frame decided now (frame ``t - lag``,
            in the order its points were given): an index into ``names``, or
            -1 for a point that is no marker. None while the first ``lag``
            frames are still open.
        """
        self.idle()  # what the frame before left (defer)
        points, valid = frame_points(points)
        return self._push(self._step(points[valid], transform), valid)

    def idle(self) -> None:
        """Do what the last frame left (``defer``): step its filters, then re-align the model if due."""
        if self._step_filters is not None:
            back, obs = self._step_filters
            self._step_filters = None
            self._advance_filters(back, obs)
        if self._adaptation is not None:
            self._adaptation.catch_up()

    def _push(self, frame: "_Frame", valid) -> np.ndarray | None:
        """Keep a stepped frame open; return the labels of the frame decided now, if any."""
        frame.n_points = len(valid)
        frame.valid = valid
        self._pending.append(frame)
        self.frame_index += 1
        if len(self._pending) > self.lag:
            return self._decide_oldest()
        return None

    def flush(self) -> list[np.ndarray]:
        """Decide every frame still open (end of a take); returns their labels, oldest first."""
        pending = self._pending
        if not pending:
            return []
        path = backtrack([pending[i].back for i in range(1, len(pending))], int(np.argmax(pending[-1].scores)))
        out = [self._labels(frame, h) for frame, h in zip(pending, path)]
        pending.clear()
        return out

    def restart_tracks(self) -> None:
        """Start the hypotheses and filters afresh from the next frame (the spatial model changed: tracks
        begun under the old one, a swap of two fingertips say, must not be carried on by their continuity)."""
        self._filters = KalmanBatch(self.model.kalman, self.n_free)
        self._scores = np.zeros(1)
        self._unlikely = np.zeros((1, self.n_free), dtype=np.int64)

    # -- one frame ------------------------------------------------------------------------
    def _step(self, points, transform) -> _Frame:
        # Each object's markers first (a rigid object with many markers is the surest find), then the
        # hand's frame among the points left (given, or from its back markers, ranked by the spatial
        # fit); the fingers are labelled among what remains.
        rest, object_points = find_objects(self._object_finders, points, self._n_object_markers)
        pose, rigid_points, rest = self._find_hand(points, rest, transform)
        return self._label(points, rest, pose, rigid_points, object_points)

    def _find_hand(self, points, rest, transform=None):
        """The hand frame among ``points[rest]``: (pose (R, t) or None, (R_rigid,) point per rigid label,
        the indices of rest without the rigid markers)."""
        self._points = points[rest]
        rigid_points = np.full(self.n_rigid, -1)
        pose = None
        if transform is not None:
            rot, trans = (np.asarray(a, dtype=np.float64) for a in transform)
            if rot.shape != (3, 3) or trans.shape != (3,):
                raise HandcapError("transform must be (rotation (3, 3), translation (3,))")
            pose = (rot, trans)
        elif self.finder is not None:
            found = self.finder.find(self._points, self._frame_fit)
            if self._adaptation is not None:
                found = self._adaptation.watch_hand(self._points, found)
            if found is not None:
                pose = (found.rotation, found.translation)
                got = found.points >= 0
                rigid_points[got] = rest[found.points[got]]
                rest = np.delete(rest, found.points[got])
        else:
            raise HandcapError("this labeling model has no rigid markers: pass transform=(R, t) every frame")
        return pose, rigid_points, rest

    def _label(self, points, rest, pose, rigid_points, object_points, ll=None) -> _Frame:
        """Hypotheses, transitions and filters of a frame whose candidate points are ``points[rest]``
        (``ll``: their spatial log-likelihoods (F, len(rest)) when the caller has them)."""
        n_free = self.n_free
        filters = self._filters
        n_prev = len(self._scores)
        state_pred, cov_pred = self._predicted = filters.predicted()
        pred = state_pred[:, 0].reshape(n_prev, n_free, 3)
        var = filters.innovation_variance(cov_pred).reshape(n_prev, n_free)
        trackable = ((filters.missed <= self.max_coast) & (filters.age >= self.warmup)).reshape(n_prev, n_free)
        self._log_norm_all = -1.5 * np.log(2 * np.pi * var)  # (P, F): Gaussian normaliser of each filter
        self._at_gate_all = self._log_norm_all - 0.5 * self.gate**2
        self._born = None
        doubtful = False
        if pose is None:
            self.lost_frames.append(self.frame_index)
            hyps = np.full((1, n_free), -1)
            world = np.zeros((0, 3))
            emission = np.zeros(1)
        else:
            world = points[rest]
            hyps, emission = self._spatial_hypotheses((world - pose[1]) @ pose[0], ll)
            self._watch_frame()
            # Until the adaptation settles, a frame that fits the model far worse than it typically fits is in a
            # hand frame not confirmed (a look-alike set, a model not yet aligned): none of its labels rather
            # than wrong ones, and it counts as lost.
            doubtful = self._adaptation is not None and self._adaptation.doubtful(self._last_ll)
            if doubtful:
                self.lost_frames.append(self.frame_index)
            if self.tracking and len(world):
                best = int(np.argmax(self._scores))
                if self._chains is not None:
                    chained = self._chains.match(world) >= self.birth
                    if chained.any() and self._adaptation is not None and self._adaptation.settled:
                        self._born = birth_pairings(self._last_ll, chained, trackable[best], self.theta_min)
                extra = tracking_hypothesis(
                    world, self._last_ll, pred[best], var[best], trackable[best],
                    trackable[best] & (self._unlikely[best] < self.max_unlikely), self._log_norm_all[best],
                    self._at_gate_all[best], theta_min=self.theta_min, occluded_score=self._occluded_score,
                    jump_cost=self.jump_cost, born=self._born)
                if not (hyps == extra).all(axis=1).any():
                    hyps = np.concatenate([hyps, extra])
                    emission = np.append(emission, emission_scores(extra, self._last_ll, self.theta_min,
                                                                   self._occluded_score, self._born))
        # Observed positions (N, F, 3) of every hypothesis. The filters track world positions: the hand
        # frame (spatial model) can be off when a back marker is missing, the points themselves are not.
        seen = hyps >= 0
        obs = np.full(hyps.shape + (3,), np.nan)
        obs[seen] = world[hyps[seen]]
        transition = transition_scores(obs, pred, var, trackable, self._log_norm_all, self._at_gate_all, self.gate,
                                       self.jump_cost)  # (N_prev, N)
        scores, back = viterbi_step(self._scores, transition, emission)
        scores -= scores.max()
        if pose is not None and len(world):  # before the filters step (now or deferred): a release restarts them
            found = self._evidence.weigh(hyps, emission, int(np.argmax(scores)), self.frame_index, world)
            if found is not None:
                self.released.append(found)
        if self.defer:
            self._step_filters = (back, obs)
        else:
            self._advance_filters(back, obs)
        if pose is not None and len(world):
            f = np.arange(n_free)
            unlikely = seen & (self._last_ll[f, np.maximum(hyps, 0)] < self.theta_min)
            self._unlikely = np.where(unlikely, self._unlikely[back] + 1, np.where(seen, 0, self._unlikely[back]))
        else:
            self._unlikely = self._unlikely[back]
        self._scores = scores
        if self._chains is not None:
            self._advance_chains(world, hyps[int(np.argmax(scores))] if pose is not None else None)
        if self._adaptation is not None:
            self._adaptation.record(world, pose, hyps[int(np.argmax(scores))])
        # Store point indices of the frame (rest maps hypothesis indices back to points).
        mapped = np.where(seen, rest[np.maximum(hyps, 0)] if len(rest) else -1, -1)
        return _Frame(len(points), rigid_points, mapped, back, scores, object_points=object_points,
                      doubtful=doubtful)

    def _frame_fit(self, rot, trans, used) -> float:
        """How well the other points fit the spatial model in a candidate hand frame."""
        others = np.setdiff1d(np.arange(len(self._points)), used[used >= 0])
        if not len(others):
            return 0.0
        ll = self.spatial.log_likelihood((self._points[others] - trans) @ rot)
        return float(np.maximum(ll.max(axis=1), self.theta_min).sum())

    def _watch_frame(self) -> None:
        """Flag the hand finder when the points fit far worse than they usually do in the hand frame: a wrong
        set of back markers can be tracked as well as the right one, so the next frame is searched afresh.

        Two yardsticks, each ``suspect_drop`` below: the take's running level (mean best log-likelihood per point),
        and the model's own (:meth:`SpatialModel.typical_fit`) against the better median best log-likelihood, the
        points' or the labels' (an unknown object's markers fit no label). The running level alone starts with the
        take: a look-alike set found in the first frame set it, and was tracked for 50 frames with no finger labelled.
        """
        if self.finder is None or not self._last_ll.size:
            return
        best = self._last_ll.max(axis=0)
        fit = float(np.maximum(best, self.theta_min).sum()) / len(best)
        if self._fit_level is None:
            self._fit_level = fit
        suspect = fit < self._fit_level - self.suspect_drop
        if not suspect and len(best) >= max(3, self.n_free // 2):
            if self._typical_fit is None:
                self._typical_fit = self.spatial.typical_fit()
            suspect = median_fit(self._last_ll) < self._typical_fit - self.suspect_drop
        self.finder.suspect = suspect
        if not suspect:
            self._fit_level += 0.05 * (fit - self._fit_level)

    def _spatial_hypotheses(self, local, ll=None):
        """The N best assignments (N, F) of candidate indices (-1: occluded) and their scores (N,) of the points
        ``local`` (K, 3) in the hand frame (:func:`spatial_hypotheses`); keeps their log-likelihoods (F, K)."""
        if ll is None:
            ll = self.spatial.log_likelihood(local) if len(local) else np.zeros((self.n_free, 0))
        self._last_ll = ll
        return spatial_hypotheses(ll, self.n_hyp, self.theta_min, self._occluded_score)

    def _advance_chains(self, world, best) -> None:
        """Step the point chains with the points the best hypothesis (F,) left without a spatially accepted
        label (a birth's point stays on its chain until its track can vouch for it)."""
        free = np.ones(len(world), dtype=bool)
        if best is not None and len(world):
            f = np.flatnonzero(best >= 0)
            free[best[f]] = self._last_ll[f, best[f]] < self.theta_min
        self._chains.advance(world, free)

    def _advance_filters(self, back, obs) -> None:
        """Filters of the new hypotheses: their predecessors' filters stepped with their observations."""
        n_free = obs.shape[1]
        index = (back[:, None] * n_free + np.arange(n_free)).ravel()
        self._filters = self._filters.successors(index, obs.reshape(-1, 3), self._predicted, self.max_coast)
        released = self._evidence.take_pending()
        if released.any():  # each takes over the track that holds its point, or starts afresh (no transition)
            self._filters.take_over(*self._evidence.hand_over(obs, released))

    # -- decisions ------------------------------------------------------------------------
    def _decide_oldest(self) -> np.ndarray:
        """Trace back from the best current hypothesis to the oldest open frame; emit its labels."""
        pending = self._pending
        path = backtrack([pending[i].back for i in range(1, len(pending))], int(np.argmax(pending[-1].scores)))
        oldest = pending.popleft()
        return self._labels(oldest, path[0])

    def _labels(self, frame: _Frame, h: int) -> np.ndarray:
        valid_index = np.flatnonzero(frame.valid)
        labels = np.full(frame.n_points, -1)
        for o, p in enumerate(frame.object_points):
            if p >= 0:
                labels[valid_index[p]] = len(self.model.names) + o
        if frame.doubtful:  # the hand's labels withheld
            return labels
        for r, p in enumerate(frame.rigid_points):
            if p >= 0:
                labels[valid_index[p]] = r
        for f, p in enumerate(frame.hypotheses[h]):
            if p >= 0:
                labels[valid_index[p]] = self.n_rigid + f
        return labels


def frame_points(points):
    """A frame's points as (K, 3) floats and which of them are not NaN."""
    points = np.asarray(points, dtype=np.float64)
    if points.size == 0:
        points = np.zeros((0, 3))
    if points.ndim != 2 or points.shape[1] != 3:
        raise HandcapError(f"points must have shape (K, 3), got {points.shape}")
    return points, ~np.isnan(points).any(axis=1)
