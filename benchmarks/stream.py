"""Live streaming (issue 19): a take's unlabelled points replayed as a live stream, labelled, filled and solved
frame by frame and sent over OSC, WebSocket and LSL to loopback receivers, each measured in this run.

A synthetic take (layout ``joints-19``: 19 markers and the 3 on the back of the hand, 120 Hz, ``--take-seconds``
long, default 20 s; dropouts, ghost points and swaps as ``handcap synth`` makes them) is replayed in a loop for
``--seconds`` (default 600: ten minutes) at the take's rate, as live (``--fast``: as fast as it is handled). Its
points are unlabelled: the labelling model is trained on another take of the same subject (its range of
motion, ``--rom-seconds`` long, default 30 s), and the hidden markers are filled by the shipped ``joints-19``
occlusion model. The receivers (an OSC server, a WebSocket client and two LSL inlets) run in a process of their
own. Printed: frames, latency per
frame (p50, p99, p99.9, worst; from a frame's arrival to its sending by every output; goal p99 < 5 ms) and each
stage's, the process's resident memory after the first minute and at the end (goal: growth < 5 %), messages
the receivers got, and the streamed joints against the synthetic truth.

    .venv/bin/python benchmarks/stream.py [--seconds 600] [--take-seconds 20] [--rom-seconds 30] [--fast]
                                          [--labelled] [--keep-swaps]
"""

from __future__ import annotations

import argparse
import multiprocessing
import os
import threading
import time

import numpy as np


def receivers(ws_port, lsl_ids, ports, counts, stop) -> None:
    """The loopback receivers, in a process of their own: an OSC server (its port sent on ``ports``), a
    WebSocket client and an LSL inlet per source id; their message counts go to ``counts`` once ``stop`` is
    set."""
    import pylsl
    from pythonosc.dispatcher import Dispatcher
    from pythonosc.osc_server import BlockingOSCUDPServer
    from websockets.sync.client import connect

    if hasattr(os, "sched_setaffinity") and os.cpu_count() > 1:
        os.sched_setaffinity(0, {os.cpu_count() - 1})  # the last core: as if the receivers were other programs
    got = {"osc": 0, "ws": 0, "lsl": [0] * len(lsl_ids)}
    dispatcher = Dispatcher()
    dispatcher.map("/handcap/joints", lambda *_: got.__setitem__("osc", got["osc"] + 1))
    server = BlockingOSCUDPServer(("127.0.0.1", 0), dispatcher)  # one thread, not one per datagram
    threading.Thread(target=server.serve_forever, daemon=True).start()

    def receive():
        with connect(f"ws://127.0.0.1:{ws_port}") as client:
            for _ in client:
                got["ws"] += 1

    def pull(k, source_id):
        inlet = pylsl.StreamInlet(pylsl.resolve_byprop("source_id", source_id, timeout=30)[0],
                                  max_buflen=30, recover=False)
        inlet.open_stream(timeout=30)
        ports.put(("lsl", k))
        while not stop.is_set() or inlet.samples_available():
            chunk, _ = inlet.pull_chunk(timeout=0.2, max_samples=4096)
            got["lsl"][k] += len(chunk)

    threading.Thread(target=receive, daemon=True).start()
    pulls = [threading.Thread(target=pull, args=(k, i), daemon=True) for k, i in enumerate(lsl_ids)]
    for thread in pulls:
        thread.start()
    ports.put(("osc", server.server_address[1]))
    stop.wait()
    time.sleep(0.5)
    for thread in pulls:
        thread.join(10)
    counts.put(dict(got))
    server.shutdown()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=600.0)
    parser.add_argument("--take-seconds", type=float, default=20.0)
    parser.add_argument("--rom-seconds", type=float, default=30.0,
                        help="the range of motion the labelling model is trained on (another take of the subject)")
    parser.add_argument("--fast", action="store_true", help="as fast as frames are handled, not at the take's rate")
    parser.add_argument("--labelled", action="store_true", help="replay the labelled markers: no label, no fill")
    parser.add_argument("--smoothing", type=float, default=None,
                        help="the live solve's pull towards the predicted angles (default the solver's; 0: none)")
    parser.add_argument("--keep-swaps", action="store_true",
                        help="solve the labels as given (default: labels the solved hand finds swapped are exchanged)")
    a = parser.parse_args()

    from handcap.core.markers import MarkerSequence
    from handcap.hand import OpenHand
    from handcap.hand.anatomy import JOINT_NAMES, PHI_NAMES, TIP_NAMES
    from handcap.labeling import LabelingModel
    from handcap.layouts import load_layout
    from handcap.stream import LslOutput, OscOutput, WebSocketOutput, stream
    from handcap.synth.scene import SynthConfig, synthesize

    rate = 120.0
    layout = load_layout("joints-19")
    capture = synthesize(SynthConfig(layout=layout.name, motion="random", frames=int(a.take_seconds * rate),
                                     rate=rate, seed=4, subject_seed=3), progress=False)
    loops = int(np.ceil(a.seconds / a.take_seconds))
    count = int(a.seconds * rate)
    if a.labelled:
        names = list(capture.attachment.marker_names)
        one = capture.markers.select(names)
        source = MarkerSequence(np.tile(one.positions, (loops, 1, 1))[:count], tuple(names), rate)
        labeling = fill = None
    else:
        points = capture.points.padded()
        source = MarkerSequence(np.tile(points, (loops, 1, 1))[:count],
                                tuple(f"p{k}" for k in range(points.shape[1])), rate)  # names unused: unlabelled
        rom = synthesize(SynthConfig(layout=layout.name, motion="random", frames=int(a.rom_seconds * rate), rate=rate,
                                     seed=11, subject_seed=3), progress=False)
        labeling = LabelingModel.train(rom.markers, layout.names, layout.rigid)
        fill = layout.name
    truth = np.tile(capture.hand_motion.joints, (loops, 1, 1))[:count]

    ws = WebSocketOutput("0")
    lsl = LslOutput("handcap-bench", rate, JOINT_NAMES + TIP_NAMES, PHI_NAMES)
    context = multiprocessing.get_context("spawn")
    ports, counts, stop = context.Queue(), context.Queue(), context.Event()
    process = context.Process(target=receivers, args=(ws.port, lsl.source_ids, ports, counts, stop), daemon=True)
    process.start()
    ready = dict(ports.get(timeout=60) for _ in range(1 + len(lsl.source_ids)))
    osc = OscOutput(f"127.0.0.1:{ready['osc']}")
    while not ws.clients:
        time.sleep(0.01)
    what = "labelled markers" if a.labelled else "unlabelled points: label + fill + solve"
    print(f"{len(layout.names)} markers ({len(layout.rigid)} on the back of the hand), {what} ({source.n_frames} "
          f"frames at {rate:g} Hz = {a.seconds:g} s, a {a.take_seconds:g} s take looped), "
          f"{'as fast as handled' if a.fast else 'at the take rate'}"
          f"{'' if a.smoothing is None else f', smoothing {a.smoothing:g}'}{', swaps kept' if a.keep_swaps else ''}")
    start = time.perf_counter()
    stats = stream(source, capture.attachment, OpenHand(capture.hand_motion.side), [osc, lsl, ws],
                   realtime=not a.fast, labeling=labeling, fill=fill, mend_swaps=not a.keep_swaps,
                   **({} if a.smoothing is None else {"smoothing": a.smoothing}))
    wall = time.perf_counter() - start
    stop.set()
    got = counts.get(timeout=60)
    ws.close()
    lsl.close()
    process.join(10)
    lat = stats.latency_ms
    first, last = stats.memory_mb
    error = np.linalg.norm(stats.solved - truth, axis=-1) * 1000
    print(f"  latency per frame   p50 {np.percentile(lat, 50):.2f}  p99 {np.percentile(lat, 99):.2f}  p99.9 "
          f"{np.percentile(lat, 99.9):.2f}  worst {lat.max():.2f} ms (goal p99 < 5 ms); "
          f"{stats.frames / wall:.0f} frames/s")
    for stage, ms in stats.stage_ms.items():
        print(f"    {stage:<8}          p50 {np.percentile(ms, 50):.2f}  p99 {np.percentile(ms, 99):.2f} ms")
    print(f"  markers per frame   {stats.seen.mean():.1f} labelled, {stats.filled.mean():.1f} filled")
    print(f"  memory              {first:.1f} MiB after the first minute, {last:.1f} MiB at the end "
          f"({100 * (last - first) / first:+.2f} %; goal < 5 %)")
    print(f"  received            OSC {got['osc']} / {stats.frames}, WebSocket {got['ws']} / {stats.frames}, LSL "
          f"{' and '.join(str(c) for c in got['lsl'])} / {stats.frames}")
    print(f"  joints vs truth     median {np.nanmedian(error):.2f} mm, p99 {np.nanpercentile(error, 99):.2f} mm")
    for line in stats.warnings:
        print(f"  warning             {line[:300]}{'...' if len(line) > 300 else ''}")


if __name__ == "__main__":
    main()
