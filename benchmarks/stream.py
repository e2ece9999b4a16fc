"""Live streaming (issue 19): a labelled take replayed as a live stream, solved frame by frame and sent over
OSC and WebSocket to loopback receivers, each measured in this run.

A synthetic take (layout ``joints-19``, 120 Hz, ``--take-seconds`` long, default 20 s) is replayed in a loop
for ``--seconds`` (default 600: ten minutes) as fast as it is solved (``--realtime`` for the take's rate).
The receivers (an OSC server and a WebSocket client) run in a process of their own. Printed: frames, latency
per frame (p50, p99, worst; from a frame's arrival to its sending; goal p99 < 5 ms), the process's resident
memory after the first minute and at the end (goal: growth < 5 %), messages the receivers got, and the
streamed joints against the synthetic truth.

    .venv/bin/python benchmarks/stream.py [--seconds 600] [--take-seconds 20] [--realtime]
"""

from __future__ import annotations

import argparse
import multiprocessing
import threading
import time

import numpy as np


def receivers(ws_port, ports, counts, stop) -> None:
    """The loopback receivers, in a process of their own: an OSC server (its port sent on ``ports``) and a
    WebSocket client; their message counts go to ``counts`` once ``stop`` is set."""
    from pythonosc.dispatcher import Dispatcher
    from pythonosc.osc_server import ThreadingOSCUDPServer
    from websockets.sync.client import connect

    got = {"osc": 0, "ws": 0}
    dispatcher = Dispatcher()
    dispatcher.map("/handcap/joints", lambda *_: got.__setitem__("osc", got["osc"] + 1))
    server = ThreadingOSCUDPServer(("127.0.0.1", 0), dispatcher)
    threading.Thread(target=server.serve_forever, daemon=True).start()

    def receive():
        with connect(f"ws://127.0.0.1:{ws_port}") as client:
            for _ in client:
                got["ws"] += 1

    threading.Thread(target=receive, daemon=True).start()
    ports.put(server.server_address[1])
    stop.wait()
    time.sleep(0.5)
    counts.put(dict(got))
    server.shutdown()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=600.0)
    parser.add_argument("--take-seconds", type=float, default=20.0)
    parser.add_argument("--realtime", action="store_true")
    a = parser.parse_args()

    from handcap.core.markers import MarkerSequence
    from handcap.hand import OpenHand
    from handcap.stream import OscOutput, WebSocketOutput, stream
    from handcap.synth.scene import SynthConfig, synthesize

    rate = 120.0
    capture = synthesize(SynthConfig(layout="joints-19", motion="random", frames=int(a.take_seconds * rate),
                                     rate=rate, seed=4, dropout=0.0, swap_rate=0.0, ghost_rate=0.0), progress=False)
    names = list(capture.hand_motion.marker_names)
    one = capture.markers.select(names).positions
    loops = int(np.ceil(a.seconds / a.take_seconds))
    markers = MarkerSequence(np.tile(one, (loops, 1, 1))[:int(a.seconds * rate)], tuple(names), rate)
    truth = np.tile(capture.hand_motion.joints, (loops, 1, 1))[:markers.n_frames]

    ws = WebSocketOutput("0")
    context = multiprocessing.get_context("spawn")
    ports, counts, stop = context.Queue(), context.Queue(), context.Event()
    process = context.Process(target=receivers, args=(ws.port, ports, counts, stop), daemon=True)
    process.start()
    osc = OscOutput(f"127.0.0.1:{ports.get(timeout=60)}")
    while not ws.clients:
        time.sleep(0.01)
    print(f"{len(names)} markers ({markers.n_frames} frames at {rate:g} Hz = {a.seconds:g} s, a "
          f"{a.take_seconds:g} s take looped), {'at the take rate' if a.realtime else 'as fast as solved'}")
    start = time.perf_counter()
    stats = stream(markers, capture.attachment, OpenHand(capture.hand_motion.side), [osc, ws],
                   realtime=a.realtime)
    wall = time.perf_counter() - start
    stop.set()
    got = counts.get(timeout=60)
    ws.close()
    process.join(10)
    lat = stats.latency_ms
    first, last = stats.memory_mb
    error = np.linalg.norm(stats.solved - truth, axis=-1) * 1000
    print(f"  latency per frame   p50 {np.percentile(lat, 50):.2f}  p99 {np.percentile(lat, 99):.2f}  worst "
          f"{lat.max():.2f} ms (goal p99 < 5 ms); {stats.frames / wall:.0f} frames/s")
    print(f"  memory              {first:.1f} MiB after the first minute, {last:.1f} MiB at the end "
          f"({100 * (last - first) / first:+.2f} %; goal < 5 %)")
    print(f"  received            OSC {got['osc']} / {stats.frames}, WebSocket {got['ws']} / {stats.frames}")
    print(f"  joints vs truth     median {np.nanmedian(error):.2f} mm, p99 {np.nanpercentile(error, 99):.2f} mm")


if __name__ == "__main__":
    main()
