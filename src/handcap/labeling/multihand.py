"""Several hands (and rigid objects) in one stream of unlabeled points: :class:`MultiHandLabeler`."""

from __future__ import annotations

from collections import deque
from dataclasses import replace

import numpy as np

from handcap.core.errors import HandcapError
from handcap.labeling.frame import HandFrameFinder
from handcap.labeling.frame import find_objects
from handcap.labeling.online import OnlineLabeler, frame_points


class MultiHandLabeler:
    """Several hands in one stream, each found by its own rigid back markers: ``update(points) -> labels``.

    Every frame, the objects' markers are found first, then each hand's back
    markers among the points left (in the order of ``models``); every other
    point goes to the hand whose spatial model explains it best, and each hand
    labels its points with its own hypotheses, filters and Viterbi trellis
    (:class:`OnlineLabeler`).

    Parameters
    ----------
    models : sequence of LabelingModel
        One per hand (each with rigid markers); the same model may serve
        both hands of a pair of identical gloves.
    prefixes : sequence of str, optional
        Put before each hand's labels (needed when the models share names).
    objects : sequence of RigidSet
    options
        :class:`OnlineLabeler` settings, shared by the hands.

    Attributes
    ----------
    names : tuple of str
        Every hand's labels (prefixed), then the objects'.
    """

    def __init__(self, models, *, prefixes=None, objects=(), **options):
        models = list(models)
        if not models:
            raise HandcapError("give at least one hand's labeling model")
        if any(m.rigid is None for m in models):
            raise HandcapError("each hand needs rigid back markers to be told apart in one stream")
        prefixes = [""] * len(models) if prefixes is None else [str(p) for p in prefixes]
        if len(prefixes) != len(models):
            raise HandcapError(f"{len(prefixes)} prefixes for {len(models)} hands")
        self.hands = [OnlineLabeler(m, **options) for m in models]
        self.objects = tuple(objects)
        self._object_finders = [HandFrameFinder(o, max_hold=0) for o in self.objects]
        self._n_object_markers = sum(len(o.names) for o in self.objects)
        hand_names = [p + n for p, m in zip(prefixes, models) for n in m.names]
        self.names = tuple(hand_names) + tuple(n for o in self.objects for n in o.names)
        if len(set(self.names)) != len(self.names):
            raise HandcapError("the hands share label names: give prefixes (e.g. prefixes=('left_', 'right_'))")
        self._offsets = np.cumsum([0] + [len(m.names) for m in models])
        self._object_pending: deque = deque()
        self.lag = self.hands[0].lag
        self._prefixes = prefixes

    @property
    def lost_frames(self) -> list:
        """Frames where some hand's frame could not be found."""
        return sorted(set().union(*(h.lost_frames for h in self.hands)))

    @property
    def released(self) -> list:
        """Every hand's labels released to its spatial model (``Release``, the labels prefixed), by frame."""
        return sorted((replace(r, labels=tuple(p + n for n in r.labels)) for h, p in zip(self.hands, self._prefixes)
                       for r in h.released), key=lambda r: r.frame)

    def update(self, points, transform=None):
        """Label one frame: as :meth:`OnlineLabeler.update`, with indices into :attr:`names`.

        Parameters
        ----------
        points : ndarray (K, 3)
            Unlabeled points of the frame, metres, any order (NaN rows are ignored).
        transform : None
            Must be None: each hand is found by its own rigid markers.

        Returns
        -------
        ndarray (K_d,) int or None
            Labels of the frame decided now (``lag`` frames back), in the order its points were
            given: an index into :attr:`names`, or -1; None while the first frames are still open.

        Raises
        ------
        HandcapError
            A ``transform`` was given.
        """
        if transform is not None:
            raise HandcapError("several hands are found by their rigid markers; a transform cannot be given")
        points, valid = frame_points(points)
        pts = points[valid]
        rest, object_points = find_objects(self._object_finders, pts, self._n_object_markers)
        found = []
        for hand in self.hands:
            pose, rigid_points, rest = hand._find_hand(pts, rest)
            found.append((pose, rigid_points))
        # Each remaining point to the hand whose spatial model explains it best, in that hand's frame.
        lls = []
        for hand, (pose, _) in zip(self.hands, found):
            if pose is None or not len(rest):
                lls.append(np.full((hand.n_free, len(rest)), -np.inf))
            else:
                lls.append(hand.spatial.log_likelihood((pts[rest] - pose[1]) @ pose[0]))
        owner = np.argmax(np.stack([ll.max(axis=0) if len(rest) else np.zeros(0) for ll in lls]), axis=0)
        decided = []
        for h, (hand, (pose, rigid_points)) in enumerate(zip(self.hands, found)):
            mine = owner == h
            frame = hand._label(pts, rest[mine], pose, rigid_points, np.zeros(0, int),
                                None if pose is None else lls[h][:, mine])
            decided.append(hand._push(frame, valid))
        self._object_pending.append((object_points, valid))
        if decided[0] is None:
            return None
        return self._combine(decided, self._object_pending.popleft())

    def flush(self) -> list[np.ndarray]:
        """Decide every frame still open (end of a take); returns their labels, oldest first."""
        per_hand = [hand.flush() for hand in self.hands]
        out = [self._combine(list(labels), self._object_pending.popleft()) for labels in zip(*per_hand)]
        self._object_pending.clear()
        return out

    def _combine(self, decided, objects) -> np.ndarray:
        object_points, valid = objects
        labels = np.full(len(valid), -1)
        for lab, offset in zip(decided, self._offsets):
            hit = lab >= 0
            labels[hit] = lab[hit] + offset
        valid_index = np.flatnonzero(valid)
        got = object_points >= 0
        labels[valid_index[object_points[got]]] = self._offsets[-1] + np.flatnonzero(got)
        return labels
