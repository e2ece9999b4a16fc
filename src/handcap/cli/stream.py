"""``handcap stream``: frames from a replayed take or from Qualisys Track Manager, labelled, filled and solved one
by one, sent over OSC, WebSocket and LSL."""

from __future__ import annotations

from handcap.hand import hand_model_from_options
from handcap.hand.attachment import MarkerAttachment
from handcap.hand.anatomy import JOINT_NAMES, PHI_NAMES, TIP_NAMES
from handcap.io import read_markers, read_points
from handcap.occlusion import SHIPPED_MODELS
from handcap.steps.step import Step
from handcap.stream import LslOutput, OscOutput, WebSocketOutput
from handcap.stream.live import stream, stream_source
from handcap.stream.solver import SMOOTHING
from handcap.stream.sources import QtmSource


def _cmd_stream(a):
    attachment = MarkerAttachment.load(a.attachment)
    hand = hand_model_from_options(None, None, side=attachment.side, recorded=attachment.model, what=a.attachment)
    if a.qtm:  # with a labelling model QTM's unlabelled points, else its labelled trajectories
        source = QtmSource(a.qtm, labelled=not a.labeling)
    elif a.labeling:
        source = read_points(a.replay, units=a.units)  # unlabelled: whatever names the file has are ignored
    else:
        source = read_markers(a.replay, units=a.units, hand=attachment.marker_names)
    outputs = []
    try:
        outputs += [OscOutput(target) for target in a.osc or ()]
        outputs += [WebSocketOutput(port) for port in a.websocket or ()]
        outputs += [LslOutput(name, source.rate, JOINT_NAMES + TIP_NAMES, PHI_NAMES) for name in a.lsl or ()]
        if a.qtm:  # live: no end known, so no joints kept
            stats = stream_source(source, attachment, hand, outputs, seconds=a.seconds, labeling=a.labeling,
                                  fill=a.fill, keep_solved=False, smoothing=a.smoothing,
                                  mend_swaps=not a.keep_swaps)
        else:
            stats = stream(source, attachment, hand, outputs, realtime=not a.fast, seconds=a.seconds,
                           labeling=a.labeling, fill=a.fill, smoothing=a.smoothing, mend_swaps=not a.keep_swaps)
    finally:
        for output in outputs:
            output.close()
        if a.qtm:
            source.close()
    return Step((f"{a.qtm or a.replay}: {stats.summary()}",), stats.warnings, (), stats)


def add_stream(verbs) -> None:
    p = verbs.add_parser("stream",
                         help="a live stream (a replayed take, or QTM): label, fill and solve each frame, send it out",
                         description="Frames come from a take replayed at its rate or live from Qualisys Track "
                                     "Manager, are labelled (with --labeling: the online labeler), filled (with "
                                     "--fill: the occlusion autoencoder), solved one by one (warm-started "
                                     "Levenberg-Marquardt), and sent to every output: OSC messages /handcap/joints "
                                     "and /handcap/angles, JSON to WebSocket clients, LSL outlets NAME-joints and "
                                     "NAME-angles. Ends with the latency per frame (p50, "
                                     "p99, and each stage's) and the memory growth. Needs the extra 'stream'.")
    source = p.add_mutually_exclusive_group(required=True)
    source.add_argument("--replay", metavar="FILE",
                        help="the take to replay: labelled markers (.c3d .trc .npz ...), or with --labeling "
                             "unlabelled points (any marker file, its names ignored, or a points .npz)")
    source.add_argument("--qtm", metavar="HOST[:PORT]",
                        help="stream live from Qualisys Track Manager's real-time server (port 22223 by default): "
                             "its labelled trajectories, or with --labeling its unlabelled points")
    p.add_argument("--attachment", required=True, help="the attachment .npz (calibrate-markers)")
    p.add_argument("--labeling", metavar="MODEL",
                   help="label every frame's points with this labelling model (.npz, from handcap label --model)")
    p.add_argument("--fill", metavar="MODEL",
                   help=f"fill hidden markers with this occlusion model: {', '.join(SHIPPED_MODELS)} or a .npz "
                        "(train-occlusion)")
    p.add_argument("--lsl", action="append", metavar="NAME",
                   help="push every frame to the LSL outlets NAME-joints and NAME-angles (repeatable)")
    p.add_argument("--osc", action="append", metavar="HOST:PORT", help="send OSC over UDP there (repeatable)")
    p.add_argument("--websocket", action="append", metavar="[HOST:]PORT",
                   help="serve WebSocket clients on this port (repeatable)")
    p.add_argument("--fast", action="store_true",
                   help="replay as fast as frames are solved, not at the take's rate")
    p.add_argument("--smoothing", type=float, default=SMOOTHING, metavar="K",
                   help=f"pull each frame's angles towards where the frames before carry them, K times as strong as "
                        f"the markers in a typical frame (default {SMOOTHING}; 0: each frame from its markers alone). "
                        "Keeps a sparse glove from jumping between two poses its markers allow")
    p.add_argument("--keep-swaps", action="store_true",
                   help="solve the labels as given: by default two labels the solved hand finds swapped are solved "
                        "exchanged from that frame on, and a warning names them at the end")
    p.add_argument("--seconds", type=float, help="stop after this many seconds of frames")
    p.add_argument("--units", choices=("mm", "cm", "m"), help="unit of the replayed file's coordinates")
    p.set_defaults(run=_cmd_stream)
