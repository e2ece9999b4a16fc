"""Naming unread white squares from the neighbouring frames and the other cameras (``handcap.detect.motion``,
``handcap.detect.views``): what they add, and how often wrong.

    .venv/bin/python benchmarks/views.py            # four rendered takes, about 8 minutes on 2 cores
    .venv/bin/python benchmarks/views.py --quick    # two
    .venv/bin/python benchmarks/views.py --unsynchronised   # cameras not triggered together, about 4 minutes
    .venv/bin/python benchmarks/views.py --quick --workers 2   # and each take detected again, 2 cameras at once

Three takes are ``handcap demo --images``'s kind: one subject in the ``dense-patches`` layout, 13 cameras at 4 Hz,
rendered by ``handcap synth`` (images the networks never saw), a grasp of 11 frames. The fourth is a video: 3
cameras at 20 Hz, a grasp of 51 frames. Each is detected once with the shipped networks and the take's template,
then the unread white squares are named as ``handcap detect`` names them: from the camera's neighbouring frames,
then from the other cameras. Against the image truth it prints, without and with the naming:

1. tags: the visible white squares (all four corners visible, as synth's truth lists them) whose tag is reported at
   their place, and the reported tags whose corners are not where that tag's square lies in that image (wrong);
2. corners: named within 2 px of their true pixel, as a share of the visible corners, and named farther (wrong);
3. the corners triangulated from three views or more (RANSAC over views, as ``handcap triangulate``): marker-frames
   and their error from the truth;
4. the naming's time, and the images' detection time beside it;
5. the same naming with a rig calibrated less well: every camera turned by 0.2 mrad and moved by 0.2 mm (standard
   deviations, each axis), so that the named corners reproject about 0.8 px from where they were found (a good
   calibration of a real rig: 0.3-0.5 px).
6. with ``--workers N``, each take of 13 cameras detected again with N cameras at once (``detect --workers N``), its
   time against the detection in one process and whether the detections agree.

``--unsynchronised``: a grasp filmed by 8 cameras at 20 Hz, each started at its own third of a frame
(:class:`~handcap.synth.filming.Clocks`), named as synchronised, with the offsets ``detect --sync auto`` finds, and
with the true offsets.
"""

from __future__ import annotations

import argparse
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from handcap.core.camera_rig import CameraRig
from handcap.detect.capture import detect_capture
from handcap.detect.networks import load_checker, load_corner_net, load_reader, load_refiner
from handcap.detect.pipeline import Detector
from handcap.detect.sources import frame_sources
from handcap.detect.motion import name_from_frames
from handcap.detect.naming import square_corners
from handcap.detect.seek import searched_frames, second_look
from handcap.detect.views import name_from_views
from handcap.multiview import triangulate_detections
from handcap.multiview.detections import detections_of
from handcap.multiview.offsets import shift_detections
from handcap.multiview.sync import Sync, estimate_sync
from handcap.patterns.pattern import Pattern
from handcap.synth.config import SynthConfig
from handcap.synth.filming import Clocks, film_take

SEEDS = ((7, 21), (101, 201), (102, 202))  # (take seed, subject seed); the first is the demo's take
OFF = 2e-4  # the rig calibrated less well: radians of each camera's turn, metres of its move (standard deviations)


def scores(arrays: dict, truth, rig: CameraRig, pattern: Pattern, offsets=None) -> dict:
    """Tags, corners and triangulation of a detections file's arrays against the image truth (with ``offsets``,
    cameras not triggered together: triangulated on the first camera's frames, as ``triangulate --sync``)."""
    index = {str(n): k for k, n in enumerate(truth["marker_names"])}
    every = truth["all_xy"]  # (T, C, N, 2), hidden corners too
    names = [str(arrays["marker_names"][m]) for m in arrays["marker"]]
    true_xy = every[arrays["frame"], arrays["camera"], [index[n] for n in names]]
    right = np.linalg.norm(arrays["xy"] - true_xy, axis=1) <= 2.0
    read = {(str(t), int(c), int(f)): xy for t, c, f, xy in zip(arrays["block_text"], arrays["block_camera"],
                                                                 arrays["block_frame"], arrays["block_xy"])}
    visible = [(str(t), int(c), int(f)) for t, c, f in zip(truth["block_text"], truth["block_camera"],
                                                           truth["block_frame"])]
    where = dict(zip(visible, truth["block_xy"]))
    found = sum(k in read and np.linalg.norm(read[k] - where[k], axis=1).max() <= 2.0 for k in visible)
    tags, corners = square_corners(pattern, truth["marker_names"])
    squares = dict(zip(tags.tolist(), corners))
    wrong = 0
    for (text, c, f), xy in read.items():
        corners = squares.get(text)
        place = None if corners is None else every[f, c, corners]
        wrong += place is None or not np.linalg.norm(place - xy, axis=1).max() <= 2.0
    d = detections_of(arrays)
    if offsets is not None:
        d, _ = shift_detections(d, offsets)
    tri = triangulate_detections(d, rig, min_views=3, progress=False)
    columns = [index.get(str(n), -1) for n in tri.names]
    true = np.where(np.array(columns)[None, :, None] >= 0, truth["positions"][:, columns], np.nan)
    if len(true) < len(tri.positions):  # frames of the other cameras after the first camera's last
        true = np.concatenate([true, np.full((len(tri.positions) - len(true),) + true.shape[1:], np.nan)])
    error = np.linalg.norm(tri.positions - true, axis=-1) * 1000
    ok = np.isfinite(error)
    return {"tags": found, "visible tags": len(visible), "tags reported": len(read), "tags wrong": wrong,
            "named right": int(right.sum()), "visible corners": len(truth["frame"]), "named wrong": int((~right).sum()),
            "marker-frames": int(ok.sum()), "median mm": float(np.median(error[ok])) if ok.any() else np.nan,
            "p95 mm": float(np.percentile(error[ok], 95)) if ok.any() else np.nan}


def rougher(rig: CameraRig, seed: int) -> CameraRig:
    """``rig`` with every camera turned and moved at random by :data:`OFF` (standard deviations)."""
    rng = np.random.default_rng(seed)
    return replace(rig, cameras=tuple(replace(c, rotation=np.asarray(c.rotation) + rng.normal(0, OFF, 3),
                                              translation=np.asarray(c.translation) + rng.normal(0, OFF, 3))
                                      for c in rig.cameras))


def reprojection(arrays: dict, rig: CameraRig) -> float:
    """Median reprojection error of the named corners triangulated from two views or more, pixels."""
    d = detections_of(arrays)
    return float(np.nanmedian(triangulate_detections(d, rig, min_views=2, progress=False).error_px))


def line(what: str, s: dict) -> str:
    """One line of figures (:func:`scores`)."""
    named = max(s["named right"] + s["named wrong"], 1)
    return (f"  {what}: tags {100 * s['tags'] / s['visible tags']:.1f} % of {s['visible tags']} visible reported "
            f"right, {s['tags wrong']} of {s['tags reported']} reported wrong; corners named right "
            f"{100 * s['named right'] / s['visible corners']:.1f} % of {s['visible corners']} visible, "
            f"{s['named wrong']} named wrong ({100 * s['named wrong'] / named:.3f} %); triangulated (3 views) "
            f"{s['marker-frames']} marker-frames, median {s['median mm']:.3f} mm, "
            f"p95 {s['p95 mm']:.3f} mm")


def detected(detector, config, folder, clocks=None):
    """Film ``config`` into ``folder`` and detect it: (capture, pattern, run, seconds, truth, frames), ``frames``
    the images as searched (for :func:`~handcap.detect.seek.second_look`)."""
    capture = film_take(config, folder, progress=False, clocks=clocks)
    pattern = Pattern.load(Path(folder) / "pattern.toml")
    detector.pattern = pattern
    sources = frame_sources([Path(folder) / "images" / c.name for c in capture.rig])
    start = time.perf_counter()
    rate = config.rate / (1 if clocks is None else clocks.every)
    run = detect_capture(detector, sources, pattern.corner_names(), rate, progress=False, response="linear")
    return (capture, pattern, run, time.perf_counter() - start, np.load(Path(folder) / "image_truth.npz"),
            searched_frames(detector, sources, run.responses))


def in_processes(detector, capture, pattern, run, folder, rate: float, workers: int, seconds: float) -> str:
    """The take in ``folder`` detected again with ``workers`` cameras at once: its time against ``seconds`` (in one
    process) and whether it names the same corners at the same pixels (to float rounding) as ``run``; "" for 1."""
    if workers <= 1:
        return ""
    sources = frame_sources([Path(folder) / "images" / c.name for c in capture.rig])
    start = time.perf_counter()
    apart = detect_capture(detector, sources, pattern.corner_names(), rate, progress=False, response="linear",
                           workers=workers)
    took = time.perf_counter() - start
    a, b = run.arrays, apart.arrays
    same = all(np.allclose(a[k], b[k], rtol=0, atol=1e-6) if a[k].dtype.kind == "f" else np.array_equal(a[k], b[k])
               for k in a)
    return (f"; detected again with {workers} cameras at once (processes): {took:.1f} s, {seconds / took:.2f}x the "
            f"one process's speed, the same detections: {same}")


def named(run, rig, pattern, sync=None, frames=None, refiner=None):
    """As ``handcap detect`` names the unread squares: from the neighbouring frames, then from the other cameras
    (``sync``: 'auto' finds the cameras' offsets first, as ``detect --sync auto``, or a Sync gives them), then
    (given ``frames`` and ``refiner``) by the second look where the other cameras or the neighbouring frames place
    squares; returns the three
    namings (the last None without ``frames``) and the seconds they took, the second look's apart."""
    start = time.perf_counter()
    moved = name_from_frames(run.arrays, run.unread, pattern, progress=False)
    if sync == "auto":
        sync = estimate_sync(detections_of(moved.arrays), rig)
    views = name_from_views(moved.arrays, moved.left, rig, pattern, progress=False, sync=sync)
    seconds = time.perf_counter() - start
    if frames is None:
        return moved, views, None, (seconds, 0.0)
    start = time.perf_counter()
    sought = second_look(views.arrays, pattern, refiner, frames, rig=rig, sync=sync, progress=False)
    return moved, views, sought, (seconds, time.perf_counter() - start)


def unsynchronised(detector) -> None:
    """8 cameras at 20 Hz started one by one (a grasp filmed at 60 Hz, each camera taking every third frame from
    its own start), named as synchronised, with the offsets ``detect --sync auto`` finds, and with the true ones."""
    starts = (0, 4, 1, 8, 2, 6, 3, 7)
    config = SynthConfig(layout="dense-patches", motion="grasp", frames=165, rate=60.0, seed=11, subject_seed=31,
                         cameras=8, min_views=3)
    clocks = Clocks(starts, 3)
    with tempfile.TemporaryDirectory() as folder:
        capture, pattern, run, seconds, truth, frames = detected(detector, config, folder, clocks)
        names = tuple(str(n) for n in run.arrays["camera_names"])
        true = Sync(names, clocks.offsets(), names[0], np.nan, np.nan, 0)
        results = [named(run, capture.rig, pattern, sync, frames, detector.refiner) for sync in (None, "auto", true)]
        figures = [scores(run.arrays, truth, capture.rig, pattern, true.offsets)]
        for _, views, sought, _ in results:
            figures += [scores(a.arrays, truth, capture.rig, pattern, true.offsets) for a in (views, sought)]
    auto = results[1]
    print(f"8 cameras at 20 Hz not triggered together (offsets {', '.join(f'{o:.2f}' for o in true.offsets)} "
          f"frames), {run.images} images: detection {seconds:.1f} s; taken as synchronised: "
          f"{results[0][1].summary()} ({'; '.join(results[0][1].warnings) or 'no warning'}); {results[0][2].summary()}"
          f"; with the offsets found: {auto[1].summary()}, {auto[2].summary()}, naming {auto[3][0]:.2f} s, second "
          f"look {auto[3][1]:.2f} s; with the true offsets: {results[2][1].summary()}, {results[2][2].summary()}")
    for what, value in zip(("detected", "named as synchronised", "and a second look", "named with the offsets found "
                            "(--sync auto)", "and a second look", "named with the true offsets", "and a second look"),
                           figures):
        print(line(what + " (triangulated with the true offsets)", value))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="one take of 13 cameras, and the video")
    parser.add_argument("--unsynchronised", action="store_true", help="only the cameras not triggered together")
    parser.add_argument("--workers", type=int, default=1,
                        help="detect each take of 13 cameras again with this many cameras at once, and time both")
    args = parser.parse_args()
    detector = Detector(load_corner_net(int8=True), load_reader(), refiner=load_refiner(int8=True),
                        checker=load_checker())
    if args.unsynchronised:
        unsynchronised(detector)
        return
    rows = ("detected", "named from the neighbouring frames too", "and from the other cameras",
            "and a second look where the other cameras or the neighbouring frames place squares",
            "the same with a rig calibrated less well")
    totals = {what: [] for what in rows}
    for seed, subject in SEEDS[:1] if args.quick else SEEDS:
        config = SynthConfig(layout="dense-patches", motion="grasp", frames=11, rate=4.0, seed=seed,
                             subject_seed=subject, cameras=13, min_views=3)
        with tempfile.TemporaryDirectory() as folder:
            capture, pattern, run, seconds, truth, frames = detected(detector, config, folder)
            apart = in_processes(detector, capture, pattern, run, folder, config.rate, args.workers, seconds)
            moved, views, sought, naming = named(run, capture.rig, pattern, None, frames, detector.refiner)
            rough = rougher(capture.rig, seed)
            _, roughly, rough_sought, _ = named(run, rough, pattern, None, frames, detector.refiner)
            off = (reprojection(run.arrays, capture.rig), reprojection(run.arrays, rough))
            figures = [scores(a, truth, capture.rig, pattern) for a in (run.arrays, moved.arrays, views.arrays,
                                                                        sought.arrays, rough_sought.arrays)]
        for key, value in zip(totals, figures):
            totals[key].append(value)
        print(f"take seed {seed} (subject {subject}), 13 cameras at 4 Hz, {run.images} images: detection "
              f"{seconds:.1f} s ({seconds / run.images:.2f} s/image); {moved.summary()}; {views.summary()}, "
              f"{views.refused} refused; {sought.summary()}, {sought.refused} refused; naming {naming[0]:.2f} s, "
              f"second look {naming[1]:.2f} s" + (f"; warnings: {'; '.join(views.warnings)}" if views.warnings else "")
              + apart)
        for what, value in zip(rows[:-1], figures):
            print(line(what, value))
        print(line(f"the same with a rig calibrated less well (median reprojection {off[1]:.2f} px, against "
                   f"{off[0]:.2f} px; {roughly.squares} squares named from the other cameras, {rough_sought.squares} "
                   "by the second look)", figures[-1]))
    if len(SEEDS[:1] if args.quick else SEEDS) > 1:
        print("all takes of 13 cameras:")
        for what, each in totals.items():
            summed = {k: sum(s[k] for s in each) for k in each[0]}
            summed["median mm"] = float(np.median([s["median mm"] for s in each]))
            summed["p95 mm"] = float(np.median([s["p95 mm"] for s in each]))
            print(line(what + " (median of the takes' mm)", summed))
    # A video: 3 cameras at 20 Hz, so few that they share few corners, and frames close enough in time.
    config = SynthConfig(layout="dense-patches", motion="grasp", frames=51, rate=20.0, seed=5, subject_seed=21,
                         cameras=3, min_views=2)
    with tempfile.TemporaryDirectory() as folder:
        capture, pattern, run, seconds, truth, frames = detected(detector, config, folder)
        moved, views, sought, naming = named(run, capture.rig, pattern, None, frames, detector.refiner)
        figures = [scores(a, truth, capture.rig, pattern) for a in (run.arrays, moved.arrays, views.arrays,
                                                                    sought.arrays)]
    print(f"video, 3 cameras at 20 Hz, {run.images} images: detection {seconds:.1f} s; {moved.summary()}; "
          f"{views.summary()}; {sought.summary()}; naming {naming[0]:.2f} s, second look {naming[1]:.2f} s")
    for what, value in zip(rows[:-1], figures):
        print(line(what, value))


if __name__ == "__main__":
    main()
