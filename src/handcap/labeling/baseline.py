"""Nearest-neighbour tracker: the baseline the labeler is measured against.

It starts like the labeler (the hand frame from the rigid markers, then the
best assignment of the spatial model), and from then on gives each label the
point nearest to where it was last seen (one assignment problem on distances
per frame, gated at ``gate`` metres). A label unseen for more than
``max_coast`` frames is started again from the spatial model, among the points
no tracked label took.
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import linear_sum_assignment

from handcap.core.errors import HandcapError
from handcap.labeling.frame import HandFrameFinder


class NearestNeighbourLabeler:
    """``update(points) -> labels`` like :class:`handcap.labeling.OnlineLabeler`, strictly online."""

    def __init__(self, model, *, gate: float = 0.02, max_coast: int = 10, theta_min: float = -2.0):
        self.model = model
        self.names = model.names
        self.gate = float(gate)
        self.max_coast = int(max_coast)
        self.theta_min = float(theta_min)
        self.n_rigid = 0 if model.rigid is None else len(model.rigid.names)
        self.n_free = len(model.free_names)
        self.finder = None if model.rigid is None else HandFrameFinder(model.rigid)
        self.last = np.full((self.n_free, 3), np.nan)
        self.missed = np.full(self.n_free, 1 << 30)

    def update(self, points, transform=None) -> np.ndarray:
        """Label one frame, at once (no lag).

        Parameters
        ----------
        points : ndarray (K, 3)
            Unlabeled points of the frame, metres, any order (NaN rows are ignored).
        transform : (ndarray (3, 3), ndarray (3,)), optional
            The hand frame (``world = R @ local + t``, ``t`` in metres); required when the model
            has no rigid markers.

        Returns
        -------
        ndarray (K,) int
            Per point, in the order given: an index into ``names``, or -1 for a point no label took.

        Raises
        ------
        HandcapError
            No ``transform`` for a model without rigid markers.
        """
        points = np.asarray(points, dtype=np.float64).reshape(-1, 3) if np.size(points) else np.zeros((0, 3))
        valid = np.flatnonzero(~np.isnan(points).any(axis=1))
        pts = points[valid]
        labels = np.full(len(points), -1)
        if transform is not None:
            pose, rigid_points = transform, np.full(self.n_rigid, -1)
        elif self.finder is not None:
            found = self.finder.find(pts)
            pose = None if found is None else (found.rotation, found.translation)
            rigid_points = np.full(self.n_rigid, -1) if found is None else found.points
        else:
            raise HandcapError("this labeling model has no rigid markers: pass transform=(R, t) every frame")
        for r, p in enumerate(rigid_points):
            if p >= 0:
                labels[valid[p]] = r
        free = np.ones(len(pts), bool)
        free[rigid_points[rigid_points >= 0]] = False
        taken = np.full(self.n_free, -1)
        tracked = np.flatnonzero(self.missed <= self.max_coast)
        cand = np.flatnonzero(free)
        if len(tracked) and len(cand):
            d = np.linalg.norm(self.last[tracked][:, None] - pts[cand][None], axis=-1)
            rows, cols = linear_sum_assignment(np.where(d < self.gate, d, 1e6))
            ok = d[rows, cols] < self.gate
            taken[tracked[rows[ok]]] = cand[cols[ok]]
            free[cand[cols[ok]]] = False
        lost = np.flatnonzero((self.missed > self.max_coast) & (taken < 0))
        cand = np.flatnonzero(free)
        if pose is not None and len(lost) and len(cand):
            ll = self.model.spatial.log_likelihood((pts[cand] - pose[1]) @ pose[0])[lost]
            rows, cols = linear_sum_assignment(np.where(ll >= self.theta_min, -ll, 1e6))
            ok = ll[rows, cols] >= self.theta_min
            taken[lost[rows[ok]]] = cand[cols[ok]]
        seen = taken >= 0
        self.last[seen] = pts[taken[seen]]
        self.missed = np.where(seen, 0, self.missed + 1)
        labels[valid[taken[seen]]] = self.n_rigid + np.flatnonzero(seen)
        return labels

    def flush(self) -> list:
        """End of a take: nothing is pending (every frame is decided in :meth:`update`), so an empty list."""
        return []
