"""Where a live stream's frames come from: a file replayed at its rate (:class:`ReplaySource`), or Qualisys Track
Manager's real-time server (:class:`QtmSource`, through Qualisys's own client ``qtm-rt``).

A source is an iterable of ``(arrived, frame)``: the ``time.perf_counter()`` at which the frame arrived (the
latency of a frame is counted from there) and its points, ``(K, 3)`` metres with NaN rows for markers not seen,
or None for a frame the source lost (QTM skipped its number: the stages step over it, so that the filters keep
time, and nothing is sent). It has ``names`` (the K columns' marker names, or None for unlabelled points),
``rate`` (frames per second) and ``warnings()`` (one line each, said at the stream's end).
"""

from __future__ import annotations

import asyncio
import contextlib
import queue
import threading
import time
import xml.etree.ElementTree as ET

import numpy as np

from handcap.core.errors import HandcapError

#: Qualisys's default port of the real-time protocol (little endian).
QTM_PORT = 22223
#: Version of the real-time protocol asked for.
QTM_PROTOCOL = "1.25"
#: Frame numbers QTM skipped are stepped over as frames of no marker up to this many seconds of them; a longer jump
#: is a paused or restarted measurement, not frames lost.
MAX_SKIPPED = 1.0


class ReplaySource:
    """A take's frames handed over one by one, at the take's rate or as fast as they are taken.

    Parameters
    ----------
    frames : ndarray (T, K, 3)
        Metres, NaN where missing.
    rate : float
        Frames per second.
    names : sequence of str or None
        The K columns' names (None: unlabelled points).
    realtime : bool
        Hand frames over at ``rate``, each stamped as arrived at its time in the take, however late it is taken
        (False: each as soon as the one before is taken, stamped then).
    """

    def __init__(self, frames, rate: float, names=None, *, realtime: bool = True):
        self.frames, self.rate, self.names, self.realtime = frames, float(rate), names, realtime

    def __len__(self) -> int:
        return len(self.frames)

    def __iter__(self):
        start = time.perf_counter()
        for t, frame in enumerate(self.frames):
            if not self.realtime:
                yield time.perf_counter(), frame
                continue
            due = start + t / self.rate
            wait = due - time.perf_counter()
            if wait > 0:
                time.sleep(wait)
            # Stamped with its own time: a frame taken late (the frames before took longer than the rate allows)
            # waited for the stream from then on, as a live system's frame waits in its queue.
            yield due, frame

    def warnings(self) -> list[str]:
        """None: a replay loses no frame."""
        return []

    def close(self) -> None:
        """Nothing to release."""


def _endpoint(address: str) -> tuple[str, int]:
    host, _, port = str(address).partition(":")
    try:
        number = int(port) if port else QTM_PORT
    except ValueError:
        raise HandcapError(f"--qtm {address!r}: give HOST or HOST:PORT") from None
    if not host or not 0 < number < 65536:
        raise HandcapError(f"--qtm {address!r}: give HOST or HOST:PORT (port 1-65535)")
    return host, number


def parse_qtm_parameters(text) -> tuple[float, tuple[str, ...]]:
    """The capture rate and the 3D labels of QTM's parameters XML (``getparameters general 3d``).

    Parameters
    ----------
    text : bytes or str

    Returns
    -------
    rate : float
        Frames per second (``General/Frequency``).
    names : tuple of str
        The labelled trajectories, in the order of the 3D component (``The_3D/Label/Name``).
    """
    try:
        root = ET.fromstring(text)
        rate = float(root.findtext(".//General/Frequency"))
    except (ET.ParseError, TypeError, ValueError):
        raise HandcapError("QTM's parameters have no capture frequency (General/Frequency): is it QTM?") from None
    names = tuple(label.findtext("Name") or f"unnamed_{k}" for k, label in enumerate(root.iterfind(".//The_3D/Label")))
    return rate, names


class QtmSource:
    """Frames streamed by Qualisys Track Manager (its real-time protocol, through ``qtm-rt``).

    The client runs on an event loop of its own thread; each data packet's 3D markers (millimetres, NaN when not
    seen) become a frame in metres, stamped when the packet arrived.

    Parameters
    ----------
    address : str
        ``HOST`` or ``HOST:PORT`` of QTM's real-time server (port 22223 by default).
    labelled : bool
        Stream QTM's labelled trajectories (component ``3d``; ``names`` their labels), or its unlabelled points
        (``3dnolabels``; for the labeler).
    timeout : float
        Seconds to wait for QTM to answer, and for the next frame before the stream is over.

    Raises
    ------
    HandcapError
        ``qtm-rt`` missing, no QTM answering there, or no 3D labels to stream.
    """

    def __init__(self, address: str, *, labelled: bool = True, timeout: float = 5.0):
        try:
            import qtm_rt  # noqa: PLC0415 (optional extra 'stream')
        except ImportError:
            raise HandcapError("streaming from QTM needs qtm-rt: pip install 'handcap[stream]'") from None
        self.qtm_rt, self.labelled, self.timeout = qtm_rt, labelled, float(timeout)
        self.last = None  # the last frame number QTM sent
        self.lost = self.jumps = self.unordered = 0  # frames skipped and stepped over; longer gaps; numbers not rising
        self.host, self.port = _endpoint(address)
        self.frames = queue.Queue()
        self.loop = asyncio.new_event_loop()
        self.thread = threading.Thread(target=self.loop.run_forever, daemon=True)
        self.thread.start()
        self.connection = None
        try:
            self.rate, names = self._call(self._connect())
        except (OSError, asyncio.TimeoutError, qtm_rt.QRTCommandException) as err:
            self.close()
            raise HandcapError(f"--qtm {address}: QTM did not answer ({type(err).__name__}: {err})") from None
        if labelled and not names:
            self.close()
            raise HandcapError(f"--qtm {address}: QTM has no labelled trajectories (give --labeling and stream its "
                               "unlabelled points)")
        self.names = names if labelled else None

    def _call(self, coroutine):
        return asyncio.run_coroutine_threadsafe(coroutine, self.loop).result(self.timeout * 3)

    async def _connect(self):
        self.connection = await self.qtm_rt.connect(self.host, self.port, version=QTM_PROTOCOL,
                                                    timeout=self.timeout,
                                                    on_disconnect=lambda _: self.frames.put(None))
        if self.connection is None:
            raise OSError(f"no QTM real-time server at {self.host}:{self.port}")
        return parse_qtm_parameters(await self.connection.get_parameters(["general", "3d"]))

    def _on_packet(self, packet) -> None:
        arrived = time.perf_counter()
        if self.labelled:
            markers = packet.get_3d_markers()
        else:
            markers = packet.get_3d_markers_no_label()
        points = np.array([m[:3] for m in markers[1]], dtype=np.float64).reshape(-1, 3) / 1000.0
        self.frames.put((arrived, points, int(packet.framenumber)))

    def __iter__(self):
        component = "3d" if self.labelled else "3dnolabels"
        self._call(self.connection.stream_frames(components=[component], on_packet=self._on_packet))
        while True:
            try:
                item = self.frames.get(timeout=self.timeout)
            except queue.Empty:
                return  # QTM stopped sending
            if item is None:
                return  # disconnected
            arrived, points, number = item
            skipped = 0 if self.last is None else number - self.last - 1
            if skipped < 0:
                self.unordered += 1  # a frame number not after the last (QTM restarted, or its numbers stuck)
            elif skipped > MAX_SKIPPED * self.rate:
                self.jumps += 1  # QTM paused or restarted its measurement: not frames to step over
            else:
                self.lost += skipped
                for _ in range(skipped):
                    yield arrived, None
            self.last = number
            yield arrived, points

    def warnings(self) -> list[str]:
        """Frames QTM skipped (its real-time output falling behind: its frame numbers jump), and frame numbers that
        did not rise, one line each; none when every frame came in order.

        Returns
        -------
        list of str
        """
        out = []
        if self.lost:
            out.append(f"QTM: {self.lost} frame(s) skipped in its real-time output (frame numbers jumped; QTM falls "
                       "behind when its processing is heavy, e.g. AIM or skeleton solving): stepped over as frames "
                       "of no marker (their joints not sent); lower the real-time frequency or QTM's processing")
        if self.jumps:
            out.append(f"QTM: its frame numbers jumped by over {MAX_SKIPPED:g} s {self.jumps} time(s) (a paused or "
                       "restarted measurement): the stream went on from there")
        if self.unordered:
            out.append(f"QTM: {self.unordered} frame(s) came with a number not after the frame before (a restarted "
                       "measurement, or numbers that do not count): streamed as they came")
        return out

    def close(self) -> None:
        """Stop the stream and disconnect."""
        if self.connection is not None and self.connection.has_transport():
            # closing: QTM gone or slow to answer changes nothing now
            with contextlib.suppress(OSError, TimeoutError, asyncio.TimeoutError, self.qtm_rt.QRTCommandException):
                self._call(self.connection.stream_frames_stop())
            self.loop.call_soon_threadsafe(self.connection.disconnect)
        self.loop.call_soon_threadsafe(self.loop.stop)
        self.thread.join(5)
