"""Two cameras' views of one named marker at one moment agree when each lies on the other's epipolar line.

:class:`EpipolarViews` holds every camera's views of named markers (2D detections) undistorted, and measures
that agreement between pairs of cameras, also with one camera's frames shifted against the other's (whole frames,
or fractions with its views interpolated between frames). :mod:`handcap.multiview.sync` finds cameras' time
offsets with it.
"""

from __future__ import annotations

import numpy as np

from handcap.core.cameras import CameraRig
from handcap.multiview.detections import Detections
from handcap.multiview.offsets import between, curving, least_on_grid

#: Matched views a pair of cameras needs at an offset to be judged there.
MIN_MATCHES = 30
#: Epipolar distances count at most this much in the whole-frame search (pixels), so wrong ids weigh little.
CAP_PX = 20.0
#: Partners each camera is paired with (those it shares the most markers with).
PARTNERS = 4
#: Views of the first camera of a pair that the fractional search takes at most (evenly spread over the take).
FINE_SAMPLES = 10000


class EpipolarViews:
    """Each camera's views sorted by (marker, frame), with their undistorted normalised coordinates, and how well
    two cameras' views of one marker agree: their distance to each other's epipolar lines.

    Parameters
    ----------
    detections : Detections
    rig : CameraRig
        The detections' calibrated cameras.

    Attributes
    ----------
    keys : list of ndarray (N_c,)
        Per camera, ``marker * stride + frame`` of its views, sorted (a marker seen twice in a frame: once).
    frames : list of ndarray (N_c,)
    points : list of ndarray (N_c, 2)
        Undistorted normalised image coordinates.
    stride : int
    """

    def __init__(self, detections: Detections, rig: CameraRig):
        d = detections
        order = d.camera_order(rig)
        self.stride = d.n_frames + 1
        self.keys, self.points, self.frames = [], [], []
        self.focal, self.rotation, self.translation = [], [], []
        for c in range(len(d.camera_names)):
            rows = np.flatnonzero(d.camera == c)
            key = d.marker[rows] * self.stride + d.frame[rows]
            key, first = np.unique(key, return_index=True)  # a marker seen twice in a frame: one view
            rows = rows[first]
            camera = rig[int(order[c])]
            self.keys.append(key)
            self.frames.append(d.frame[rows])
            self.points.append(camera.undistort_pixels(d.xy[rows], normalised=True))
            self.focal.append(float(camera.matrix[0, 0] + camera.matrix[1, 1]) / 2)
            self.rotation.append(camera.rotation_matrix)
            self.translation.append(camera.translation)
        self.n_frames = d.n_frames
        self.curves = [None] * len(self.keys)

    def curving(self, c: int) -> bool:
        """Whether camera ``c``'s tracks curve between its frames by more than their noise moves them
        (:func:`~handcap.multiview.offsets.curving`): its views are then interpolated along a spline.

        Parameters
        ----------
        c : int
            Camera.
        """
        if self.curves[c] is None:
            self.curves[c] = curving(self.points[c], self.keys[c])
        return self.curves[c]

    def essential(self, a: int, b: int) -> np.ndarray | None:
        """Essential matrix (3, 3) with x_b^T E x_a = 0 (normalised coordinates); None for cameras at one place.

        Parameters
        ----------
        a, b : int
            Cameras, in the detections' order.
        """
        rotation = self.rotation[b] @ self.rotation[a].T
        t = self.translation[b] - rotation @ self.translation[a]
        if np.linalg.norm(t) < 1e-3:
            return None
        cross = np.array([[0, -t[2], t[1]], [t[2], 0, -t[0]], [-t[1], t[0], 0]])
        return cross @ rotation

    def distance(self, a: int, b: int, xa: np.ndarray, xb: np.ndarray, e: np.ndarray) -> np.ndarray:
        """Symmetric distance (N,) of matched normalised points to each other's epipolar lines, pixels.

        Parameters
        ----------
        a, b : int
            Cameras.
        xa, xb : ndarray (N, 2)
            Their normalised points, matched row by row.
        e : ndarray (3, 3)
            :meth:`essential` of (a, b).
        """
        ha = np.column_stack([xa, np.ones(len(xa))])
        hb = np.column_stack([xb, np.ones(len(xb))])
        line_b, line_a = ha @ e.T, hb @ e
        algebraic = np.abs(np.einsum("ij,ij->i", hb, line_b))
        with np.errstate(divide="ignore", invalid="ignore"):
            in_b = algebraic / np.hypot(line_b[:, 0], line_b[:, 1]) * self.focal[b]
            in_a = algebraic / np.hypot(line_a[:, 0], line_a[:, 1]) * self.focal[a]
        return (in_a + in_b) / 2

    def matched(self, a: int, b: int, rows: np.ndarray, shift: int) -> tuple[np.ndarray, np.ndarray]:
        """Of a's ``rows``, those b saw ``shift`` frames later: (a's rows, b's rows).

        Parameters
        ----------
        a, b : int
            Cameras.
        rows : ndarray (R,) int
            Sorted indices into a's views.
        shift : int or ndarray (R,) int
            Frames, one for all rows or one per row.
        """
        keys = self.keys[b]
        if not len(keys):
            return rows[:0], rows[:0]
        wanted = self.keys[a][rows] + shift
        at = np.minimum(np.searchsorted(keys, wanted), len(keys) - 1)
        hit = (keys[at] == wanted) & (self.frames[a][rows] + shift >= 0) & (self.frames[a][rows] + shift
                                                                             < self.n_frames)
        return rows[hit], at[hit]

    def at_offset(self, a: int, b: int, rows: np.ndarray, shift) -> np.ndarray:
        """b's normalised points (R, 2) ``shift`` frames after a's ``rows``, interpolated between b's frames for a
        fraction (along a spline where b's tracks curve: :meth:`curving`); NaN where b lacks a frame.

        Parameters
        ----------
        a, b : int
            Cameras.
        rows : ndarray (R,) int
            Sorted indices into a's views.
        shift : float or ndarray (R,)
            Frames, one for all rows or one per row.
        """
        shift = np.broadcast_to(np.asarray(shift, dtype=np.float64), rows.shape)
        whole = np.floor(shift).astype(np.int64)
        part = shift - whole
        moving = part > 1e-9
        spline = bool(moving.any()) and self.curving(b)
        near = {}
        for step in (-1, 0, 1, 2) if spline else (0, 1) if moving.any() else (0,):
            near[step] = np.full((len(rows), 2), np.nan)
            first_a, first_b = self.matched(a, b, rows, whole + step)
            near[step][np.searchsorted(rows, first_a)] = self.points[b][first_b]
        out = near[0]
        if moving.any():
            outer = (near[-1][moving], near[2][moving]) if spline else (near[0][moving], near[1][moving])
            cubic = np.isfinite(outer[0]).all(axis=1) & np.isfinite(outer[1]).all(axis=1) & spline
            out[moving] = between(outer[0], near[0][moving], near[1][moving], outer[1], part[moving], cubic)
        return out

    def median_distance(self, pairs, offsets: np.ndarray, drift=None) -> float:
        """Median epipolar distance (px) over the pairs' views, b interpolated at the offsets (NaN: no view).

        Parameters
        ----------
        pairs : sequence of (a, b, ...)
        offsets : ndarray (C,)
            Frames, as :class:`handcap.multiview.sync.Sync` counts them; a camera with NaN is skipped.
        drift : ndarray (C,) or None
            Each clock's drift, as :class:`handcap.multiview.sync.Sync` counts it.
        """
        drift = np.zeros(len(offsets)) if drift is None else np.asarray(drift, dtype=np.float64)
        distances = []
        for a, b, *_ in pairs:
            e = self.essential(a, b)
            if e is None or np.isnan(offsets[a]) or np.isnan(offsets[b]):
                continue
            rows = np.arange(0, len(self.keys[a]), max(1, len(self.keys[a]) // FINE_SAMPLES))
            f = self.frames[a][rows]
            shift = (f * (1 + drift[a]) + offsets[a] - offsets[b]) / (1 + drift[b]) - f
            xb = self.at_offset(a, b, rows, shift)
            ok = np.isfinite(xb).all(axis=1)
            distances.append(self.distance(a, b, self.points[a][rows[ok]], xb[ok], e))
        return float(np.median(np.concatenate(distances))) if distances and sum(map(len, distances)) else np.nan

    def pairs(self) -> list:
        """Pairs (a, b), a < b, each camera with the partners it shares the most marker views with."""
        n = len(self.keys)
        markers = [np.bincount(k // self.stride) if len(k) else np.zeros(0, np.int64) for k in self.keys]
        shared = np.zeros((n, n))
        for a in range(n):
            for b in range(a + 1, n):
                m = min(len(markers[a]), len(markers[b]))
                shared[a, b] = shared[b, a] = np.minimum(markers[a][:m], markers[b][:m]).sum()
        pairs = set()
        for a in range(n):
            for b in np.argsort(-shared[a], kind="stable")[:PARTNERS]:
                if b != a and shared[a, b] >= MIN_MATCHES:
                    pairs.add((min(a, int(b)), max(a, int(b))))
        return sorted(pairs)

    def mean_by_shift(self, a: int, b: int, rows: np.ndarray, shifts: np.ndarray, e) -> np.ndarray:
        """Mean epipolar distance (S,) of a's ``rows`` against b's views each of ``shifts`` later, pixels, each
        capped at :data:`CAP_PX`; inf where fewer than :data:`MIN_MATCHES` match.

        Parameters
        ----------
        a, b : int
            Cameras.
        rows : ndarray (R,) int
            Indices into a's views.
        shifts : ndarray (S,) int
            Frames.
        e : ndarray (3, 3)
            :meth:`essential` of (a, b).
        """
        keys = self.keys[b]
        cost = np.full(len(shifts), np.inf)
        if not len(keys):
            return cost
        wanted = self.keys[a][rows][None, :] + shifts[:, None]
        frame = self.frames[a][rows][None, :] + shifts[:, None]
        at = np.minimum(np.searchsorted(keys, wanted), len(keys) - 1)
        hit = (keys[at] == wanted) & (frame >= 0) & (frame < self.n_frames)
        which, column = np.nonzero(hit)
        if not len(which):
            return cost
        distance = self.distance(a, b, self.points[a][rows[column]], self.points[b][at[which, column]], e)
        counts = np.bincount(which, minlength=len(shifts))
        capped = np.minimum(np.nan_to_num(distance, nan=CAP_PX), CAP_PX)
        total = np.bincount(which, weights=capped, minlength=len(shifts))
        full = counts >= MIN_MATCHES
        cost[full] = total[full] / counts[full]
        return cost

    def fine_shift(self, a: int, b: int, shift: int, e: np.ndarray) -> float:
        """``shift`` to a twentieth of a frame (within one frame of it): where the median epipolar distance is
        least, b's views interpolated between its frames.

        Parameters
        ----------
        a, b : int
            Cameras.
        shift : int
            The best whole shift.
        e : ndarray (3, 3)
            :meth:`essential` of (a, b).
        """
        rows = np.arange(len(self.keys[a]))
        keep = np.ones(len(rows), bool)
        for s in (shift - 1, shift, shift + 1):
            ra, _ = self.matched(a, b, rows, s)
            hit = np.zeros(len(rows), bool)
            hit[ra] = True
            keep &= hit
        rows = rows[keep][::max(1, int(keep.sum()) // FINE_SAMPLES)]
        if len(rows) < MIN_MATCHES:
            return float(shift)
        grid = shift + np.linspace(-1, 1, 41)
        cost = np.array([np.median(self.distance(a, b, self.points[a][rows], self.at_offset(a, b, rows, s), e))
                         for s in grid])
        return least_on_grid(grid, cost)
