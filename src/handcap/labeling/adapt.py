"""Re-aligning a labeling model to the take it labels as the take streams in (issue 14): :class:`StreamAdaptation`.

A spatial model learned on one take is wrong for a take of another day when
the back-of-hand markers sit differently relative to the fingers (a glove put
on again: 13 degrees / 13 mm), when the rigid markers' distances changed (a
marker stuck back on a few millimetres away) or when the hand is another
subject's. Three corrections, each estimated from the take itself:

1. :func:`rigid_from_take` (:mod:`handcap.labeling.relearn`): the rigid set's
   shape as the take shows it, re-learned from the triangle shape that recurs
   in most frames.
2. :func:`register_to_model` (:mod:`handcap.labeling.realign`): the rigid
   transform that takes the take's hand-frame points onto the spatial model,
   by EM on the Gaussian mixtures (rigid CPD; label-free with annealing, or
   with the labels given).
3. :func:`adapt_means` (:mod:`handcap.labeling.realign`): the mixture means
   moved toward the take's labelled points (MAP with a relevance factor).

Strictly online, a label hardly given in the frames gathered (another subject's knuckle marker a few millimetres
from the training subject's) is also searched :data:`~handcap.labeling.plausible.MISSING_SPREAD` wider, on trial,
as the offline second pass searches it (:meth:`StreamAdaptation._widen`); where it then lies the other way round than
the model's means say with a neighbour (:func:`~handcap.labeling.plausible.reversed_pairs`), the two labels held
each other's markers, and their tracks are exchanged.

:meth:`SpatialModel.moved` then expresses the model in the take's hand frame.
This module owns their use by the online labeler, frame by frame
(:class:`StreamAdaptation`); the offline two passes use them in
:mod:`handcap.labeling.take`. The functions are re-exported here.
"""

from __future__ import annotations

from collections import deque

import numpy as np

from handcap.labeling.frame import HandFrameFinder
from handcap.labeling.realign import (MAX_SHIFT, MAX_TURN_DEG, OUTLIER_SHARE, OUTLIER_VOLUME, adapt_means,
                                      register_to_model)
from handcap.labeling.plausible import MISSING_SPREAD, missing_labels, reversed_pairs
from handcap.labeling.release import Release
from handcap.labeling.relearn import RELEARN_WIDTH, largest_change, rigid_from_take
from handcap.labeling.spatial import median_fit

#: Frames with labelled points the window must hold before a label hardly given in them is searched for wider, and
#: frames after that a wider search is judged on.
WIDEN_AFTER = 200
#: A wider search is kept where it labels this much more of the points (as offline, ``take.ONLINE_RIGID_MARGIN``).
WIDEN_MARGIN = 0.01
#: Frames between the provisional alignments made until the first one the schedule (``every``) makes: each from
#: every point gathered so far, the one before as its start. The live stream re-aligns once a second; waiting that
#: long for its first alignment, it labelled another subject's first second hardly at all (section 9 of
#: ``benchmarks/labeling.py`` labelled as the stream labels: 88.3 -> 91.7 % and 86.3 -> 89.3 % of the points
#: right with them, 5,333 -> 4,845 wrong).
PROVISIONAL_EVERY = 10

__all__ = ["MAX_SHIFT", "MAX_TURN_DEG", "OUTLIER_SHARE", "OUTLIER_VOLUME", "StreamAdaptation", "adapt_means",
           "largest_change", "register_to_model", "rigid_from_take"]


class StreamAdaptation:
    """The online labeler's adaptation to the take (see :class:`handcap.labeling.OnlineLabeler`, ``adapt``).

    Keeps the recent frames' points in the take's hand frame and the labels
    the labeler gave them; every ``every`` frames re-estimates the transform
    to the trained model's frame (rigidly: the means stay as trained), and sets the
    labeler's ``spatial`` to the result (before the first of those, provisionally
    every :data:`PROVISIONAL_EVERY` frames). Also watches the hand frame: when it
    is lost in most recent frames, the rigid set is re-learned from them.
    """

    window = 1000  # frames of labelled points kept
    most_points = 800  # points per re-estimation (spread over the window), so that one stays ~1 ms

    def __init__(self, labeler, every: int, forget: float):
        self.labeler = labeler
        self.every = every
        self.forget = forget
        self.base = labeler.model.spatial
        self.rotation, self.translation = np.eye(3), np.zeros(3)
        n_free = labeler.n_free
        self.local = np.full((self.window, n_free, 3), np.nan)
        self.stamp = np.full(self.window, -1)
        self.count = 0
        self.aligned = False
        self.provisional = False  # aligned provisionally (PROVISIONAL_EVERY), not yet by the schedule
        self.unlabelled: deque = deque(maxlen=4 * every)  # take-frame points before the first alignment
        self.raw: deque = deque(maxlen=100)  # every frame's points, for re-learning the rigid set
        self.lost: deque = deque(maxlen=20)
        self.last_relearn = -(10**9)
        self.relearned = 0
        self.checked = False
        self.deferred = False  # the labeler's defer: a due re-estimation waits for catch_up()
        self.due = False
        self.typical = self.base.typical_fit() if labeler.finder is not None else None
        self.wide = np.zeros(n_free, bool)  # labels searched for wider: hardly given in the window
        self.blocked = np.zeros(n_free, bool)  # ... whose wider search labelled no more of the points: not again
        self.trial = None  # (labels, labelled share before) of the labels widened last, on trial
        self.judged = -1  # the frame count at which the last trial began or was judged
        self.points = np.zeros(self.window, dtype=np.int64)  # each slot's frame: candidate points, labels given
        self.given = np.zeros(self.window, dtype=np.int64)
        self.trained_rigid = None if labeler.finder is None else labeler.finder.rigid  # re-learned near it
        weights = self.base.weights[..., None]
        self.expected = (weights * self.base.means).sum(axis=1) / weights.sum(axis=1)  # (F, 3) each label's mean

    @property
    def settled(self) -> bool:
        """Whether the take's rigid shape has been checked (with rigid markers) and the model aligned to it:
        until then a point the model filters out may as well mean a wrong hand frame."""
        return self.aligned and (self.checked or self.labeler.finder is None)

    def watch_hand(self, points, found):
        """After the hand-frame finder: keep the frame, and re-learn the rigid set when it is mostly lost.

        Parameters
        ----------
        points : ndarray (K, 3)
            The frame's unlabeled points, metres.
        found : HandPose or None
            What the hand-frame finder made of them.

        Returns
        -------
        HandPose or None
            ``found``, or the pose found again with the re-learned rigid set.
        """
        self.raw.append(points)
        self.lost.append(found is None or not found.found)
        lab = self.labeler
        if sum(self.lost) >= 10 and self.count - self.last_relearn >= 20 and len(self.raw) >= 10:
            self.last_relearn = self.count
            if self.relearn_rigid(list(self.raw)[-50:]):
                found = lab.finder.find(points, lab._frame_fit)
                self.lost.clear()
        return found

    def doubtful(self, ll) -> bool:
        """Whether a frame's hand frame is in doubt, before the adaptation has settled: its points fit the
        model far worse (median best log-likelihood more than the labeler's ``suspect_drop`` below) than the
        model's points typically do (:meth:`SpatialModel.typical_fit`), and its labels find no better points
        (their median best log-likelihood: an unknown object's markers fit no label, yet the hand's labels find
        theirs; counted over the points alone, a synthetic glove grasp lost its first 100 frames): a model not
        yet aligned to the take, or a set of points that looks like the rigid one (its markers moved, another
        subject). Once the model
        is aligned, such a frame counts as lost, so that the rigid set is re-learned when most recent frames
        are (before, a take whose glove sits otherwise fits poorly in the right frame too). Strictly online
        only (``lag`` 0): with a look-ahead the frame is decided later, and offline a second pass labels
        every frame again with the model refit to the take.

        Parameters
        ----------
        ll : ndarray (F, K)
            Log-likelihood of every free label for each of the frame's candidate points in the hand frame.

        Returns
        -------
        bool
        """
        lab = self.labeler
        if self.typical is None or lab.lag or self.settled or ll.shape[1] < max(3, lab.n_free // 2):
            return False
        if median_fit(ll) >= self.typical - lab.suspect_drop:
            return False
        if self.lost and self.aligned:
            self.lost[-1] = True
        return True

    def relearn_rigid(self, frames) -> bool:
        """Re-learn the rigid set from ``frames`` (:func:`rigid_from_take`); True when it changed."""
        lab = self.labeler
        rigid, trained = lab.finder.rigid, self.trained_rigid
        new = rigid_from_take(trained, frames, spatial=self.base, width=max(RELEARN_WIDTH, 3 * trained.tolerance),
                              min_share=0.5, current=rigid)
        if new is None or largest_change(new, rigid) <= 0.5 * rigid.tolerance:
            return False
        lab.finder = HandFrameFinder(new, max_hold=lab.finder.max_hold)
        self.relearned += 1
        self._restart()
        return True

    def _widen(self, valid) -> None:
        """Strictly online, a label hardly given in the window (``valid`` (W, F): its labelled points) is searched
        :data:`MISSING_SPREAD` wider, on trial: kept where the frames after label :data:`WIDEN_MARGIN` more of
        their points than the window before, as offline keeps its wider pass; else undone for good (the label
        took a neighbour's point, and the neighbour would be next). A label whose points then lie the other way
        round than the model's means say with another label's (:func:`reversed_pairs`) took that label's marker,
        which held its own (so it was hardly given): the two are exchanged (:meth:`_reversed`)."""
        live = (self.stamp >= 0) & (self.stamp > self.judged)  # frames since the last trial was judged
        if self.trial is not None:
            labels, before = self.trial
            self._reversed(live, labels)
            if live.sum() >= WIDEN_AFTER:
                if self.given[live].sum() / max(self.points[live].sum(), 1) < before + WIDEN_MARGIN:
                    self.wide &= ~labels
                    self.blocked |= labels
                self.trial, self.judged = None, self.count  # (a trial undone leaves its neighbours starved a while)
        elif live.sum() >= WIDEN_AFTER:
            labelled = valid & live[:, None]  # each label's labelled points in the frames since
            starved = missing_labels(labelled.sum(axis=0) / live.sum()) & ~self.wide & ~self.blocked
            if starved.any():
                self.trial = (starved, self.given[live].sum() / max(self.points[live].sum(), 1))
                self.wide |= starved
                self.judged = self.count
        self.labeler.widened = tuple(np.array(self.base.names)[self.wide])

    def _reversed(self, live, labels) -> None:
        """Labels on trial (``labels`` (F,) bool, updated) that lie the other way round than the model's means say
        with another label (:func:`reversed_pairs`) in the ``live`` frames (W,) bool: with one label not on trial,
        the two are exchanged (:meth:`_exchange`); else the label on trial is undone for good."""
        local = self.local[live] @ self.rotation.T + self.translation  # in the model's frame
        pairs = reversed_pairs(self.expected, local) & labels[:, None]
        for a in np.flatnonzero(pairs.any(axis=1)):
            b = np.flatnonzero(pairs[a])
            if len(b) == 1 and not labels[b[0]]:
                self._exchange(a, int(b[0]))
            else:
                self.wide[a], self.blocked[a] = False, True
            labels[a] = False

    def _exchange(self, a: int, b: int) -> None:
        """Labels ``a`` (widened on trial) and ``b`` lie the other way round (:func:`reversed_pairs`): each holds the
        other's marker (``b`` held ``a``'s, so ``a`` was hardly given, and ``a`` searched wider took ``b``'s).
        Their tracks are exchanged in every hypothesis, and both are searched wider (``b``'s marker was not where
        the model puts it either). Kept as a :class:`Release` of the two."""
        lab = self.labeler
        index = np.arange(lab._filters.age.size).reshape(-1, lab.n_free)
        index[:, [a, b]] = index[:, [b, a]]
        lab._filters.take_over(index.ravel(), np.zeros(index.size, dtype=bool))
        lab._unlikely[:, [a, b]] = lab._unlikely[:, [b, a]]
        self.local[:, [a, b]] = self.local[:, [b, a]]
        self.wide[[a, b]] = True
        since = lab.frame_index - (self.count - self.judged)  # the trial's first frame
        lab.released.append(Release(lab.frame_index, since, (str(self.base.names[a]), str(self.base.names[b]))))

    def _restart(self) -> None:
        """The hand frame changed meaning: forget what was gathered in the old one."""
        self.wide[:] = self.blocked[:] = False
        self.trial, self.judged, self.labeler.widened = None, -1, ()
        self.local[:] = np.nan
        self.stamp[:] = -1
        self.unlabelled.clear()
        self.aligned = self.provisional = False
        self.rotation, self.translation = np.eye(3), np.zeros(3)
        self.labeler.spatial = self.base

    def record(self, world, pose, best) -> None:
        """Keep a frame's labelled points in the hand frame; re-estimate the alignment every ``every`` frames.

        Parameters
        ----------
        world : ndarray (K, 3)
            The frame's candidate points in the world, metres.
        pose : (ndarray (3, 3), ndarray (3,)) or None
            The hand frame's rotation and translation (metres), None where it was not found.
        best : ndarray (F,) int
            The best hypothesis's point (index into ``world``) per free label, -1 for none.
        """
        self.count += 1
        if pose is not None and len(world):
            local = (world - pose[1]) @ pose[0]
            if not self.aligned:
                self.unlabelled.append(local)
            slot = self.count % self.window
            row = np.full((len(best), 3), np.nan)
            seen = best >= 0
            if seen.any():
                ll = self.labeler._last_ll
                ok = seen.copy()
                ok[seen] = ll[np.flatnonzero(seen), best[seen]] >= self.labeler.theta_min
                row[ok] = local[best[ok]]
            self.local[slot] = row
            self.stamp[slot] = self.count
            self.points[slot], self.given[slot] = len(world), int(seen.sum())
        if self.count % self.every == 0 or (not self.aligned and self.count % PROVISIONAL_EVERY == 0):
            self.due = True
            if not self.deferred:
                self.catch_up()

    def catch_up(self) -> None:
        """Re-estimate now if a re-estimation is due (see :meth:`record`)."""
        if self.due:
            self.due = False
            self.update()

    def update(self) -> None:
        """Re-estimate the transform from the frames gathered."""
        if not self.checked and len(self.raw) == self.raw.maxlen and self.labeler.finder is not None:
            # Once, when a second or so of frames shows which shapes recur: is the rigid set the shape it
            # was in training?
            self.checked = True
            if self.relearn_rigid(list(self.raw)):
                return
        if not self.aligned:
            if sum(len(p) for p in self.unlabelled) < 100:
                return
            pts = np.concatenate(list(self.unlabelled))
            if len(pts) > self.most_points:
                pts = pts[np.linspace(0, len(pts) - 1, self.most_points).astype(int)]
            if self.count % self.every:  # provisional (PROVISIONAL_EVERY): the points gathered are kept
                # After the first, each goes on from the one before (10 iterations, not annealed: a third of the
                # cost, 14-47 ms a time on the live stream's second of frames, which fell behind for that second).
                more = {"start": (self.rotation, self.translation), "anneal": 0.0, "iterations": 10}
                self.rotation, self.translation = register_to_model(self.base, pts,
                                                                    **(more if self.provisional else {}))
                self.labeler.spatial = self.base.moved(self.rotation, self.translation)
                if not self.provisional:
                    self.labeler.restart_tracks()
                self.provisional = True
                return
            self.rotation, self.translation = register_to_model(self.base, pts)
            self.aligned, self.provisional = True, False
            self.unlabelled.clear()
            self.local[:] = np.nan  # labels given before the alignment are not trusted
            self.stamp[:] = -1
            self.labeler.spatial = self.base.moved(self.rotation, self.translation)
            self.labeler.restart_tracks()  # tracks begun under the unaligned model may be swapped
            return
        valid = (self.stamp >= 0)[:, None] & ~np.isnan(self.local[..., 0])
        slots, labels = np.nonzero(valid)
        if len(slots) < 50:
            return
        if len(slots) > self.most_points:  # spread over the window: a second of frames is one pose only
            pick = np.linspace(0, len(slots) - 1, self.most_points).astype(int)
            slots, labels = slots[pick], labels[pick]
        local = self.local[slots, labels]
        weights = self.forget ** (self.count - self.stamp[slots])
        self.rotation, self.translation = register_to_model(self.base, local, labels, weights=weights, anneal=0.0,
                                                            iterations=2, start=(self.rotation, self.translation))
        if not self.labeler.lag:  # (offline, a second pass searches wider: take.py)
            self._widen(valid)
        moved = self.base.moved(self.rotation, self.translation)
        self.labeler.spatial = moved.widened(MISSING_SPREAD, self.wide) if self.wide.any() else moved
