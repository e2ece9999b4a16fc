"""``handcap stream``: a labelled take replayed as a live stream, solved frame by frame, sent over OSC and
WebSocket."""

from __future__ import annotations

from handcap.hand import hand_model_from_options
from handcap.hand.attachment import MarkerAttachment
from handcap.io import read_markers
from handcap.steps.step import Step
from handcap.stream import OscOutput, WebSocketOutput, stream


def _cmd_stream(a):
    attachment = MarkerAttachment.load(a.attachment)
    markers = read_markers(a.replay, units=a.units, hand=attachment.marker_names)
    hand = hand_model_from_options(None, None, side=attachment.side, recorded=attachment.model, what=a.attachment)
    outputs = [OscOutput(target) for target in a.osc or ()] + [WebSocketOutput(port) for port in a.websocket or ()]
    try:
        stats = stream(markers, attachment, hand, outputs, realtime=not a.fast, seconds=a.seconds)
    finally:
        for output in outputs:
            output.close()
    return Step((f"{a.replay}: {stats.summary()}",), (), (), stats)


def add_stream(verbs) -> None:
    p = verbs.add_parser("stream", help="replay a labelled take as a live stream: solve each frame, send it out",
                         description="Frames are handed over at the take's rate, solved one by one (warm-started "
                                     "Levenberg-Marquardt), and sent to every output: OSC messages /handcap/joints "
                                     "and /handcap/angles, and JSON to WebSocket clients. Ends with the latency per "
                                     "frame (p50, p99) and the memory growth. Needs the extra 'stream'.")
    p.add_argument("--replay", required=True, help="labelled markers to replay (.c3d .trc .npz ...)")
    p.add_argument("--attachment", required=True, help="the attachment .npz (calibrate-markers)")
    p.add_argument("--osc", action="append", metavar="HOST:PORT", help="send OSC over UDP there (repeatable)")
    p.add_argument("--websocket", action="append", metavar="[HOST:]PORT",
                   help="serve WebSocket clients on this port (repeatable)")
    p.add_argument("--fast", action="store_true", help="as fast as frames are solved, not at the take's rate")
    p.add_argument("--seconds", type=float, help="stop after this much of the take")
    p.add_argument("--units", choices=("mm", "cm", "m"), help="unit of the replayed file's coordinates")
    p.set_defaults(run=_cmd_stream)
