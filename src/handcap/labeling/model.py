"""What a labeler learns from a labeled range-of-motion take, and the hand frame of labeled rigid markers."""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from handcap.core.errors import HandcapError, warn
from handcap.core.files import load_npz, save_npz
from handcap.core.markers import MarkerSequence
from handcap.labeling.kalman import JUMPING_FACTOR, KalmanSettings
from handcap.labeling.rigid_set import RigidSet
from handcap.labeling.spatial import SpatialModel
from handcap.objects.rigid import canonical_from_markers, kabsch


@dataclass(frozen=True)
class LabelingModel:
    """What a labeler learns from a labeled range-of-motion take.

    Attributes
    ----------
    names : tuple of str
        Every label: the rigid markers, then the others (the order of output).
    rigid : RigidSet or None
        The back-of-hand markers; None when the caller gives the hand frame.
    spatial : SpatialModel
        Mixtures of the other markers in the hand frame.
    kalman : KalmanSettings
    spans : ndarray (M, M, 2) or None
        Between every two labels of ``spatial`` in training: the median and the
        standard deviation of their distance (metres), pooled over the takes;
        None in models saved before they were kept.
    warnings : tuple of str
        What looked implausible in training, kept with the model: labels whose tracks jump (left out of the
        Kalman tuning, :meth:`KalmanSettings.fit`) and a tuning on the edge of its search
        (:meth:`KalmanSettings.edge_warning`).
    """

    names: tuple
    rigid: RigidSet | None
    spatial: SpatialModel
    kalman: KalmanSettings
    spans: np.ndarray | None = field(default=None, compare=False)
    warnings: tuple = field(default=(), compare=False)

    def at_rate(self, rate: float) -> "LabelingModel":
        """The model for a take of ``rate`` frames per second: its filters step ``1 / rate`` seconds.

        The filters' jerk density and measurement noise are the hand's and the system's, not the frame rate's,
        so a model trained at one rate labels takes of another; stepping the training's interval instead (a 120 Hz
        model on a 30 Hz take) predicts each marker a quarter of the way (synthetic joints-19, 2 ghosts/s: 90.6 %
        correct and 2.2 % wrong online, against 96.5 % and 0.11 %).

        Parameters
        ----------
        rate : float
            Frames per second of the take; NaN or None keeps the training's.
        """
        if rate is None or not np.isfinite(rate) or np.isclose(1.0 / rate, self.kalman.dt, rtol=1e-9):
            return self
        if rate <= 0:
            raise HandcapError(f"a take's frame rate must be positive, got {rate}")
        return replace(self, kalman=replace(self.kalman, dt=1.0 / float(rate)))

    @property
    def free_names(self) -> tuple:
        """The labels that are not rigid markers, in output order (those of the spatial model)."""
        return self.spatial.names

    @classmethod
    def train(cls, markers, names=None, rigid=None, *, transforms=None, components: int = 3,
              seed: int = 0) -> "LabelingModel":
        """Train on one labeled take or several.

        Parameters
        ----------
        markers : MarkerSequence or sequence of MarkerSequence
            Labeled training takes (ranges of motion), metres, at one rate.
            Several takes (other days, other subjects) are pooled: each take's
            hand frame comes from its own rigid-marker shape turned onto the
            first take's, so a triad put on again does not blur the mixtures,
            and the rigid tolerance is learned from how much the distances
            vary within each take.
        names : sequence of str, optional
            The labels to learn (default: every marker of the first take).
        rigid : sequence of str, optional
            Which of them are the rigid back-of-hand markers (3 or more).
        transforms : (ndarray (T, 3, 3), ndarray (T, 3)), optional
            Hand frame per training frame (``world = R @ local + t``), when
            there are no rigid markers (one take only).
        components : int
            Mixture components per label.
        seed : int
        """
        takes = [markers] if isinstance(markers, MarkerSequence) else list(markers)
        if not takes:
            raise HandcapError("give at least one labeled training take")
        if any(abs(t.rate - takes[0].rate) > 1e-9 for t in takes):
            raise HandcapError(f"the training takes have different frame rates: "
                               f"{', '.join(f'{t.rate:g}' for t in takes)} Hz; resample them to one rate")
        if transforms is not None and len(takes) > 1:
            raise HandcapError("transforms=... describe one take; give one take with them")
        names = list(takes[0].names if names is None else names)
        rigid = list(rigid or [])
        for k, take in enumerate(takes):
            which = "the training take" if len(takes) == 1 else f"training take {k + 1}"
            missing = [n for n in names if n not in take.names and n not in take.short_names]
            if missing:
                raise HandcapError(f"labels not in {which}: {', '.join(missing)}")
        unknown = [n for n in rigid if n not in names]
        if unknown:
            raise HandcapError(f"rigid markers not among the labels: {', '.join(unknown)}")
        free = [n for n in names if n not in rigid]
        if not free:
            raise HandcapError("every label is rigid: nothing left to label")
        ordered = rigid + free
        per_take = [np.stack([t.positions[:, t.index(n)] for n in ordered], axis=1) for t in takes]
        everything = np.concatenate(per_take)
        for n, s in zip(ordered, ~np.isnan(everything[..., 0]).T):
            if not s.any():
                raise HandcapError(f"marker {n!r} never appears in the training take")
        n_rigid = len(rigid)
        locals_, known = [], 0
        if rigid:
            rigid_set = RigidSet.from_takes(rigid, [p[:, :n_rigid] for p in per_take])
            for p in per_take:
                rot, trans, ok = rigid_transforms(own_shape(rigid_set.canonical, p[:, :n_rigid]), p[:, :n_rigid])
                local = np.full((len(p), len(free), 3), np.nan)
                local[ok] = np.einsum("tji,tmj->tmi", rot[ok], p[ok, n_rigid:] - trans[ok, None])
                locals_.append(local)
                known += int(ok.sum())
        elif transforms is not None:
            rot, trans = (np.asarray(a, dtype=np.float64) for a in transforms)
            n_frames = takes[0].n_frames
            if rot.shape != (n_frames, 3, 3) or trans.shape != (n_frames, 3):
                raise HandcapError(f"transforms must be ((T, 3, 3), (T, 3)) with T = {n_frames}")
            ok = np.isfinite(rot).all(axis=(1, 2)) & np.isfinite(trans).all(axis=1)
            rigid_set = None
            local = np.full((n_frames, len(free), 3), np.nan)
            local[ok] = np.einsum("tji,tmj->tmi", rot[ok], per_take[0][ok] - trans[ok, None])
            locals_.append(local)
            known = int(ok.sum())
        else:
            raise HandcapError("give the rigid back-of-hand markers (rigid=...) or the hand frame per frame "
                               "(transforms=...)")
        if known < 10:
            raise HandcapError(f"the hand frame is known in only {known} training frames")
        spatial = SpatialModel.fit(free, np.concatenate(locals_), components=components, seed=seed)
        # The filters see the takes one after the other, a gap longer than any coasting between them.
        gap = np.full((12, len(free), 3), np.nan)
        joined = np.concatenate([x for p in per_take for x in (p[:, n_rigid:], gap)][:-1])
        kalman, jumping = KalmanSettings.fit(joined, takes[0].rate)
        lines = [kalman.edge_warning()]
        if jumping.any():
            lines.append(f"{', '.join(np.array(free)[jumping])} jump between frames in the training take (their "
                         f"tracks fit no filter with under {JUMPING_FACTOR:g} times the other labels' noise): labels "
                         f"swapped back and forth? The filters were tuned without them; check the training take")
        return cls(tuple(ordered), rigid_set, spatial, kalman, label_spans(np.concatenate(per_take)[:, n_rigid:]),
                   tuple(warn(line) for line in lines if line))

    def save(self, path) -> None:
        """Write the model as a ``.npz`` (kind ``labeling_model``): names, mixtures, Kalman settings, rigid set.

        Only ``dt``, ``jerk`` and ``measurement`` of the Kalman settings are stored; the initial
        velocity and acceleration variances are their defaults on :meth:`load`.

        Parameters
        ----------
        path : str or Path
        """
        data = {"kind": np.array("labeling_model"), "names": np.array(self.names), **self.spatial.to_arrays(),
                "kalman": np.array([self.kalman.dt, self.kalman.jerk, self.kalman.measurement])}
        if self.rigid is not None:
            data.update(self.rigid.to_arrays())
        if self.spans is not None:
            data["spans"] = self.spans
        if self.warnings:
            data["warnings"] = np.array(self.warnings, dtype=str)
        save_npz(path, data)

    @classmethod
    def load(cls, path) -> "LabelingModel":
        """Read a model written by :meth:`save`.

        Parameters
        ----------
        path : str or Path

        Returns
        -------
        LabelingModel
            Lengths in metres, Kalman ``dt`` in seconds.

        Raises
        ------
        HandcapError
            Unreadable file or a missing entry.
        """
        data = load_npz(path, required=("names", "gmm_weights", "gmm_means", "gmm_precision_chol", "kalman"),
                        what="labeling model")
        dt, jerk, measurement = (float(v) for v in data["kalman"])
        rigid = RigidSet.from_arrays(data) if "rigid_names" in data else None
        spans = np.asarray(data["spans"], dtype=np.float64) if "spans" in data else None
        warnings = tuple(str(w) for w in np.atleast_1d(data["warnings"])) if "warnings" in data else ()
        return cls(tuple(str(n) for n in data["names"]), rigid, SpatialModel.from_arrays(data),
                   KalmanSettings(dt, jerk, measurement), spans, warnings)


def label_spans(positions) -> np.ndarray:
    """Median and standard deviation of the distance between every two markers over labeled frames.

    Parameters
    ----------
    positions : ndarray (T, M, 3)
        Metres, NaN where missing.

    Returns
    -------
    ndarray (M, M, 2)
        Metres; NaN for a pair never seen together.
    """
    positions = np.asarray(positions, dtype=np.float64)
    m = positions.shape[1]
    out = np.full((m, m, 2), np.nan)
    for i in range(m):  # one label at a time: (T, M) distances, not (T, M, M)
        dist = np.linalg.norm(positions - positions[:, i:i + 1], axis=-1)
        seen = np.isfinite(dist).sum(axis=0) > 1
        if seen.any():
            out[i, seen, 0] = np.nanmedian(dist[:, seen], axis=0)
            out[i, seen, 1] = np.nanstd(dist[:, seen], axis=0)
    return out


def own_shape(canonical, positions) -> np.ndarray:
    """The take's own shape of the rigid markers, turned onto ``canonical``.

    A set put on again (another day, another subject) keeps its own distances; the hand frame it gives
    (:func:`rigid_transforms`) moves as little as possible from the model's.

    Parameters
    ----------
    canonical : ndarray (R, 3)
        The model's rigid markers in the hand frame, metres.
    positions : ndarray (T, R, 3)
        The take's rigid markers, metres, NaN where missing.

    Returns
    -------
    ndarray (R, 3)
        Metres; ``canonical`` itself when fewer than 3 frames show 3 or more of the markers.
    """
    if (np.isfinite(positions[..., 0]).sum(axis=1) >= 3).sum() < 3:
        return canonical
    shape = canonical_from_markers(positions)
    r0, t0 = kabsch(shape, canonical)  # this take's shape onto the reference
    return shape @ r0.T + t0


def rigid_transforms(canonical, positions):
    """Kabsch per frame from labeled rigid markers (T, R, 3); frames with < 3 markers are not ok.

    Parameters
    ----------
    canonical : ndarray (R, 3)
        The rigid markers in the hand frame, metres.
    positions : ndarray (T, R, 3)
        The same markers in the world, metres, NaN where missing (missing ones get zero weight).

    Returns
    -------
    rotation : ndarray (T, 3, 3)
        ``world = rotation @ local + translation``; identity where not ok.
    translation : ndarray (T, 3)
        Metres; zero where not ok.
    ok : ndarray (T,) bool
        Frames with 3 or more markers seen.
    """
    seen = ~np.isnan(positions[..., 0])
    ok = seen.sum(axis=1) >= 3
    rot = np.tile(np.eye(3), (len(positions), 1, 1))
    trans = np.zeros((len(positions), 3))
    if ok.any():
        r, t = kabsch(np.broadcast_to(canonical, positions[ok].shape), np.nan_to_num(positions[ok]),
                      seen[ok].astype(float))
        rot[ok], trans[ok] = r, t
    return rot, trans, ok


def is_labeling_model(path) -> bool:
    """Whether ``path`` is a labeling model saved by :meth:`LabelingModel.save` (an ``.npz`` of that kind)."""
    from pathlib import Path

    return Path(path).suffix.lower() == ".npz" and str(load_npz(path).get("kind", "")) == "labeling_model"
