"""A live stream: frames in (a file replayed at its rate, so far), labelled, filled and solved one by one
(:class:`~handcap.stream.pipeline.LivePipeline`), out to OSC, WebSocket and LSL, with the latency of every
frame and of each stage, and the memory used.

The latency of a frame runs from its arrival (the moment the replay hands it over) to the moment every output
has sent it. Memory is the process's resident set (Linux ``/proc/self/statm``), read after the first minute
of the stream and at its end.
"""

from __future__ import annotations

import os
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from tqdm import tqdm

from handcap.core.errors import HandcapError
from handcap.core.points import PointCloudSequence
from handcap.solve.motion import observed_markers
from handcap.stream.pipeline import LivePipeline


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
        The joints sent, metres.
    stage_ms : dict of str to ndarray (frames,)
        Each stage's time per frame (``label``, ``fill``, ``solve`` where they ran, and ``send``), milliseconds.
    seen, filled : ndarray (frames,) int
        Markers measured (labelled) and predicted in each frame.
    """

    frames: int
    latency_ms: np.ndarray
    memory_mb: tuple
    solved: np.ndarray
    stage_ms: dict = field(default_factory=dict)
    seen: np.ndarray | None = None
    filled: np.ndarray | None = None

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
           progress: bool | None = None, labeling=None, fill=None) -> StreamStats:
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

    Returns
    -------
    StreamStats
    """
    names = list(attachment.marker_names)
    if labeling is not None:
        frames = (markers.padded() if isinstance(markers, PointCloudSequence) else markers.positions)
    else:
        if isinstance(markers, PointCloudSequence):
            raise HandcapError("unlabelled points: give a labelling model (--labeling) to stream them")
        frames, absent = observed_markers(markers, names)
        if len(absent) == len(names):
            raise HandcapError(f"none of the attachment's markers ({', '.join(names[:4])}...) is in the replayed "
                               "file; unlabelled points need a labelling model (--labeling)")
    rate = markers.rate
    n = len(frames) if seconds is None else min(len(frames), int(round(seconds * rate)))
    pipeline = LivePipeline(attachment, hand, rate=rate, labeling=labeling, fill=fill)
    latency, solved = np.zeros(n), np.full((n, 21, 3), np.nan)
    stage_ms = {k: np.zeros(n) for k in (*pipeline.stages, "send")}
    seen, filled = np.zeros(n, dtype=int), np.zeros(n, dtype=int)
    memory = [resident_mb(), resident_mb()]
    # The outputs' threads (the WebSocket server's event loop) share the interpreter: at the default 5 ms switch
    # interval one of them may hold a frame up for 5 ms. Shorter while the stream runs.
    interval = sys.getswitchinterval()
    sys.setswitchinterval(min(interval, SWITCH_INTERVAL))
    try:
        _run(pipeline, frames, n, rate, outputs, realtime, progress, latency, solved, stage_ms, seen, filled,
             memory)
    finally:
        sys.setswitchinterval(interval)
    return StreamStats(n, latency, tuple(memory), solved, stage_ms, seen, filled)


def _run(pipeline, frames, n, rate, outputs, realtime, progress, latency, solved, stage_ms, seen, filled, memory):
    """The stream's loop (see :func:`stream`); fills the arrays it is given."""
    minute = min(n - 1, int(60 * rate))
    start = time.perf_counter()
    for t in tqdm(range(n), desc="stream", unit="frame", disable=None if progress is None else not progress,
                  leave=False):
        if realtime:
            wait = start + t / rate - time.perf_counter()
            if wait > 0:
                time.sleep(wait)
        arrived = time.perf_counter()
        live = pipeline.frame(frames[t])
        sending = time.perf_counter()
        for send in outputs:
            send(t, t / rate, live.joints, live.phi)
        sent = time.perf_counter()
        latency[t] = (sent - arrived) * 1000
        for k in pipeline.stages:
            stage_ms[k][t] = pipeline.last_ms[k]
        stage_ms["send"][t] = (sent - sending) * 1000
        solved[t], seen[t], filled[t] = live.joints, live.seen, live.filled
        if t == minute:
            memory[0] = resident_mb()
    memory[1] = resident_mb()
