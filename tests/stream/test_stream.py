"""Live streams over loopback: every frame reaches a fake OSC server and a WebSocket client built on the same
protocol libraries, the streamed joints agree with the batch solver and the truth, and the benchmark's 20 s
version runs (its timings are printed, not asserted)."""

import json
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from handcap.cli import main
from handcap.hand import OpenHand
from handcap.solve import solve_hand
from handcap.synth.scene import SynthConfig, synthesize, write_capture

pytest.importorskip("pythonosc", reason="the extra 'stream' (python-osc, websockets)")
from pythonosc.dispatcher import Dispatcher  # noqa: E402
from pythonosc.osc_server import ThreadingOSCUDPServer  # noqa: E402
from websockets.sync.client import connect  # noqa: E402

from handcap.stream import OscOutput, WebSocketOutput, stream  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def capture():
    return synthesize(SynthConfig(layout="joints-19", motion="random", frames=240, rate=120.0, seed=8, dropout=0.0,
                                  swap_rate=0.0, ghost_rate=0.0), progress=False)


def test_every_frame_reaches_osc_and_websocket(capture):
    received, texts = [], []
    dispatcher = Dispatcher()
    dispatcher.map("/handcap/joints", lambda address, *values: received.append(values))
    server = ThreadingOSCUDPServer(("127.0.0.1", 0), dispatcher)
    threading.Thread(target=server.serve_forever, daemon=True).start()
    ws = WebSocketOutput("0")

    def client():
        with connect(f"ws://127.0.0.1:{ws.port}") as link:
            for message in link:
                texts.append(message)

    threading.Thread(target=client, daemon=True).start()
    deadline = time.monotonic() + 10
    while not ws.clients and time.monotonic() < deadline:
        time.sleep(0.01)
    # at the take's rate, as live: unpaced, UDP datagrams overflow a receiver that shares this interpreter
    stats = stream(capture.markers, capture.attachment, OpenHand("right"),
                   [OscOutput(f"127.0.0.1:{server.server_address[1]}"), ws], realtime=True)
    deadline = time.monotonic() + 10
    while (len(received) < stats.frames or len(texts) < stats.frames) and time.monotonic() < deadline:
        time.sleep(0.02)
    ws.close()
    server.shutdown()
    assert len(received) == len(texts) == stats.frames == 240
    frames = sorted(int(v[0]) for v in received)
    assert frames == list(range(240))
    by_frame = {int(v[0]): np.array(v[2:]).reshape(21, 3) for v in received}
    assert np.allclose(by_frame[100], stats.solved[100], atol=1e-5)  # OSC sends float32
    last = json.loads(texts[-1])
    assert last["frame"] == 239 and np.allclose(last["joints"], stats.solved[239], atol=1e-6)
    assert stats.latency_ms.shape == (240,) and (stats.latency_ms > 0).all()


def test_streamed_joints_agree_with_the_batch_solver_and_the_truth(capture):
    stats = stream(capture.markers, capture.attachment, OpenHand("right"), realtime=False)
    batch = solve_hand(capture.markers, capture.attachment, OpenHand("right")).joints
    assert np.median(np.linalg.norm(stats.solved - batch, axis=-1)) < 0.001
    assert np.median(np.linalg.norm(stats.solved - capture.hand_motion.joints, axis=-1)) < 0.002


def test_stream_verb_and_bad_inputs(capture, tmp_path, capsys):
    write_capture(capture, tmp_path)
    capture.attachment.save(tmp_path / "attachment.npz")
    argv = ["stream", "--replay", str(tmp_path / "markers.c3d"), "--attachment", str(tmp_path / "attachment.npz"),
            "--fast", "--seconds", "0.5"]
    assert main(argv) == 0
    assert "60 frames, latency p50" in capsys.readouterr().out
    for extra, message in ((["--osc", "nowhere"], "give PORT or HOST:PORT"), (["--osc", "1:99999"], "1-65535")):
        assert main([*argv, *extra]) == 2
        err = capsys.readouterr().err
        assert message in err and len(err.strip().splitlines()) == 1, err


def test_the_benchmarks_20_second_version_runs():
    run = subprocess.run([sys.executable, str(ROOT / "benchmarks" / "stream.py"), "--seconds", "20",
                          "--take-seconds", "5"], capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stderr[-2000:]
    assert "received            OSC 2400 / 2400, WebSocket 2400 / 2400" in run.stdout
    assert "latency per frame" in run.stdout and "memory" in run.stdout
