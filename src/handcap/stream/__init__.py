"""Live streams (issue 19): frames solved one by one (:mod:`~handcap.stream.solver`), sent over OSC and
WebSocket (:mod:`~handcap.stream.outputs`), with per-frame latency and memory (:mod:`~handcap.stream.live`)."""

from handcap.stream.live import StreamStats, stream
from handcap.stream.outputs import OscOutput, WebSocketOutput
from handcap.stream.solver import FrameSolver

__all__ = ["FrameSolver", "OscOutput", "StreamStats", "WebSocketOutput", "stream"]
