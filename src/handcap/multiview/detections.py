"""2D marker detections: the ``.npz`` File contract, its checks, and matching it to a camera rig.

One row per observation (see DESIGN.md, File contracts)::

    camera_names (C,)   names of the cameras, as in the rig file
    marker_names (M,)   marker ids
    frame (N,)          frame index, 0-based
    camera (N,)         index into camera_names
    marker (N,)         index into marker_names
    xy (N, 2)           pixels in the distorted image (OpenCV's convention)
    score (N,)          detector confidence, 0..1 (1 when the detector has none)
    rate ()             frames per second
    n_frames ()         optional: frames in the take (default: last frame + 1)
    pitch ()            optional: side of the printed squares of coded patches, metres (``handcap detect``
                        with a template: adjacent corners ``NAME_r{r}c{c}`` lie this far apart on the patch)

``handcap synth`` writes exactly this (plus a ``wrong_id`` column with the
truth about its injected outliers, which the loader ignores). Several files,
say one per camera, merge into one with :func:`merge_detections`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from handcap.core.cameras import CameraRig
from handcap.core.errors import HandcapError
from handcap.core.files import load_npz, save_npz

REQUIRED = ("camera_names", "marker_names", "frame", "camera", "marker", "xy", "score", "rate")


@dataclass(frozen=True, eq=False)
class Detections:
    """2D detections of named markers by named cameras, one row per observation.

    Attributes
    ----------
    camera_names : tuple of str, length C
    marker_names : tuple of str, length M
    frame, camera, marker : ndarray (N,) int64
        Frame index and indices into the name tuples.
    xy : ndarray (N, 2) float64
        Distorted pixels.
    score : ndarray (N,) float64
    rate : float
        Frames per second.
    n_frames : int
        Frames in the take; every ``frame`` is below it.
    source : str
        Where the rows came from (a file name), for messages.
    pitch : float or None
        Side of the printed squares of the coded patches the markers are corners of, metres (None: not
        coded-patch corners, or not known).
    """

    camera_names: tuple
    marker_names: tuple
    frame: np.ndarray
    camera: np.ndarray
    marker: np.ndarray
    xy: np.ndarray
    score: np.ndarray
    rate: float
    n_frames: int
    source: str = "detections"
    pitch: float | None = None

    def __post_init__(self):
        where = self.source
        names = {}
        for key in ("camera_names", "marker_names"):
            value = tuple(str(n) for n in np.asarray(getattr(self, key)).reshape(-1))
            if len(set(value)) != len(value):
                repeated = sorted({n for n in value if value.count(n) > 1})
                raise HandcapError(f"{where}: {key} repeats {', '.join(repeated)}")
            object.__setattr__(self, key, value)
            names[key] = value
        n = None
        for key in ("frame", "camera", "marker"):
            array = np.asarray(getattr(self, key))
            if array.ndim != 1 or not (np.issubdtype(array.dtype, np.integer) or array.size == 0):
                raise HandcapError(f"{where}: {key} must be a 1-D array of whole numbers, got {array.dtype} "
                                   f"{array.shape}")
            n = len(array) if n is None else n
            if len(array) != n:
                raise HandcapError(f"{where}: frame, camera, marker, xy and score must have one row per "
                                   f"observation; {key} has {len(array)}, frame has {n}")
            object.__setattr__(self, key, array.astype(np.int64))
        xy = np.asarray(self.xy, dtype=np.float64) if np.asarray(self.xy).dtype.kind in "fiu" else None
        if xy is None or xy.shape != (n, 2):
            raise HandcapError(f"{where}: xy must be pixels of shape ({n}, 2), got "
                               f"{np.asarray(self.xy).dtype} {np.asarray(self.xy).shape}")
        if not np.isfinite(xy).all():
            bad = int(np.flatnonzero(~np.isfinite(xy).all(axis=1))[0])
            raise HandcapError(f"{where}: xy of row {bad} is not finite ({xy[bad].tolist()})")
        score = np.asarray(self.score)
        if score.dtype.kind not in "fiu" or score.shape != (n,):
            raise HandcapError(f"{where}: score must be {n} numbers, got {score.dtype} {score.shape}")
        object.__setattr__(self, "xy", xy)
        object.__setattr__(self, "score", score.astype(np.float64))
        for key, count in (("camera", len(names["camera_names"])), ("marker", len(names["marker_names"]))):
            index = getattr(self, key)
            if n and (index.min() < 0 or index.max() >= count):
                bad = int(index[(index < 0) | (index >= count)][0])
                raise HandcapError(f"{where}: {key} index {bad} is outside {key}_names (it has {count})")
        try:
            rate = float(self.rate)
        except (TypeError, ValueError):
            raise HandcapError(f"{where}: rate must be a number of frames per second, got {self.rate!r}") from None
        if not (np.isfinite(rate) and rate > 0):
            raise HandcapError(f"{where}: rate must be a positive number of frames per second, got {rate}")
        object.__setattr__(self, "rate", rate)
        if n and self.frame.min() < 0:
            raise HandcapError(f"{where}: frame {int(self.frame.min())} is negative")
        last = int(self.frame.max()) + 1 if n else 0
        n_frames = last if self.n_frames is None else self.n_frames
        if isinstance(n_frames, (bool, np.bool_)) or int(n_frames) != n_frames or n_frames < 0:
            raise HandcapError(f"{where}: n_frames must be a whole number, got {n_frames!r}")
        if int(n_frames) < last:
            raise HandcapError(f"{where}: mismatched frame counts: n_frames is {int(n_frames)} but a detection "
                               f"is in frame {last - 1}")
        object.__setattr__(self, "n_frames", int(n_frames))
        if self.pitch is not None:
            try:
                pitch = float(self.pitch)
            except (TypeError, ValueError):
                raise HandcapError(f"{where}: pitch must be the side of a printed square in metres, got "
                                   f"{self.pitch!r}") from None
            if not (np.isfinite(pitch) and 0 < pitch < 1):
                raise HandcapError(f"{where}: pitch must be the side of a printed square in metres (0 to 1), got "
                                   f"{pitch}")
            object.__setattr__(self, "pitch", pitch)
        for key in ("frame", "camera", "marker", "xy", "score"):
            getattr(self, key).setflags(write=False)

    def __len__(self) -> int:
        return len(self.frame)

    def __repr__(self) -> str:
        return (f"Detections({len(self)} rows, {len(self.camera_names)} cameras, {len(self.marker_names)} markers, "
                f"{self.n_frames} frames at {self.rate:g} Hz)")

    def select_frames(self, start: int, stop: int) -> "Detections":
        """The rows of frames ``start <= frame < stop``, frames renumbered from 0.

        Parameters
        ----------
        start : int
            First frame kept (frame index).
        stop : int
            Frame index one past the last kept.

        Returns
        -------
        Detections
            Pixels unchanged; ``n_frames`` is ``min(stop, n_frames) - start`` (at least 0); same rate and source.
        """
        keep = (self.frame >= start) & (self.frame < stop)
        return Detections(self.camera_names, self.marker_names, self.frame[keep] - start, self.camera[keep],
                          self.marker[keep], self.xy[keep], self.score[keep], self.rate,
                          max(0, min(stop, self.n_frames) - start), self.source, self.pitch)

    def camera_order(self, rig: CameraRig) -> np.ndarray:
        """Index into ``rig`` of each of ``camera_names``.

        Raises
        ------
        HandcapError
            Naming the cameras the rig lacks.
        """
        if not isinstance(rig, CameraRig):
            raise HandcapError(f"need a CameraRig, got {type(rig).__name__}")
        unknown = [name for name in self.camera_names if name not in rig.names]
        if unknown:
            raise HandcapError(f"{self.source}: detections of camera {', '.join(map(repr, unknown))} that the rig "
                               f"lacks (it has {', '.join(rig.names)})")
        return np.array([rig.index(name) for name in self.camera_names], dtype=np.int64)


def detections_of(arrays: dict) -> Detections:
    """The :class:`Detections` of a detections file's arrays, as a step holds them before writing (``n_frames`` and
    ``rate`` among them).

    Parameters
    ----------
    arrays : dict of str to ndarray
    """
    return Detections(arrays["camera_names"], arrays["marker_names"], arrays["frame"], arrays["camera"],
                      arrays["marker"], arrays["xy"], arrays["score"], arrays["rate"], int(arrays["n_frames"]))


def read_detections(path) -> Detections:
    """Read a detections ``.npz`` (File contract above).

    Raises
    ------
    HandcapError
        Not an npz, a key missing, shapes that disagree, indices outside the
        name lists, non-finite pixels, or a frame past ``n_frames``; the
        message names the file.
    """
    arrays = load_npz(path, REQUIRED, what="detections file")
    n_frames, pitch = arrays.get("n_frames"), arrays.get("pitch")
    try:
        return Detections(arrays["camera_names"], arrays["marker_names"], arrays["frame"], arrays["camera"],
                          arrays["marker"], arrays["xy"], arrays["score"], arrays["rate"],
                          None if n_frames is None else int(n_frames), source=str(path),
                          pitch=None if pitch is None else pitch.item() if pitch.size == 1 else pitch)
    except (TypeError, ValueError, OverflowError, HandcapError) as err:
        # One line, whatever the entry held (a message may quote an array).
        reason = " ".join(str(err).split())[:160]
        raise HandcapError(f"{path}: not a valid detections file ({reason})") from None


def write_detections(detections: Detections, path) -> None:
    """Write detections as an ``.npz`` (atomically; identical input, identical bytes).

    Parameters
    ----------
    detections : Detections
        Written with the keys of the File contract: ``xy`` (N, 2) distorted pixels, ``rate`` frames
        per second, ``n_frames``, ``pitch`` where known; ``source`` is not stored.
    path : str or Path
    """
    pitch = {} if detections.pitch is None else {"pitch": np.array(detections.pitch)}
    save_npz(path, {"camera_names": np.array(detections.camera_names),
                    "marker_names": np.array(detections.marker_names), "frame": detections.frame,
                    "camera": detections.camera, "marker": detections.marker, "xy": detections.xy,
                    "score": detections.score, "rate": np.array(detections.rate),
                    "n_frames": np.array(detections.n_frames), **pitch})


def merge_detections(parts, *, same_length: bool = True) -> Detections:
    """One :class:`Detections` from several (say one file per camera).

    Markers are matched by name (the union, in order of appearance); cameras
    must not repeat; rates must agree, and frame counts too unless ``same_length``
    is False (cameras started one by one, to be synchronised: the merged take
    has the longest count).

    Parameters
    ----------
    parts : iterable of Detections
    same_length : bool
        Refuse parts of different frame counts (parts of one take, cameras triggered together).

    Raises
    ------
    HandcapError
        Naming the sources whose camera, rate or frame count clash.
    """
    parts = list(parts)
    if not parts:
        raise HandcapError("no detections to merge")
    if len(parts) == 1:
        return parts[0]
    first = parts[0]
    cameras, markers = [], []
    for part in parts:
        for name in part.camera_names:
            if name in cameras:
                raise HandcapError(f"{part.source}: camera {name!r} also appears in another detections file")
            cameras.append(name)
        markers.extend(name for name in part.marker_names if name not in markers)
        if part.rate != first.rate:
            raise HandcapError(f"{part.source}: rate {part.rate:g} Hz differs from {first.source} ({first.rate:g} Hz)")
        if same_length and part.n_frames != first.n_frames:
            raise HandcapError(f"mismatched frame counts: {part.source} has {part.n_frames} frames, "
                               f"{first.source} has {first.n_frames} (cameras started one by one: synchronise them, "
                               f"triangulate --sync auto)")
    pitches = {p.pitch for p in parts if p.pitch is not None}
    if len(pitches) > 1:
        raise HandcapError(f"the detections files give different pitches of the printed squares: "
                           f"{', '.join(f'{1000 * p:g} mm' for p in sorted(pitches))}; detect each with its own "
                           "session's template")
    camera_index = {name: i for i, name in enumerate(cameras)}
    marker_index = {name: i for i, name in enumerate(markers)}
    columns = {"frame": [], "camera": [], "marker": [], "xy": [], "score": []}
    for part in parts:
        columns["frame"].append(part.frame)
        columns["camera"].append(np.array([camera_index[n] for n in part.camera_names], np.int64)[part.camera])
        columns["marker"].append(np.array([marker_index[n] for n in part.marker_names], np.int64)[part.marker])
        columns["xy"].append(part.xy)
        columns["score"].append(part.score)
    joined = {key: np.concatenate(value) for key, value in columns.items()}
    order = np.lexsort((joined["marker"], joined["camera"], joined["frame"]))
    return Detections(tuple(cameras), tuple(markers), *(joined[k][order] for k in ("frame", "camera", "marker", "xy",
                                                                                  "score")),
                      first.rate, max(p.n_frames for p in parts), source=" + ".join(p.source for p in parts),
                      pitch=next(iter(pitches), None))


__all__ = ["Detections", "merge_detections", "read_detections", "write_detections"]
