"""Live streams over loopback: every frame reaches a fake OSC server, a WebSocket client and LSL inlets built on
the same protocol libraries; the streamed joints agree with the batch solver and the truth, from labelled
markers and from unlabelled points labelled and filled frame by frame; and the benchmark's 5 s version runs
(its timings are printed, not asserted)."""

import json
import re
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest

from handcap.cli import main
from handcap.hand import OpenHand
from handcap.labeling import LabelingModel
from handcap.layouts import load_layout
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


def test_a_replayed_frame_taken_late_counts_its_wait():
    # A replay at 100 Hz whose reader is held up 0.2 s after frame 2: frames 3-22 are taken late, as a live system's
    # queue would hand them on, and each is stamped with its own time in the take, so the wait counts as latency.
    from handcap.stream.sources import ReplaySource

    stamps, taken = [], []
    for t, (arrived, _) in enumerate(ReplaySource(np.zeros((30, 1, 3)), 100.0)):
        stamps.append(arrived)
        taken.append(time.perf_counter())
        if t == 2:
            time.sleep(0.2)
    stamps, taken = np.array(stamps) - stamps[0], np.array(taken) - stamps[0]
    assert np.allclose(stamps, np.arange(30) / 100.0)
    assert taken[3] > 0.2 > stamps[3] + 0.15  # taken 0.2 s after it arrived
    fast = [arrived for arrived, _ in ReplaySource(np.zeros((3, 1, 3)), 100.0, realtime=False)]
    assert fast[-1] - fast[0] < 0.01  # as fast as taken: stamped when taken


def test_streamed_joints_agree_with_the_batch_solver_and_the_truth(capture):
    stats = stream(capture.markers, capture.attachment, OpenHand("right"), realtime=False)
    batch = solve_hand(capture.markers, capture.attachment, OpenHand("right")).joints
    assert np.median(np.linalg.norm(stats.solved - batch, axis=-1)) < 0.001
    assert np.median(np.linalg.norm(stats.solved - capture.hand_motion.joints, axis=-1)) < 0.002


def test_an_implausible_fit_and_a_lost_hand_are_warnings_of_the_stream(capture):
    """The live solve says what handcap solve says of a take: a mean marker error above 5 mm (here a hand 30 %
    larger than its attachment's), and frames with too few markers to place the hand."""
    from handcap import MarkerSequence

    hand = OpenHand("right")
    markers = capture.markers
    assert stream(markers, capture.attachment, hand, realtime=False).warnings == ()
    centre = np.nanmean(markers.positions, axis=1, keepdims=True)
    larger = MarkerSequence(centre + 1.3 * (markers.positions - centre), markers.names, markers.rate)
    said = stream(larger, capture.attachment, hand, realtime=False).warnings
    mre = [float(m) for w in said for m in re.findall(r"live solve MRE ([0-9.]+) mm is above 5 mm", w)]
    assert len(mre) == 1 and mre[0] > 8.0, said  # measured 12.3 mm
    few = markers.positions.copy()
    few[100:200, 2:] = np.nan
    said = stream(MarkerSequence(few, markers.names, markers.rate), capture.attachment, hand, realtime=False).warnings
    assert any("hand frame is lost in 100 of 240 frames" in w for w in said), said


def test_stream_verb_and_bad_inputs(capture, tmp_path, capsys):
    write_capture(capture, tmp_path)
    capture.attachment.save(tmp_path / "attachment.npz")
    argv = ["stream", "--replay", str(tmp_path / "markers.c3d"), "--attachment", str(tmp_path / "attachment.npz"),
            "--fast", "--seconds", "0.5"]
    assert main(argv) == 0
    assert "60 frames, latency p50" in capsys.readouterr().out
    for extra, message in ((["--osc", "nowhere"], "give PORT or HOST:PORT"), (["--osc", "1:99999"], "1-65535"),
                           (["--smoothing", "-1"], "smoothing must be 0 or more")):
        assert main([*argv, *extra]) == 2
        err = capsys.readouterr().err
        assert message in err and len(err.strip().splitlines()) == 1, err


def test_the_benchmarks_short_version_runs():
    run = subprocess.run([sys.executable, str(ROOT / "benchmarks" / "stream.py"), "--seconds", "2",
                          "--take-seconds", "5", "--rom-seconds", "5"], capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stderr[-2000:]
    assert "label + fill + solve" in run.stdout
    assert "received            OSC 240 / 240, WebSocket 240 / 240, LSL 240 and 240 / 240" in run.stdout
    assert "latency per frame" in run.stdout and "memory" in run.stdout
    for stage in ("label", "fill", "solve", "send"):
        assert re.search(rf"^    {stage} +p50", run.stdout, re.M), run.stdout
    median = float(re.search(r"joints vs truth +median ([0-9.]+) mm", run.stdout).group(1))
    assert median < 2.0, run.stdout  # labelled, filled and solved one frame at a time


@pytest.fixture(scope="module")
def unlabelled():
    """A take's unlabelled points (dropouts, ghosts, swaps as synth makes them) and a labelling model trained on
    another take of the same subject."""
    layout = load_layout("joints-19")
    rom = synthesize(SynthConfig(layout=layout.name, motion="random", frames=1200, rate=120.0, seed=11,
                                 subject_seed=3), progress=False)
    take = synthesize(SynthConfig(layout=layout.name, motion="random", frames=600, rate=120.0, seed=4,
                                  subject_seed=3), progress=False)
    return take, LabelingModel.train(rom.markers, layout.names, layout.rigid)


def test_unlabelled_points_are_labelled_filled_and_solved_frame_by_frame(unlabelled):
    take, model = unlabelled
    hand = OpenHand("right")
    stats = stream(take.points, take.attachment, hand, realtime=False, labeling=model, fill="joints-19")
    assert set(stats.stage_ms) == {"label", "fill", "solve", "send"}
    error = np.linalg.norm(stats.solved - take.hand_motion.joints, axis=-1)
    assert np.nanmedian(error) < 0.0015  # as good as from the labelled markers, about 0.4 mm
    labelled = stream(take.markers, take.attachment, hand, realtime=False)
    assert abs(np.nanmedian(error) - np.nanmedian(np.linalg.norm(labelled.solved - take.hand_motion.joints,
                                                                 axis=-1))) < 0.0005
    visible = np.isfinite(take.markers.select(take.attachment.marker_names).positions).all(axis=-1).sum(axis=1)
    assert stats.seen.mean() > 0.95 * visible.mean()  # nearly every measured marker got its label
    # every hidden marker the occlusion model knows was predicted (the 3 on the back of the hand it does not)
    assert stats.filled.sum() > 0 and (stats.seen + stats.filled >= 19).mean() > 0.95


def test_labels_the_labeller_released_are_a_warning_of_the_stream(unlabelled, monkeypatch):
    """A release says the labels were probably swapped before it (:mod:`handcap.labeling.release`)."""
    import functools

    import handcap.stream.pipeline as pipeline_module
    from handcap.core.errors import HandcapWarning
    from handcap.labeling import OnlineLabeler

    take, model = unlabelled
    hand = OpenHand("right")
    assert not any("released" in w for w in stream(take.points, take.attachment, hand, realtime=False,
                                                   labeling=model, seconds=2.0).warnings)
    # A low threshold releases labels on this ordinary take.
    monkeypatch.setattr(pipeline_module, "OnlineLabeler", functools.partial(OnlineLabeler, release=30.0))
    with pytest.warns(HandcapWarning, match="labels released to the spatial model"):
        stats = stream(take.points, take.attachment, hand, realtime=False, labeling=model, seconds=2.0)
    assert sum("labels released to the spatial model" in w for w in stats.warnings) == 1


def test_a_model_of_another_subject_is_a_warning_of_the_stream(unlabelled):
    """Labels streamed with another subject's model are said doubtful at the end, as label_take says them: the rigid
    set re-learned, the hand frame often lost, few points labelled (before, only the releases were said)."""
    from handcap.core.errors import HandcapWarning

    take, model = unlabelled
    hand = OpenHand("right")
    plausibility = ("rigid markers' distances", "hand frame lost", "labelled in", "labels for")
    same = stream(take.points, take.attachment, hand, realtime=False, labeling=model, seconds=3.0)
    assert not any(p in w for w in same.warnings for p in plausibility)
    layout = load_layout("joints-19")
    rom = synthesize(SynthConfig(layout=layout.name, motion="random", frames=600, rate=120.0, seed=11,
                                 subject_seed=43), progress=False)
    other = LabelingModel.train(rom.markers, layout.names, layout.rigid)
    with pytest.warns(HandcapWarning, match="rigid markers' distances in this take differ from training"):
        stats = stream(take.points, take.attachment, hand, realtime=False, labeling=other, seconds=3.0)
    said = " | ".join(stats.warnings)
    assert "rigid markers' distances" in said and "labels for" in said, said
    share = float(re.search(r"labels for ([0-9.]+) % of the points", said).group(1))
    assert share < 95.0


def test_a_hidden_marker_is_filled_near_where_it_is(unlabelled):
    take, _ = unlabelled
    from handcap.stream import LivePipeline

    names = list(take.attachment.marker_names)
    truth = take.truth["positions"][:, [list(take.hand_motion.marker_names).index(n) for n in names]]
    pipeline = LivePipeline(take.attachment, OpenHand("right"), rate=120.0, fill="joints-19")
    tip = names.index("index_tip")
    errors = []
    for t in range(len(truth)):
        frame = truth[t].copy()
        if t >= 300 and t % 60 < 30:  # a quarter of a second hidden, twice a second
            frame[tip] = np.nan
        live = pipeline.frame(frame)
        if np.isnan(frame[tip]).any():
            errors.append(np.linalg.norm(live.markers[tip] - truth[t, tip]))
            assert live.filled >= 1
    assert np.median(errors) < 0.01  # the autoencoder from the other markers: within a centimetre


def test_lsl_outlets_reach_an_inlet():
    pylsl = pytest.importorskip("pylsl", reason="the extra 'stream' (pylsl)")
    from handcap.hand.anatomy import JOINT_NAMES, PHI_NAMES, TIP_NAMES
    from handcap.stream import LslOutput

    out = LslOutput("handcap-test", 120.0, JOINT_NAMES + TIP_NAMES, PHI_NAMES)
    inlets = []
    for source_id in out.source_ids:
        found = pylsl.resolve_byprop("source_id", source_id, timeout=10)
        assert found, f"no LSL stream {source_id} on this machine"
        inlet = pylsl.StreamInlet(found[0])
        inlet.open_stream(timeout=10)
        inlets.append(inlet)
    info = inlets[0].info(timeout=10)
    assert info.channel_count() == 63 and info.nominal_srate() == 120.0
    assert info.desc().child("channels").child("channel").child_value("label") == "wrist_x"
    time.sleep(0.5)
    joints = np.arange(63, dtype=float).reshape(21, 3) / 100
    for frame in range(50):
        out(frame, frame / 120.0, joints + frame, np.full(27, frame / 10))
    samples = [[], []]
    deadline = time.monotonic() + 10
    while (len(samples[0]) < 50 or len(samples[1]) < 50) and time.monotonic() < deadline:
        for k, inlet in enumerate(inlets):
            chunk, _ = inlet.pull_chunk(timeout=0.2)
            samples[k] += chunk
    out.close()
    assert len(samples[0]) == len(samples[1]) == 50
    np.testing.assert_allclose(np.array(samples[0][7]).reshape(21, 3), joints + 7, atol=1e-5)  # float32
    np.testing.assert_allclose(samples[1][49], np.full(27, 4.9), atol=1e-6)


def test_qtm_labelled_trajectories_stream_live(capture, fake_qtm):
    from handcap.stream.live import stream_source
    from handcap.stream.sources import QtmSource

    names = list(capture.markers.names)
    server = fake_qtm(capture.markers.positions, ["Subject:" + n for n in names], 120.0)
    source = QtmSource(f"127.0.0.1:{server.port}")
    try:
        assert source.rate == 120.0 and source.names[0] == "Subject:" + names[0]
        stats = stream_source(source, capture.attachment, OpenHand("right"))
    finally:
        source.close()
    assert stats.frames == 240 and "streamframes allframes 3d" in server.commands
    replay = stream(capture.markers, capture.attachment, OpenHand("right"), realtime=False)
    np.testing.assert_allclose(stats.solved, replay.solved, atol=1e-4)  # float32 millimetres on the wire
    assert (stats.latency_ms > 0).all()


def test_qtm_unlabelled_points_are_labelled_live(unlabelled, fake_qtm):
    from handcap.stream.live import stream_source
    from handcap.stream.sources import QtmSource

    take, model = unlabelled
    kept = np.r_[0:120, 123:240]  # QTM skips three frames: the labeler steps over them
    server = fake_qtm(take.points.padded()[kept], [], 120.0, numbers=kept)
    source = QtmSource(f"127.0.0.1:{server.port}", labelled=False)
    try:
        stats = stream_source(source, take.attachment, OpenHand("right"), labeling=model, fill="joints-19")
    finally:
        source.close()
    assert stats.frames == 237 and "streamframes allframes 3dnolabels" in server.commands
    assert any(w.startswith("QTM: 3 frame(s) skipped") for w in stats.warnings)
    error = np.linalg.norm(stats.solved - take.hand_motion.joints[kept], axis=-1)
    assert np.nanmedian(error) < 0.0015 and np.nanmedian(error[120:]) < 0.0015


def test_frames_qtm_skipped_are_stepped_over_and_said(capture, fake_qtm):
    """QTM's real-time output falls behind under heavy processing and skips frame numbers: the stages step over
    each skipped frame as one of no marker (the filters and the solve keep time), nothing is sent for it, and the
    stream's end says how many. Numbers that do not rise are said too."""
    from handcap.stream.live import stream_source
    from handcap.stream.sources import QtmSource

    names = ["Subject:" + n for n in capture.markers.names]
    kept = np.r_[0:100, 105:240]  # frames 100-104 never sent
    server = fake_qtm(capture.markers.positions[kept], names, 120.0, numbers=kept)
    source = QtmSource(f"127.0.0.1:{server.port}")
    sent = []
    try:
        stats = stream_source(source, capture.attachment, OpenHand("right"), outputs=[lambda t, *_: sent.append(t)])
    finally:
        source.close()
    assert stats.frames == 235 and sent == kept.tolist()  # sent under their own frame numbers
    assert [w for w in stats.warnings if w.startswith("QTM:")] == [stats.warnings[0]]
    assert stats.warnings[0].startswith("QTM: 5 frame(s) skipped")
    replay = stream(capture.markers, capture.attachment, OpenHand("right"), realtime=False)
    error = np.linalg.norm(stats.solved - replay.solved[kept], axis=-1)
    assert np.nanmax(error[100:]) < 0.002  # the solve goes on as if the frames had come without markers
    stuck = fake_qtm(capture.markers.positions[:60], names, 120.0, numbers=np.ones(60, int))
    source = QtmSource(f"127.0.0.1:{stuck.port}")
    try:
        stats = stream_source(source, capture.attachment, OpenHand("right"))
    finally:
        source.close()
    assert stats.frames == 60 and any("59 frame(s) came with a number not after" in w for w in stats.warnings)


def test_stream_verb_from_qtm_and_its_bad_addresses(capture, fake_qtm, tmp_path, capsys):
    server = fake_qtm(capture.markers.positions[:60], capture.markers.names, 120.0)
    capture.attachment.save(tmp_path / "attachment.npz")
    assert main(["stream", "--qtm", f"127.0.0.1:{server.port}", "--attachment", str(tmp_path / "attachment.npz"),
                 "--seconds", "0.25"]) == 0
    assert f"127.0.0.1:{server.port}: 30 frames, latency p50" in capsys.readouterr().out
    closed = server.port
    server.close()
    for address, message in ((f"127.0.0.1:{closed}", "QTM did not answer"), ("127.0.0.1:http", "HOST:PORT")):
        assert main(["stream", "--qtm", address, "--attachment", str(tmp_path / "attachment.npz")]) == 2
        err = capsys.readouterr().err
        assert message in err and len(err.strip().splitlines()) == 1, err


def test_the_live_labeler_steps_the_streams_frame_time(unlabelled):
    # The model was trained at 120 Hz; a stream of 60 Hz is labelled with filters stepping 1/60 s.
    take, model = unlabelled
    from handcap.stream import LivePipeline

    assert LivePipeline(take.attachment, OpenHand("right"), rate=60.0, labeling=model).labeler.model.kalman.dt == (
        1 / 60)
    assert LivePipeline(take.attachment, OpenHand("right"), rate=120.0, labeling=model).labeler.model is model


def test_a_stream_with_an_objects_markers_names_the_rigid_body_at_its_end():
    # A glove-13 grasp of a cylinder streamed with the hand's labelling model only: the cylinder's markers are left
    # without labels, and the stream's end names them as a rigid body (an object not given).
    layout = load_layout("glove-13")
    rom = synthesize(SynthConfig(layout="glove-13", motion="random", frames=1200, seed=11, subject_seed=5),
                     progress=False)
    grasp = synthesize(SynthConfig(layout="glove-13", motion="grasp", frames=600, seed=12, subject_seed=5),
                       progress=False)
    model = LabelingModel.train(rom.labeled_points(layout.names), layout.names, layout.rigid)
    stats = stream(grasp.points, grasp.attachment, OpenHand("right"), realtime=False, labeling=model)
    named = [w for w in stats.warnings if "keep their distances, as a rigid body's markers do" in w]
    assert len(named) == 1 and "label the take offline" in named[0]
    assert int(named[0].split(" of the points")[0]) >= 3
