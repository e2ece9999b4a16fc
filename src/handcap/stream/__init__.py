"""Live streams (issue 19): frames labelled, filled and solved one by one (:mod:`~handcap.stream.pipeline`,
:mod:`~handcap.stream.solver`), sent over OSC, WebSocket and LSL (:mod:`~handcap.stream.outputs`), with per-frame
latency and memory (:mod:`~handcap.stream.live`)."""

from handcap.stream.live import StreamStats, stream
from handcap.stream.outputs import LslOutput, OscOutput, WebSocketOutput
from handcap.stream.pipeline import LiveFrame, LivePipeline
from handcap.stream.solver import FrameSolver

__all__ = ["FrameSolver", "LiveFrame", "LivePipeline", "LslOutput", "OscOutput", "StreamStats", "WebSocketOutput",
           "stream"]
