"""A live stream: frames in (a file replayed at its rate, so far), labelled, filled and solved one by one
(:class:`~handcap.stream.pipeline.LivePipeline`), out to OSC, WebSocket and LSL, with the latency of every
frame and of each stage, and the memory used.

The latency of a frame runs from its arrival (the moment the replay hands it over) to the moment every output
has sent it. The work that only the next frame needs (the labeler's filters and its periodic re-alignment) is
done after the sending, between frames (:meth:`LivePipeline.idle`). Memory is the process's resident set
(Linux ``/proc/self/statm``), read after the first minute of the stream and at its end.
"""

from __future__ import annotations

import os
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from tqdm import tqdm

from handcap.core.errors import HandcapError, warn
from handcap.quality.fit_checks import lost_frame_warnings
from handcap.core.points import PointCloudSequence
from handcap.core.markers import MarkerSequence
from handcap.stream.pipeline import LivePipeline
from handcap.stream.solver import SMOOTHING
from handcap.stream.sources import ReplaySource


#: The interpreter's thread switch interval while a stream runs, seconds (default 0.005).
SWITCH_INTERVAL = 0.0002


@dataclass(frozen=True)
class StreamStats:
    """What a stream measured.

    Attributes
    ----------
    frames : int
    latency_ms : ndarray (frames,)
        Per frame, from its arrival to its sending by every output, milliseconds.
    memory_mb : tuple of float
        Resident memory after the first minute of stream time (or the first frame of a shorter stream) and at
        the end, MiB.
    solved : ndarray (frames, 21, 3)
        The joints sent, metres (empty when the stream was asked not to keep them).
    stage_ms : dict of str to ndarray (frames,)
        Each stage's time per frame (``label``, ``fill``, ``solve`` where they ran, and ``send``), milliseconds.
    seen, filled : ndarray (frames,) int
        Markers measured (labelled) and predicted in each frame.
    warnings : tuple of str
        Printed as :class:`~handcap.HandcapWarning` at the stream's end: labels the solve found swapped and solved
        exchanged (:meth:`FrameSolver.swap_warnings`), the solve's mean marker error above 5 mm
        (:meth:`FrameSolver.fit_warnings`), frames with too few markers to place the hand, and the labels'
        plausibility (:meth:`LivePipeline.label_warnings`: a rigid set re-learned, the hand frame often lost,
        labels hardly given, few points labelled, labels released).
    """

    frames: int
    latency_ms: np.ndarray
    memory_mb: tuple
    solved: np.ndarray
    stage_ms: dict = field(default_factory=dict)
    seen: np.ndarray | None = None
    filled: np.ndarray | None = None
    warnings: tuple = ()

    def summary(self) -> str:
        """Frames, latency p50 / p99 / worst, each stage's p99, markers seen and filled, memory growth."""
        lat = self.latency_ms
        first, last = self.memory_mb
        stages = ", ".join(f"{k} {np.percentile(v, 99):.2f}" for k, v in self.stage_ms.items())
        markers = "" if self.seen is None else (f"; markers per frame: {self.seen.mean():.1f} seen, "
                                                f"{self.filled.mean():.1f} filled")
        return (f"{self.frames} frames, latency p50 {np.percentile(lat, 50):.2f} ms, p99 {np.percentile(lat, 99):.2f} "
                f"ms, worst {lat.max():.2f} ms" + (f" (p99 by stage, ms: {stages})" if stages else "") + markers +
                f"; memory {first:.0f} -> {last:.0f} MiB "
                f"({100 * (last - first) / max(first, 1e-9):+.1f} % after the first minute)")


def resident_mb() -> float:
    """The process's resident memory, MiB (0 where ``/proc`` is missing)."""
    statm = Path("/proc/self/statm")
    if not statm.is_file():
        return 0.0
    return int(statm.read_text().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 2 ** 20


def stream(markers, attachment, hand, outputs=(), *, realtime: bool = True, seconds: float | None = None,
           progress: bool | None = None, labeling=None, fill=None, smoothing: float = SMOOTHING,
           mend_swaps: bool = True) -> StreamStats:
    """Replay a take as a live stream: label, fill and solve every frame and send it to every output.

    Parameters
    ----------
    markers : MarkerSequence or PointCloudSequence
        The take, metres. Without ``labeling``, labelled markers (the attachment's are used); with it, its
        points are unlabelled (any names are ignored).
    attachment : MarkerAttachment
    hand : HandModel
    outputs : sequence of callables ``(frame, time_s, joints, phi)``
        :class:`~handcap.stream.outputs.OscOutput`, :class:`~handcap.stream.outputs.WebSocketOutput`,
        :class:`~handcap.stream.outputs.LslOutput` ...
    realtime : bool
        Hand frames over at the take's rate (False: as fast as they are solved).
    seconds : float or None
        Stop after this much stream time.
    progress : bool or None
        Progress bar (default: on a terminal).
    labeling, fill
        A labelling model and an occlusion model (see :class:`~handcap.stream.pipeline.LivePipeline`).
    smoothing : float
        The solve's pull towards the predicted angles (:class:`~handcap.stream.solver.FrameSolver`; 0: none).
    mend_swaps : bool
        Labels the solved hand finds swapped are solved exchanged, with a warning (False: as given).

    Returns
    -------
    StreamStats
    """
    if labeling is not None:
        frames, names = (markers.padded() if isinstance(markers, PointCloudSequence) else markers.positions), None
    else:
        if isinstance(markers, PointCloudSequence):
            raise HandcapError("unlabelled points: give a labelling model (--labeling) to stream them")
        names = tuple(attachment.marker_names)
        columns = marker_columns(markers.names, names)
        frames = markers.positions[:, np.maximum(columns, 0)]  # in the attachment's order once, not frame by frame
        frames[:, columns < 0] = np.nan
    n = len(frames) if seconds is None else min(len(frames), int(round(seconds * markers.rate)))
    source = ReplaySource(frames[:n], markers.rate, names, realtime=realtime)
    return stream_source(source, attachment, hand, outputs, progress=progress, labeling=labeling, fill=fill,
                         smoothing=smoothing, mend_swaps=mend_swaps)


def stream_source(source, attachment, hand, outputs=(), *, seconds: float | None = None,
                  progress: bool | None = None, labeling=None, fill=None, keep_solved: bool = True,
                  smoothing: float = SMOOTHING, mend_swaps: bool = True) -> StreamStats:
    """Label, fill and solve every frame of a live source and send it to every output.

    Parameters
    ----------
    source : ReplaySource, QtmSource or another iterable of ``(arrived, frame (K, 3))``
        With ``names`` (the K markers' names, None for unlabelled points) and ``rate`` (see
        :mod:`handcap.stream.sources`).
    attachment : MarkerAttachment
    hand : HandModel
    outputs : sequence of callables ``(frame, time_s, joints, phi)``
    seconds : float or None
        Stop after this many seconds of frames.
    progress : bool or None
        Progress bar (default: on a terminal).
    labeling, fill
        A labelling model (needed for unlabelled points) and an occlusion model.
    keep_solved : bool
        Keep every frame's joints in the result (``solved``); a stream of no known end should not (its other
        records take 40 bytes a frame).
    smoothing : float
        The solve's pull towards the predicted angles (:class:`~handcap.stream.solver.FrameSolver`; 0: none).
    mend_swaps : bool
        Labels the solved hand finds swapped are solved exchanged, with a warning (False: as given).

    Returns
    -------
    StreamStats
    """
    names = list(attachment.marker_names)
    columns = None
    if labeling is None:
        if source.names is None:
            raise HandcapError("unlabelled points: give a labelling model (--labeling) to stream them")
        if tuple(source.names) != tuple(names):  # a replay comes in the attachment's order already
            columns = marker_columns(source.names, names)
    limit = None if seconds is None else int(round(seconds * source.rate))
    pipeline = LivePipeline(attachment, hand, rate=source.rate, labeling=labeling, fill=fill, smoothing=smoothing,
                            mend_swaps=mend_swaps)
    size = len(source) if hasattr(source, "__len__") else int(60 * source.rate)
    if limit is not None:
        size = min(size, limit)
    rows = _Rows(size, (*pipeline.stages, "send"), keep_solved)
    memory = [resident_mb(), resident_mb()]
    # The outputs' threads (the WebSocket server's event loop) share the interpreter: at the default 5 ms switch
    # interval one of them may hold a frame up for 5 ms. Shorter while the stream runs.
    interval = sys.getswitchinterval()
    sys.setswitchinterval(min(interval, SWITCH_INTERVAL))
    minute = int(60 * source.rate)
    try:
        frames = tqdm(source, desc="stream", unit="frame", total=len(source) if hasattr(source, "__len__") else limit,
                      disable=None if progress is None else not progress, leave=False)
        for t, (arrived, frame) in enumerate(frames):
            if limit is not None and t >= limit:
                break
            lost = frame is None  # a frame the source lost: every stage steps over it (the filters keep time)
            if lost:
                frame = np.full((0 if labeling is not None else len(source.names), 3), np.nan)
            if columns is not None:
                frame = np.where(columns[:, None] >= 0, np.asarray(frame)[np.maximum(columns, 0)], np.nan)
            live = pipeline.frame(frame)
            if lost:  # ... and nothing is sent or counted
                pipeline.idle()
                continue
            sending = time.perf_counter()
            for send in outputs:
                send(t, t / source.rate, live.joints, live.phi)
            sent = time.perf_counter()
            pipeline.idle()  # what only the next frame needs, between frames
            rows.add(rows.count, (sent - arrived) * 1000, {**pipeline.last_ms, "send": (sent - sending) * 1000}, live)
            if t == minute:
                memory[0] = resident_mb()
    finally:
        sys.setswitchinterval(interval)
    memory[1] = resident_mb()
    if not rows.count:
        raise HandcapError("the source sent no frame")
    n = rows.count
    stage_ms = {k: v[:n].astype(np.float64) for k, v in rows.stage_ms.items()}
    solved = rows.solved[:n] if keep_solved else np.zeros((0, 21, 3))
    said = getattr(source, "warnings", list)() + pipeline.solver.swap_warnings(source.rate) \
        + pipeline.solver.fit_warnings() + lost_frame_warnings(rows.seen[:n]) + pipeline.label_warnings(source.rate)
    found = tuple(warn(line) for line in said if line)
    return StreamStats(n, rows.latency[:n].astype(np.float64), tuple(memory), solved, stage_ms, rows.seen[:n],
                       rows.filled[:n], found)


class _Rows:
    """Per-frame records of a stream in arrays allocated ahead (a replay's length, else a minute, doubled when
    full), so that the stream's own bookkeeping does not show as memory growing frame by frame."""

    def __init__(self, size: int, stages, keep_solved: bool):
        size = max(size, 1)
        self.count, self.keep_solved = 0, keep_solved
        self.latency, self.seen, self.filled = np.zeros(size, np.float32), np.zeros(size, int), np.zeros(size, int)
        self.stage_ms = {k: np.zeros(size, np.float32) for k in stages}
        self.solved = np.full((size if keep_solved else 0, 21, 3), np.nan)

    def _grow(self) -> None:
        for name in ("latency", "seen", "filled") + (("solved",) if self.keep_solved else ()):
            old = getattr(self, name)
            setattr(self, name, np.concatenate([old, np.zeros_like(old)]))
        self.stage_ms = {k: np.concatenate([v, np.zeros_like(v)]) for k, v in self.stage_ms.items()}

    def add(self, t: int, latency: float, stage_ms: dict, live) -> None:
        if t >= len(self.latency):
            self._grow()
        self.latency[t], self.seen[t], self.filled[t] = latency, live.seen, live.filled
        for k, v in self.stage_ms.items():
            v[t] = stage_ms[k]
        if self.keep_solved:
            self.solved[t] = live.joints
        self.count = t + 1


def marker_columns(source_names, names) -> np.ndarray:
    """For each of ``names``, its column among ``source_names`` (``Subject:`` prefixes allowed), -1 if absent.

    Parameters
    ----------
    source_names : sequence of str
        The K markers a source sends.
    names : sequence of str
        The markers wanted (an attachment's).

    Raises
    ------
    HandcapError
        None of ``names`` is sent.
    """
    probe = MarkerSequence(np.zeros((1, len(source_names), 3)), tuple(source_names), 100.0)
    columns = []
    for name in names:
        try:
            columns.append(probe.index(name))
        except HandcapError:
            columns.append(-1)
    columns = np.array(columns)
    if (columns < 0).all():
        raise HandcapError(f"none of the attachment's markers ({', '.join(names[:4])}...) is in the stream "
                           f"({', '.join(source_names[:4])}...); unlabelled points need a labelling model (--labeling)")
    return columns
