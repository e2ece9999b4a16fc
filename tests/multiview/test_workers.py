"""How triangulate_detections chooses its workers, and that it runs from a script without a __main__ guard."""

import subprocess
import sys
import textwrap

import numpy as np
import pytest

import handcap.multiview.reconstruct as reconstruct
from handcap.multiview import read_detections, triangulate_detections
from handcap.synth.scene import SynthConfig, synthesize, write_capture


@pytest.fixture(scope="module")
def take(tmp_path_factory):
    folder = tmp_path_factory.mktemp("take")
    capture = synthesize(SynthConfig(layout="glove-13", motion="calibration", frames=30, cameras=6, seed=1,
                                     outlier_rate=0.02), progress=False)
    write_capture(capture, folder)
    return folder, read_detections(folder / "detections.npz"), capture.rig


def same(a, b):
    return all(np.array_equal(getattr(a, k), getattr(b, k), equal_nan=True)
               for k in ("positions", "error_px", "views", "residual", "used"))


@pytest.mark.parametrize("serial, cores, expected", [
    (0.5, 2, 1), (7.9, 2, 1), (8.1, 2, 2), (4.0, 16, 1), (4.5, 16, 16), (1000.0, 1, 1),
])
def test_pool_only_when_the_work_pays_for_starting_it(serial, cores, expected, monkeypatch):
    monkeypatch.setattr(reconstruct, "POOL_START_SECONDS", 4.0)
    assert reconstruct.pool_workers(serial, cores) == expected
    # The rule: serial / W + start < serial, checked against the formula directly.
    assert (expected > 1) == (cores > 1 and serial / cores + 4.0 < serial)


def test_small_take_stays_in_this_process(take, monkeypatch):
    _, detections, rig = take
    assert len(detections) < reconstruct.PROBE_DETECTIONS
    reference = triangulate_detections(detections, rig, workers=1, chunk_frames=7)
    calls = []
    monkeypatch.setattr(reconstruct, "map_chunks", lambda *a, **k: calls.append(k) or [])
    result = triangulate_detections(detections, rig)
    assert calls == []  # all of it was the timed first block
    assert same(result, reference)


@pytest.mark.parametrize("start_seconds, pooled", [(0.0, True), (1e9, False)])
def test_larger_take_is_timed_then_split(take, monkeypatch, start_seconds, pooled):
    _, detections, rig = take
    monkeypatch.setattr(reconstruct, "PROBE_DETECTIONS", len(detections) // 5)
    monkeypatch.setattr(reconstruct, "POOL_START_SECONDS", start_seconds)
    monkeypatch.setattr(reconstruct, "idle_workers", lambda: 2)  # as on an idle 2-core machine
    real_map = reconstruct.map_chunks
    seen = {}

    def spy(func, chunks, **options):
        seen.update(options, first=chunks[0].start)
        return real_map(func, chunks, **options)

    monkeypatch.setattr(reconstruct, "map_chunks", spy)
    result = triangulate_detections(detections, rig)
    assert 0 < seen["first"] < detections.n_frames  # the probe took the first frames
    assert (seen["workers"] > 1) == pooled
    assert same(result, triangulate_detections(detections, rig, workers=1))


@pytest.mark.parametrize("workers", ["None", "2"])
def test_runs_from_a_plain_script_without_main_guard(take, tmp_path, workers):
    folder, detections, rig = take
    script = tmp_path / "plain.py"
    script.write_text(textwrap.dedent(f"""\
        import numpy as np
        from handcap.io.camera_formats import read_rig
        from handcap.multiview import read_detections, triangulate_detections
        result = triangulate_detections(read_detections({str(folder / 'detections.npz')!r}),
                                        read_rig({str(folder / 'cameras.toml')!r}), workers={workers},
                                        chunk_frames=None if {workers} is None else 10)
        np.save({str(tmp_path / 'positions.npy')!r}, result.positions)
        print("done")
        """))
    run = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, timeout=300,
                         cwd=tmp_path)
    assert run.returncode == 0, run.stderr[-2000:]
    assert "BrokenProcessPool" not in run.stderr and run.stdout.count("done") == 1  # the script ran once
    np.testing.assert_array_equal(np.load(tmp_path / "positions.npy"),
                                  triangulate_detections(detections, rig, workers=1).positions)
