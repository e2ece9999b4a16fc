"""Unlabeled 3D points per frame: ``PointCloudSequence``."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from handcap.core.errors import HandcapError
from handcap.core.checks import check_rate
from handcap.core.markers import MarkerSequence


@dataclass(frozen=True, eq=False)
class PointCloudSequence:
    """Unlabeled points, a different number in every frame.

    Parameters
    ----------
    frames : sequence of ndarray, each of shape (K_t, 3)
        Points of frame t in metres, in no particular order. No NaN inside.
    rate : float
        Frames per second.
    """

    frames: tuple[np.ndarray, ...]
    rate: float

    def __post_init__(self):
        checked = []
        for t, pts in enumerate(self.frames):
            pts = np.array(pts, dtype=np.float64).reshape(-1, 3) if np.size(pts) else np.zeros((0, 3))
            if not np.isfinite(pts).all():
                raise HandcapError(f"frame {t} holds non-finite points; drop missing points instead")
            checked.append(pts)
        object.__setattr__(self, "frames", tuple(checked))
        object.__setattr__(self, "rate", check_rate(self.rate))

    @classmethod
    def from_padded(cls, points, rate) -> "PointCloudSequence":
        """From a NaN-padded array of shape (T, K, 3); rows with any NaN are dropped.

        Parameters
        ----------
        points : array_like of shape (T, K, 3)
            Metres, NaN rows for padding or missing points.
        rate : float
            Frames per second.

        Returns
        -------
        PointCloudSequence
            T frames, each with the finite rows of its frame, in column order.

        Raises
        ------
        HandcapError
            ``points`` not of shape (T, K, 3), infinite values, or a bad rate.
        """
        points = np.asarray(points, dtype=np.float64)
        if points.ndim != 3 or points.shape[2] != 3:
            raise HandcapError(f"points must have shape (T, K, 3), got {points.shape}")
        return cls(tuple(p[~np.isnan(p).any(axis=1)] for p in points), rate)

    @classmethod
    def from_markers(cls, markers: MarkerSequence) -> "PointCloudSequence":
        """The visible markers of every frame, labels dropped (column order kept)."""
        return cls.from_padded(markers.positions, markers.rate)

    @property
    def n_frames(self) -> int:
        """Number of frames T."""
        return len(self.frames)

    @property
    def counts(self) -> np.ndarray:
        """Number of points in each frame, shape (T,)."""
        return np.array([len(p) for p in self.frames], dtype=int)

    def __len__(self) -> int:
        return self.n_frames

    def __repr__(self) -> str:
        counts = self.counts
        rng = f"{counts.min()}-{counts.max()}" if len(counts) else "0"
        return f"PointCloudSequence({self.n_frames} frames, {rng} points per frame at {self.rate:g} Hz)"

    def padded(self, width: int | None = None) -> np.ndarray:
        """Points as a NaN-padded array of shape (T, K, 3), K = ``width`` or the largest count."""
        width = int(self.counts.max(initial=0)) if width is None else width
        out = np.full((self.n_frames, width, 3), np.nan)
        for t, pts in enumerate(self.frames):
            if len(pts) > width:
                raise HandcapError(f"frame {t} has {len(pts)} points, more than width {width}")
            out[t, :len(pts)] = pts
        return out

    def frames_slice(self, start: int = 0, stop: int | None = None) -> "PointCloudSequence":
        """Frames ``start:stop`` (frame indices, Python slice semantics) as a new sequence at the same rate.

        Parameters
        ----------
        start : int
            First frame kept.
        stop : int, optional
            Frame index one past the last kept; None for the end.

        Returns
        -------
        PointCloudSequence
        """
        return PointCloudSequence(self.frames[start:stop], self.rate)
