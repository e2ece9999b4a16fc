"""Cameras not triggered together: their offsets found from the detections against known truth.

The truth: a take synthesised at four times the rate, each camera keeping every fourth frame from its own
phase and starting its own number of frames late, so camera c's frame f is the moment of the reference's frame
``f + start[c] + phase[c] / 4`` exactly.
"""

import numpy as np
import pytest

from handcap import HandcapError
from handcap.cli import main
from handcap.io.camera_formats import write_rig
from handcap.multiview import Detections, read_detections, triangulate_detections, write_detections
from handcap.multiview.epipolar import EpipolarViews
from handcap.io import read_markers
from handcap.multiview.sync import (Sync, check_sync, estimate_sync, offsets_from_names, parse_offsets,
                                    shift_detections)
from handcap.steps.detect import clock_arrays
from handcap.synth.config import SynthConfig
from handcap.synth.scene import synthesize

UP, FRAMES, RATE = 4, 120, 60.0
START = np.array([0, 7, -5, 3, -9, 12])
PHASE = np.array([0, 1, 2, 3, 0, 2])


@pytest.fixture(scope="module")
def capture():
    return synthesize(SynthConfig(layout="glove-13", motion="random", frames=FRAMES * UP, rate=RATE * UP, seed=3,
                                  cameras=6, outlier_rate=0.02, ghost_rate=0.0), progress=False)


def _cameras(capture, start, phase, *, rate_of=None) -> Detections:
    """Each camera's own frames (see the module docstring); ``rate_of`` {camera: factor} runs a camera's clock
    that much fast."""
    d = capture.detections
    frames, rows = [], []
    for c in range(len(d["camera_names"])):
        mine = np.flatnonzero(d["camera"] == c)
        factor = (rate_of or {}).get(c, 1.0)
        wanted = np.round((np.arange(FRAMES) * UP + phase[c] + UP * start[c]) * factor).astype(int)
        at = {int(f): k for k, f in enumerate(wanted)}
        own = np.array([at.get(int(f), -1) for f in d["frame"][mine]])
        frames.append(own[own >= 0])
        rows.append(mine[own >= 0])
    rows = np.concatenate(rows)
    return Detections(d["camera_names"], d["marker_names"], np.concatenate(frames), d["camera"][rows],
                      d["marker"][rows], d["xy"][rows], d["score"][rows], RATE, FRAMES, source="cameras")


def _error_mm(capture, markers) -> float:
    """Median distance of the triangulated hand markers from the truth at the reference's frames, mm."""
    names = [str(n) for n in capture.truth["names"]]
    index = [names.index(n) for n in markers.names]
    truth = capture.truth["positions"][::UP][:markers.n_frames, index]
    return 1000 * float(np.nanmedian(np.linalg.norm(markers.positions - truth[:len(markers.positions)], axis=-1)))


def test_offsets_are_found_to_a_twentieth_of_a_frame_and_the_markers_land_on_the_truth(capture):
    cameras = _cameras(capture, START, PHASE)
    truth = START + PHASE / UP
    sync = estimate_sync(cameras, capture.rig)
    assert sync.reference == "cam_0" and sync.warnings == ()
    assert np.abs(sync.offsets - truth).max() < 0.05, (sync.offsets, truth)
    assert sync.before > 10 and sync.after < 1.0, sync.summary()
    shifted, lost = shift_detections(cameras, sync.offsets)
    assert 0 < lost < 0.2 * len(cameras.frame)
    before = triangulate_detections(cameras, capture.rig, min_views=2, threshold_px=5.0)
    after = triangulate_detections(shifted, capture.rig, min_views=2, threshold_px=5.0)
    assert after.counts()["mean_views"] > before.counts()["mean_views"] + 1
    assert _error_mm(capture, after.to_markers()) < 1.0 < 3 * _error_mm(capture, before.to_markers())
    # another reference: the same offsets, counted from it
    other = estimate_sync(cameras, capture.rig, reference="cam_3")
    assert np.abs(other.offsets - (truth - truth[3])).max() < 0.05


def test_shifting_renumbers_whole_offsets_and_interpolates_fractions():
    rate, xy = 30.0, np.array([[10.0, 20.0], [14.0, 28.0], [30.0, 30.0], [50.0, 60.0]])
    d = Detections(("a", "b"), ("m",), np.array([0, 1, 5, 6]), np.array([0, 0, 1, 1]), np.zeros(4, int), xy,
                   np.array([1.0, 0.9, 0.8, 0.7]), rate, 8)
    whole, lost = shift_detections(d, [0.0, 2.0])
    assert lost == 0 and whole.frame.tolist() == [0, 1, 7, 8] and whole.n_frames == 9
    assert np.array_equal(whole.xy, xy)
    # b's clock 10 % slow: its frames 5 and 6 show the reference's 4.5 and 5.4; the reference's frame 5 lies
    # 0.5 / 0.9 of the way from b's frame 5 to 6
    slow, _ = shift_detections(d, [0.0, 0.0], [0.0, -0.1])
    assert slow.frame.tolist() == [0, 1, 5] and np.allclose(slow.xy[2], xy[2] + 5 / 9 * (xy[3] - xy[2]))
    part, lost = shift_detections(d, [-1.0, 0.25])
    # a's frame 0 falls before the reference's frame 0; b's frames 5 and 6 give the reference's frame 6:
    # b's time 5.75, three quarters of the way from frame 5 to 6
    assert lost == 2 and part.frame.tolist() == [0, 6] and part.camera.tolist() == [0, 1]
    assert np.allclose(part.xy[1], 0.25 * xy[2] + 0.75 * xy[3]) and part.score[1] == 0.7
    _, lost = shift_detections(d, [0.0, np.nan])
    assert lost == 2
    with pytest.raises(HandcapError, match="one offset per camera"):
        shift_detections(d, [0.0])


def test_the_check_warns_only_when_cameras_are_not_synchronised(capture):
    together = _cameras(capture, np.zeros(6, int), np.zeros(6, int))
    assert check_sync(together, capture.rig).warnings == ()
    apart = _cameras(capture, START, PHASE)
    found = check_sync(apart, capture.rig)
    assert any("seem not synchronised" in w and "--sync auto" in w for w in found.warnings)
    right = offsets_from_names(apart, {f"cam_{c}": START[c] + PHASE[c] / UP for c in range(6)})
    assert check_sync(apart, capture.rig, right).warnings == ()
    assert any("check their signs" in w for w in check_sync(apart, capture.rig, -right).warnings)


def test_cameras_in_step_that_share_few_views_keep_no_offset(capture):
    """A fifth of the detections of cameras filmed together, 0.5 px of noise: before the best whole shift was scored
    on all the views (not only the search's sample) and a camera kept its offset only where its views agree better
    with it than at 0, draws 5 and 10 (of 12) put cameras 1 or 0.33-0.67 frames off, the views agreeing worse."""
    together = _cameras(capture, np.zeros(6, int), np.zeros(6, int))
    for seed in (5, 10):
        rng = np.random.default_rng(seed)
        keep = rng.random(len(together.frame)) < 0.2
        sparse = Detections(together.camera_names, together.marker_names, together.frame[keep],
                            together.camera[keep], together.marker[keep],
                            together.xy[keep] + rng.normal(0, 0.5, (keep.sum(), 2)), together.score[keep], RATE,
                            FRAMES)
        sync = estimate_sync(sparse, capture.rig)
        found = sync.offsets[np.isfinite(sync.offsets)]
        assert len(found) >= 4 and np.abs(found).max() < 0.05, (seed, sync.offsets)
        assert sync.after <= sync.before + 1e-9


def test_a_pair_that_agrees_nowhere_within_the_noise_is_left_out(capture):
    """Views that agree no better than 3 px at their best shift matched no moments: in a rendered take of 4 cameras,
    two that shared 809 views agreed best 25 frames apart to 6.2 px, and that put a camera filmed in step 24 frames
    off. Here camera 4's pixels carry 8 px of noise (its pairs agree to 4-5 px at best): it is left out, said, and
    the others are timed as before; with 4 px (under 3 px at its offset) it is timed too."""
    cameras = _cameras(capture, START, PHASE)
    truth = START + PHASE / UP
    rng = np.random.default_rng(0)
    for px, kept in ((4.0, True), (8.0, False)):
        noisy = cameras.xy + (cameras.camera == 4)[:, None] * rng.normal(0, px, cameras.xy.shape)
        sync = estimate_sync(Detections(cameras.camera_names, cameras.marker_names, cameras.frame, cameras.camera,
                                        cameras.marker, noisy, cameras.score, RATE, FRAMES), capture.rig)
        others = np.arange(6) != 4
        assert np.abs(sync.offsets[others] - truth[others]).max() < 0.05, (px, sync.offsets)
        if kept:
            assert abs(sync.offsets[4] - truth[4]) < 0.2 and sync.warnings == ()
        else:
            assert np.isnan(sync.offsets[4])
            assert any("and cam_4 agree best" in w and "left out" in w for w in sync.warnings), sync.warnings


def test_what_cannot_be_found_is_said(capture):
    cameras = _cameras(capture, START, PHASE)
    # a still take: every frame shows the first one, so no offset is better than another
    first = cameras.frame == cameras.frame.min()
    still = Detections(cameras.camera_names, cameras.marker_names,
                       np.concatenate([cameras.frame[first] * 0 + f for f in range(40)]),
                       np.tile(cameras.camera[first], 40), np.tile(cameras.marker[first], 40),
                       np.tile(cameras.xy[first], (40, 1)), np.tile(cameras.score[first], 40), RATE, 40)
    sync = estimate_sync(still, capture.rig)
    assert np.isnan(sync.offsets[1:]).all() and any("no offset found" in w for w in sync.warnings)
    # a camera that sees none of the others' markers
    alone = Detections(cameras.camera_names, (*cameras.marker_names, *(f"x{m}" for m in cameras.marker_names)),
                       cameras.frame, cameras.camera,
                       cameras.marker + len(cameras.marker_names) * (cameras.camera == 4), cameras.xy, cameras.score,
                       RATE, FRAMES)
    sync = estimate_sync(alone, capture.rig)
    assert np.isnan(sync.offsets[4]) and np.isfinite(np.delete(sync.offsets, 4)).all()
    assert any("no offset found for camera cam_4" in w for w in sync.warnings)
    # an offset past the search range
    sync = estimate_sync(cameras, capture.rig, max_offset_s=0.1)
    assert any("end of the search range" in w for w in sync.warnings)
    # a camera that drops 2 frames three quarters into the take: its offset jumps, which no line follows
    d = _cameras(capture, START, PHASE)
    mine = d.camera == 3
    keep = ~(mine & (d.frame >= 90) & (d.frame < 92))
    frame = np.where(mine & (d.frame >= 92), d.frame - 2, d.frame)[keep]
    dropped = Detections(d.camera_names, d.marker_names, frame, d.camera[keep], d.marker[keep], d.xy[keep],
                         d.score[keep], RATE, FRAMES)
    assert any("camera cam_3's offset changes within the take" in w
               for w in estimate_sync(dropped, capture.rig).warnings)


def test_a_clock_that_runs_fast_is_followed(capture):
    """Camera 2's clock runs 2 % fast: its frame f shows the reference's frame 1.02 (f + start + phase / 4)."""
    drifting = _cameras(capture, START, PHASE, rate_of={2: 1.02})
    sync = estimate_sync(drifting, capture.rig)
    assert abs(sync.drift[2] - 0.02) < 0.002 and np.abs(np.delete(sync.drift, 2)).max() < 0.002, sync.summary()
    truth = START + PHASE / UP
    assert abs(sync.offsets[2] - 1.02 * truth[2]) < 0.2 and np.abs(np.delete(sync.offsets - truth, 2)).max() < 0.1
    assert "cam_2's clock runs +" in sync.summary() and sync.after < 1.0
    # camera 2's views agree with its partners' when its clock is followed, not with one offset alone
    views = EpipolarViews(drifting, capture.rig)
    pairs = [pair for pair in views.pairs() if 2 in pair]
    followed, constant = views.median_distance(pairs, sync.offsets, sync.drift), views.median_distance(pairs,
                                                                                                       sync.offsets)
    assert followed < 1.0 < 3 * followed < constant, (followed, constant)
    results = [triangulate_detections(shift_detections(drifting, sync.offsets, drift)[0], capture.rig, min_views=2,
                                      threshold_px=5.0) for drift in (sync.drift, None)]
    assert 2 * results[0].counts()["rejected"] < results[1].counts()["rejected"]
    assert _error_mm(capture, results[0].to_markers()) < 0.5


def test_offsets_given_by_name_and_refused_in_one_line(capture):
    cameras = _cameras(capture, START, PHASE)
    assert parse_offsets("cam_1=+7.25, cam_2 = -4.5") == {"cam_1": 7.25, "cam_2": -4.5}
    assert parse_offsets(["cam_1=1", "cam_3=2"]) == {"cam_1": 1.0, "cam_3": 2.0}
    assert offsets_from_names(cameras, {"cam_1": 3.0, "cam_2": 1.0}, "cam_2").tolist() == [-1, 2, 0, -1, -1, -1]
    for bad, message in (("cam_1", "CAMERA=FRAMES"), ("=3", "CAMERA=FRAMES"), ("cam_1=x", "number of frames"),
                         ("cam_1=1,cam_1=2", "two offsets"), ("cam_1=nan", "finite"), ("", "CAMERA=FRAMES")):
        with pytest.raises(HandcapError, match=message):
            parse_offsets(bad)
    with pytest.raises(HandcapError, match="lack"):
        offsets_from_names(cameras, {"cam_9": 1.0})
    with pytest.raises(HandcapError, match="no camera 'cam_9'"):
        estimate_sync(cameras, capture.rig, reference="cam_9")
    with pytest.raises(HandcapError, match="positive number of seconds"):
        estimate_sync(cameras, capture.rig, max_offset_s=0)


def test_the_command_synchronises_files_of_one_camera_each(capture, tmp_path, capsys):
    cameras = _cameras(capture, START, PHASE)
    paths = []
    for c, name in enumerate(cameras.camera_names):  # one file per camera, each as long as its camera recorded
        mine = cameras.camera == c
        length = int(cameras.frame[mine].max()) + 1
        part = Detections((name,), cameras.marker_names, cameras.frame[mine], cameras.camera[mine] * 0,
                          cameras.marker[mine], cameras.xy[mine], cameras.score[mine], RATE, length)
        paths.append(tmp_path / f"{name}.npz")
        write_detections(part, paths[-1])
    rig = tmp_path / "cameras.toml"
    write_rig(capture.rig, rig)
    before = [p.read_bytes() for p in paths]
    args = ["triangulate", *map(str, paths), "--cameras", str(rig), "--min-views", "2"]
    assert main([*args, "--out", str(tmp_path / "apart.c3d")]) == 2  # different lengths: not one take as it is
    assert "--sync auto" in capsys.readouterr().err
    assert main([*args, "--sync", "auto", "--out", str(tmp_path / "synced.c3d")]) == 0
    out = capsys.readouterr().out
    assert "synchronised to cam_0" in out and "cam_1 +7.2" in out
    quality = np.load(tmp_path / "synced.triangulation.npz")
    assert np.abs(quality["sync_offsets"] - (START + PHASE / UP)).max() < 0.05
    assert [p.read_bytes() for p in paths] == before
    for extra, message in ((["--sync", "auto", "--sync", "cam_1=2"], "give it alone"),
                           (["--sync-reference", "cam_1"], "goes with --sync"),
                           (["--sync", "cam_7=2"], "lack"), (["--sync", "cam_1"], "CAMERA=FRAMES")):
        assert main([*args, *extra, "--out", str(tmp_path / "bad.c3d")]) == 2
        err = capsys.readouterr().err
        assert message in err and len(err.strip().splitlines()) == 1, err
    assert not (tmp_path / "bad.c3d").exists()
    # a take in which nothing moves: no offset can be told, which is one clear line, not a triangulation of one view
    first = cameras.frame == 0
    still = Detections(cameras.camera_names, cameras.marker_names, np.repeat(np.arange(30), first.sum()),
                       np.tile(cameras.camera[first], 30), np.tile(cameras.marker[first], 30),
                       np.tile(cameras.xy[first], (30, 1)), np.ones(30 * first.sum()), RATE, 30)
    write_detections(still, tmp_path / "still.npz")
    assert main(["triangulate", str(tmp_path / "still.npz"), "--cameras", str(rig), "--sync", "auto",
                 "--out", str(tmp_path / "still.c3d")]) == 2
    assert "placed no camera beside cam_0" in capsys.readouterr().err
    assert read_detections(paths[0]).n_frames == FRAMES - START[0]


def test_offsets_that_detect_stored_are_taken_by_triangulate_without_sync(capture, tmp_path, capsys):
    cameras = _cameras(capture, START, PHASE)
    truth = START + PHASE / UP
    rig = tmp_path / "cameras.toml"
    write_rig(capture.rig, rig)

    def written(name, offsets, reference="cam_0"):
        path = tmp_path / f"{name}.npz"
        write_detections(cameras, path)
        with np.load(path) as data:
            arrays = dict(data)
        sync = Sync(cameras.camera_names, np.asarray(offsets, float), reference, np.nan, np.nan, 0)
        np.savez(path, **arrays, **clock_arrays(sync))
        return path

    args = ["--cameras", str(rig), "--min-views", "2"]
    stored = written("stored", truth)
    before = stored.read_bytes()
    assert main(["triangulate", str(stored), *args, "--out", str(tmp_path / "stored.c3d")]) == 0
    out = capsys.readouterr().out
    assert "offsets as detect --sync stored them" in out and "cam_1 +7.25" in out
    assert np.allclose(np.load(tmp_path / "stored.triangulation.npz")["sync_offsets"], truth)
    assert _error_mm(capture, read_markers(tmp_path / "stored.c3d")) < 1.0
    assert stored.read_bytes() == before
    # the same file taken as it is, without the stored offsets: the views disagree (the check says so)
    plain = tmp_path / "plain.npz"
    write_detections(cameras, plain)
    assert main(["triangulate", str(plain), *args, "--out", str(tmp_path / "plain.c3d")]) == 0
    assert "seem not synchronised" in capsys.readouterr().err
    assert _error_mm(capture, read_markers(tmp_path / "plain.c3d")) > 3.0
    # a camera detect could not place: left out, with a warning; --sync overrides what is stored
    lacking = written("lacking", np.r_[truth[:5], np.nan])
    assert main(["triangulate", str(lacking), *args, "--out", str(tmp_path / "lacking.c3d")]) == 0
    assert "no stored offset for camera cam_5" in capsys.readouterr().err
    assert main(["triangulate", str(lacking), *args, "--sync", "auto", "--out", str(tmp_path / "auto.c3d")]) == 0
    assert np.abs(np.load(tmp_path / "auto.triangulation.npz")["sync_offsets"] - truth).max() < 0.05
    # two files whose offsets count from different cameras cannot be joined
    other = written("other", truth - truth[3], reference="cam_3")
    assert main(["triangulate", str(stored), str(other), *args, "--out", str(tmp_path / "both.c3d")]) == 2
    assert "count from different cameras (cam_0, cam_3)" in capsys.readouterr().err
    # stored offsets that are no numbers, or one short: one line
    for name, bad in (("words", {"sync_offsets": np.array(["a"] * 6)}), ("short", {"sync_drift": np.zeros(5)})):
        with np.load(stored) as data:
            np.savez(tmp_path / f"{name}.npz", **{**dict(data), **bad})
        assert main(["triangulate", str(tmp_path / f"{name}.npz"), *args, "--out", str(tmp_path / "bad.c3d")]) == 2
        err = capsys.readouterr().err
        assert "stored" in err and len(err.strip().splitlines()) == 1, err


def _circling(step: float, noise: float, frames: int = 16, markers: int = 4, seed: int = 0):
    """Camera b's detections of ``markers`` finger tips going round (40-70 px radius, ``step`` radians a frame),
    with ``noise`` px, and each one's true pixels at any moment (b's frames)."""
    def at(m, t):
        a = t * step + m
        return np.stack([300 + (40 + 10 * m) * np.cos(a), 200 + (40 + 10 * m) * np.sin(a)], axis=-1)

    frame, marker = np.tile(np.arange(frames), markers), np.repeat(np.arange(markers), frames)
    xy = at(marker, frame) + np.random.default_rng(seed).normal(0, noise, (len(frame), 2))
    return frame, marker, xy, at


def test_a_marker_that_curves_between_frames_is_moved_along_its_curve():
    # Finger tips going round at 20 Hz (a quarter turn in 4 frames): camera b started half a frame late, so the
    # reference's frames fall halfway between b's.
    frame, marker, xy, at = _circling(np.pi / 8, 0.0)
    seen = ~((marker == 0) & (frame == 9))  # b lost marker 0 in its frame 9
    d = Detections(("a", "b"), ("m0", "m1", "m2", "m3"), frame[seen], np.ones(seen.sum(), int), marker[seen],
                   xy[seen], np.ones(seen.sum()), 20.0, 16)
    shifted, _ = shift_detections(d, [0.0, -0.5])  # b's frame f shows the reference's f - 0.5
    truth = at(shifted.marker, shifted.frame + 0.5)  # the reference's frame g is b's moment g + 0.5
    error = np.linalg.norm(shifted.xy - truth, axis=1)
    # Where b lacks a frame around its two (each marker's first and last, and marker 0 around its lost frame), the
    # straight line, off by the chord's sag, r (1 - cos(pi / 16)) = 0.77-1.35 px; along the spline elsewhere,
    # within 0.05 px (58 moments: b's pairs of frames, less marker 0's two around its lost frame).
    first, last = shifted.frame == 0, shifted.frame == 14
    straight = first | last | ((shifted.marker == 0) & np.isin(shifted.frame, [7, 10]))
    np.testing.assert_allclose(error[straight], (40 + 10 * shifted.marker[straight]) * (1 - np.cos(np.pi / 16)),
                               rtol=1e-6)
    assert len(error) == 58 and straight.sum() == 10 and error[~straight].max() < 0.05


def test_tracks_are_curving_where_their_motion_between_frames_is_more_than_their_noise():
    from handcap.multiview.offsets import curving

    def told(step, noise, frames=16):
        frame, marker, xy, _ = _circling(step, noise, frames)
        key = marker * (frames + 1) + frame
        return curving(xy, key)

    assert told(np.pi / 8, 0.0) and told(np.pi / 8, 0.15)  # 20 Hz, a detector's noise: the spline
    assert not told(np.pi / 48, 0.5)  # 60 Hz, turning three times slower per frame, half a pixel of noise: the line
    assert not told(0.0, 0.3)  # still: the line
    assert not told(np.pi / 8, 0.0, frames=6)  # 8 points to tell from: the line
