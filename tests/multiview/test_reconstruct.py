"""From 2D detections to 3D markers on a synthetic dense-patches capture with known truth."""

import hashlib
from dataclasses import replace

import numpy as np
import pytest

from handcap import HandcapError
from handcap.cli import main
from handcap.core.cameras import CameraRig
from handcap.io import read_markers
from handcap.multiview import (Detections, merge_detections, quality_path, read_detections, triangulate_detections,
                               write_detections)
from handcap.synth.scene import SynthConfig, synthesize, write_capture


@pytest.fixture(scope="module")
def capture():
    # 12 cameras, 0.5 px noise, 2 % wrong-id detections, occlusion ray-cast against the hand.
    return synthesize(SynthConfig(layout="dense-patches", motion="random", frames=40, cameras=12, pixel_noise=0.5,
                                  outlier_rate=0.02, seed=3), progress=False)


@pytest.fixture(scope="module")
def detections(capture):
    d = capture.detections
    return Detections(d["camera_names"], d["marker_names"], d["frame"], d["camera"], d["marker"], d["xy"],
                      d["score"], d["rate"], None, source="synth")


@pytest.fixture(scope="module")
def result(detections, capture):
    return triangulate_detections(detections, capture.rig, workers=1)


def test_accuracy_against_the_truth(capture, result):
    error = np.linalg.norm(result.positions - capture.truth["positions"], axis=-1)
    found = ~np.isnan(error)
    assert found.mean() > 0.7  # the rest is hidden from all but one or two cameras
    assert np.median(error[found]) <= 0.0005 and np.percentile(error[found], 95) <= 0.0015
    assert np.nanmean(result.error_px) <= 0.7
    assert (result.views[found] >= 3).all() and (result.views[~found] == 0).all()
    # The metric residual is pixel error x depth / focal: about 0.5 px x 1.4 m / 1800 px.
    assert 0.1e-3 < np.nanmedian(result.residual) < 1e-3


def test_wrong_ids_are_rejected_and_true_views_kept(capture, detections, result):
    wrong = capture.detections["wrong_id"]
    assert wrong.sum() > 1000
    assert (~result.used[wrong]).mean() >= 0.99
    point = detections.frame * len(detections.marker_names) + detections.marker
    found = ~np.isnan(result.positions.reshape(-1, 3)[point, 0])
    assert result.used[~wrong & found].mean() > 0.999
    # A wrong id often lands on a marker the camera also sees: two detections of one id. The true one wins.
    key = (point * 100 + detections.camera)
    _, inverse, counts = np.unique(key, return_inverse=True, return_counts=True)
    twice = counts[inverse] > 1
    assert (twice & wrong).sum() > 100
    assert result.used[twice & ~wrong & found].mean() > 0.99
    assert (~result.used[twice & wrong]).mean() >= 0.99


def test_without_ransac_wrong_ids_would_hurt(capture, detections):
    loose = triangulate_detections(detections, capture.rig, threshold_px=1e6, workers=1)
    error = np.linalg.norm(loose.positions - capture.truth["positions"], axis=-1)
    assert np.nanpercentile(error, 95) > 0.005  # 5 mm: what the robust version avoids


def test_blocks_of_any_size_give_the_same_numbers(capture, detections, result):
    again = triangulate_detections(detections, capture.rig, chunk_frames=7, workers=1)
    for key in ("positions", "error_px", "views", "residual", "used"):
        assert np.array_equal(getattr(again, key), getattr(result, key), equal_nan=key != "used" and key != "views")


def test_process_pool_and_dask_cluster_give_identical_results(capture, detections, result):
    distributed = pytest.importorskip("distributed")
    pooled = triangulate_detections(detections, capture.rig, chunk_frames=10, workers=2)
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None) as cluster:
        clustered = triangulate_detections(detections, capture.rig, chunk_frames=10,
                                           scheduler=cluster.scheduler_address)
    for other in (pooled, clustered):
        assert np.array_equal(other.positions, result.positions, equal_nan=True)
        assert np.array_equal(other.used, result.used)
        assert np.array_equal(other.views, result.views)


def test_rig_must_hold_every_camera(capture, detections):
    smaller = CameraRig([camera for camera in capture.rig if camera.name != capture.rig.names[4]])
    with pytest.raises(HandcapError, match=f"camera '{capture.rig.names[4]}' that the rig lacks"):
        triangulate_detections(detections, smaller)
    with pytest.raises(HandcapError, match="min_views"):
        triangulate_detections(detections, capture.rig, min_views=1)
    with pytest.raises(HandcapError, match="threshold_px"):
        triangulate_detections(detections, capture.rig, threshold_px=-1)


def test_detections_file_round_trip_and_checks(detections, tmp_path):
    path = tmp_path / "d.npz"
    write_detections(detections, path)
    back = read_detections(path)
    assert back.camera_names == detections.camera_names and back.n_frames == detections.n_frames
    assert np.array_equal(back.xy, detections.xy) and np.array_equal(back.marker, detections.marker)
    write_detections(back, tmp_path / "e.npz")
    assert hashlib.sha256(path.read_bytes()).digest() == hashlib.sha256((tmp_path / "e.npz").read_bytes()).digest()
    arrays = dict(np.load(path))

    def broken(**changes):
        bad = dict(arrays, **changes)
        np.savez(tmp_path / "bad.npz", **bad)
        return tmp_path / "bad.npz"

    for changes, message in [({"camera": arrays["camera"] + 20}, "camera index .* outside camera_names"),
                             ({"xy": np.where(np.arange(len(arrays["xy"]))[:, None] == 5, np.nan, arrays["xy"])},
                              "xy of row 5 is not finite"),
                             ({"score": arrays["score"][:-1]}, "score must be"),
                             ({"frame": arrays["frame"][:-1]}, "one row per observation"),
                             ({"n_frames": np.array(10)}, "mismatched frame counts"),
                             ({"rate": np.array(0.0)}, "rate must be a positive")]:
        with pytest.raises(HandcapError, match=message):
            read_detections(broken(**changes))
    for pitch in (np.array(-0.005), np.array(np.nan), np.array(2.0), np.array("5 mm"), np.zeros(3)):
        with pytest.raises(HandcapError, match="pitch must be"):
            read_detections(broken(pitch=pitch))
    write_detections(replace(detections, pitch=0.005), tmp_path / "p.npz")  # the printed squares' side, metres
    assert read_detections(tmp_path / "p.npz").pitch == 0.005 and back.pitch is None
    del arrays["xy"]
    np.savez(tmp_path / "noxy.npz", **arrays)
    with pytest.raises(HandcapError, match="missing xy"):
        read_detections(tmp_path / "noxy.npz")


def test_per_camera_files_merge_into_the_whole(detections):
    parts = []
    for c, name in enumerate(detections.camera_names):
        rows = detections.camera == c
        parts.append(Detections((name,), detections.marker_names, detections.frame[rows], detections.camera[rows] * 0,
                                detections.marker[rows], detections.xy[rows], detections.score[rows], detections.rate,
                                detections.n_frames, source=f"{name}.npz"))
    merged = merge_detections(parts[::-1])
    assert sorted(merged.camera_names) == sorted(detections.camera_names) and len(merged) == len(detections)

    def as_names(d):
        return sorted(zip(d.frame.tolist(), np.array(d.camera_names)[d.camera].tolist(),
                          np.array(d.marker_names)[d.marker].tolist(), d.xy[:, 0].tolist()))

    assert as_names(merged) == as_names(detections)
    short = parts[3].select_frames(0, detections.n_frames - 5)
    with pytest.raises(HandcapError, match=f"mismatched frame counts: {parts[3].source} has {detections.n_frames - 5}"):
        merge_detections([parts[0], short])
    with pytest.raises(HandcapError, match="also appears"):
        merge_detections([parts[0], parts[0]])
    assert merge_detections([replace(parts[0], pitch=0.005), parts[1]]).pitch == 0.005
    with pytest.raises(HandcapError, match="different pitches of the printed squares: 4 mm, 5 mm"):
        merge_detections([replace(parts[0], pitch=0.005), replace(parts[1], pitch=0.004)])


@pytest.fixture(scope="module")
def capture_folder(capture, tmp_path_factory):
    folder = tmp_path_factory.mktemp("capture")
    write_capture(capture, folder)
    return folder


def _one_error_line(capsys, *needles):
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1, err
    for needle in needles:
        assert needle in err, err
    return err


def test_cli_writes_markers_and_their_quality(capture, capture_folder, result, tmp_path, capsys):
    out = tmp_path / "markers.c3d"
    before = hashlib.sha256((capture_folder / "detections.npz").read_bytes()).digest()
    assert main(["triangulate", str(capture_folder / "detections.npz"), "--cameras",
                 str(capture_folder / "cameras.toml"), "--workers", "1", "--out", str(out)]) == 0
    assert "marker-frames/s" in capsys.readouterr().out
    markers = read_markers(out)
    assert markers.names == result.names
    assert np.allclose(markers.positions, result.positions, atol=2e-5, equal_nan=True)  # C3D keeps float32 mm
    assert np.allclose(markers.residuals[~np.isnan(result.residual)], result.residual[~np.isnan(result.residual)],
                       atol=2e-5)
    with np.load(quality_path(out)) as quality:
        assert np.array_equal(quality["views"], result.views)
        assert np.array_equal(quality["error_px"], result.error_px, equal_nan=True)
        assert np.array_equal(quality["used"], result.used)
    assert hashlib.sha256((capture_folder / "detections.npz").read_bytes()).digest() == before


def test_the_printed_pitch_is_a_ruler_for_the_rigs_scale(capture, detections, tmp_path, capsys):
    # Independent of the check: the median distance of adjacent patch corners in the truth.
    names = list(detections.marker_names)
    pairs = [(i, names.index(f"{n[:n.rindex('_r')]}_r{r}c{c + 1}")) for i, n in enumerate(names)
             for r, c in [map(int, n[n.rindex("_r") + 2:].split("c"))] if f"{n[:n.rindex('_r')]}_r{r}c{c + 1}" in names]
    truth = capture.truth["positions"]
    side = np.nanmedian(np.linalg.norm(truth[:, [i for i, _ in pairs]] - truth[:, [j for _, j in pairs]], axis=-1))
    assert 0.004 < side < 0.007
    rig_file = tmp_path / "cameras.toml"
    capture.rig.save(rig_file)
    for pitch, said in ((side, False), (0.8 * side, True)):
        write_detections(replace(detections, pitch=pitch), tmp_path / "d.npz")
        assert main(["triangulate", str(tmp_path / "d.npz"), "--cameras", str(rig_file), "--workers", "1",
                     "--out", str(tmp_path / f"m{said}.npz")]) == 0
        out, err = capsys.readouterr()
        shown = float(out.split("of the printed pitch (%)")[1].split()[0])
        assert abs(shown - 100 * side / pitch) < 2.0  # rows along the patch too, and triangulation noise
        assert ("the coded patches' squares measure" in err) == said
    assert "squares measure 5." in err or "squares measure 4." in err or "squares measure 6." in err


def test_cli_bad_input_exits_2_with_one_line(capture, capture_folder, detections, tmp_path, capsys):
    detections_file, rig_file = str(capture_folder / "detections.npz"), str(capture_folder / "cameras.toml")
    out = str(tmp_path / "out.c3d")
    smaller = CameraRig([camera for camera in capture.rig if camera.name != capture.rig.names[2]])
    smaller.save(tmp_path / "smaller.toml")
    assert main(["triangulate", detections_file, "--cameras", str(tmp_path / "smaller.toml"), "--out", out]) == 2
    _one_error_line(capsys, repr(capture.rig.names[2]), "rig lacks")
    assert main(["triangulate", str(tmp_path / "absent.npz"), "--cameras", rig_file, "--out", out]) == 2
    _one_error_line(capsys, "absent.npz", "no such file")
    assert main(["triangulate", detections_file, "--cameras", rig_file, "--out", detections_file]) == 2
    _one_error_line(capsys, "overwrite the input")
    half = detections.select_frames(0, 20)
    write_detections(half, tmp_path / "half.npz")
    renamed = Detections(("extra",), half.marker_names, half.frame[:3], half.camera[:3] * 0, half.marker[:3],
                         half.xy[:3], half.score[:3], half.rate, 25, source="x")
    write_detections(renamed, tmp_path / "extra.npz")
    assert main(["triangulate", str(tmp_path / "half.npz"), str(tmp_path / "extra.npz"), "--cameras", rig_file,
                 "--out", out]) == 2
    _one_error_line(capsys, "mismatched frame counts", "extra.npz")
    assert main(["triangulate", detections_file, "--cameras", rig_file, "--min-views", "1", "--out", out]) == 2
    _one_error_line(capsys, "min_views")
    assert not (tmp_path / "out.c3d").exists()
