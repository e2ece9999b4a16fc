"""A live stream: frames in (a file replayed at its rate, so far), solved one by one, out to OSC and
WebSocket, with the latency of every frame and the memory used.

The latency of a frame runs from its arrival (the moment the replay hands it over) to the moment every output
has sent it. Memory is the process's resident set (Linux ``/proc/self/statm``), read after the first minute
of the stream and at its end.
"""

from __future__ import annotations

import os
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from tqdm import tqdm

from handcap.core.errors import HandcapError
from handcap.solve.motion import observed_markers
from handcap.stream.solver import FrameSolver


@dataclass(frozen=True)
class StreamStats:
    """What a stream measured.

    Attributes
    ----------
    frames : int
    latency_ms : ndarray (frames,)
        Per frame, milliseconds.
    memory_mb : tuple of float
        Resident memory after the first minute of stream time (or the first frame of a shorter stream) and at
        the end, MiB.
    solved : ndarray (frames, 21, 3)
        The joints sent, metres.
    """

    frames: int
    latency_ms: np.ndarray
    memory_mb: tuple
    solved: np.ndarray

    def summary(self) -> str:
        """One line: frames, latency p50 / p99 / worst, memory growth."""
        lat = self.latency_ms
        first, last = self.memory_mb
        return (f"{self.frames} frames, latency p50 {np.percentile(lat, 50):.2f} ms, p99 {np.percentile(lat, 99):.2f} "
                f"ms, worst {lat.max():.2f} ms; memory {first:.0f} -> {last:.0f} MiB "
                f"({100 * (last - first) / max(first, 1e-9):+.1f} % after the first minute)")


def resident_mb() -> float:
    """The process's resident memory, MiB (0 where ``/proc`` is missing)."""
    statm = Path("/proc/self/statm")
    if not statm.is_file():
        return 0.0
    return int(statm.read_text().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 2 ** 20


def stream(markers, attachment, hand, outputs=(), *, realtime: bool = True, seconds: float | None = None,
           progress: bool | None = None) -> StreamStats:
    """Replay labelled markers as a live stream: solve every frame and send it to every output.

    Parameters
    ----------
    markers : MarkerSequence
        Labelled markers, metres; the attachment's are used.
    attachment : MarkerAttachment
    hand : HandModel
    outputs : sequence of callables ``(frame, time_s, joints, phi)``
        :class:`~handcap.stream.outputs.OscOutput`, :class:`~handcap.stream.outputs.WebSocketOutput` ...
    realtime : bool
        Hand frames over at the take's rate (False: as fast as they are solved).
    seconds : float or None
        Stop after this much stream time.
    progress : bool or None
        Progress bar (default: on a terminal).

    Returns
    -------
    StreamStats
    """
    names = list(attachment.marker_names)
    target, absent = observed_markers(markers, names)
    if len(absent) == len(names):
        raise HandcapError(f"none of the attachment's markers ({', '.join(names[:4])}...) is in the replayed file")
    n = markers.n_frames if seconds is None else min(markers.n_frames, int(round(seconds * markers.rate)))
    solver = FrameSolver(attachment, hand)
    latency, solved = np.zeros(n), np.full((n, 21, 3), np.nan)
    minute = min(n - 1, int(60 * markers.rate))
    memory = [resident_mb(), resident_mb()]
    start = time.perf_counter()
    for t in tqdm(range(n), desc="stream", unit="frame", disable=None if progress is None else not progress,
                  leave=False):
        if realtime:
            wait = start + t / markers.rate - time.perf_counter()
            if wait > 0:
                time.sleep(wait)
        arrived = time.perf_counter()
        joints, phi, _ = solver.solve(target[t])
        for send in outputs:
            send(t, t / markers.rate, joints, phi)
        latency[t] = (time.perf_counter() - arrived) * 1000
        solved[t] = joints
        if t == minute:
            memory[0] = resident_mb()
    memory[1] = resident_mb()
    return StreamStats(n, latency, tuple(memory), solved)
