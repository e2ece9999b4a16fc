"""Naming unread white squares from the other cameras (``handcap.detect.views``): what it adds, and how often wrong.

    .venv/bin/python benchmarks/views.py            # three rendered takes, about 6 minutes on 2 cores
    .venv/bin/python benchmarks/views.py --quick    # one

Each take is ``handcap demo --images``'s kind: one subject in the ``dense-patches`` layout, 13 cameras at 4 Hz,
rendered by ``handcap synth`` (images the networks never saw), a grasp of 11 frames. It is detected once with the
shipped networks and the take's template, then the unread white squares are named from the other cameras. Against
the image truth it prints, without and with the naming:

1. tags: the visible white squares (all four corners visible, as synth's truth lists them) whose tag is reported at
   their place, and the reported tags whose corners are not where that tag's square lies in that image (wrong);
2. corners: named within 2 px of their true pixel, as a share of the visible corners, and named farther (wrong);
3. the corners triangulated from three views or more (RANSAC over views, as ``handcap triangulate``): marker-frames
   and their error from the truth;
4. the naming's time, and the images' detection time beside it;
5. the same naming with a rig calibrated less well: every camera turned by 0.2 mrad and moved by 0.2 mm (standard
   deviations, each axis), so that the named corners reproject about 0.8 px from where they were found (a good
   calibration of a real rig: 0.3-0.5 px).
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
from handcap.detect.views import name_from_views, square_corners
from handcap.multiview import Detections, triangulate_detections
from handcap.patterns.pattern import Pattern
from handcap.synth.config import SynthConfig
from handcap.synth.filming import film_take

SEEDS = ((7, 21), (101, 201), (102, 202))  # (take seed, subject seed); the first is the demo's take
OFF = 2e-4  # the rig calibrated less well: radians of each camera's turn, metres of its move (standard deviations)


def scores(arrays: dict, truth, rig: CameraRig, pattern: Pattern) -> dict:
    """Tags, corners and triangulation of a detections file's arrays against the image truth."""
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
    d = Detections(arrays["camera_names"], arrays["marker_names"], arrays["frame"], arrays["camera"],
                   arrays["marker"], arrays["xy"], arrays["score"], arrays["rate"], int(arrays["n_frames"]))
    tri = triangulate_detections(d, rig, min_views=3, progress=False)
    columns = [index.get(str(n), -1) for n in tri.names]
    true = np.where(np.array(columns)[None, :, None] >= 0, truth["positions"][:, columns], np.nan)
    error = np.linalg.norm(tri.positions - true, axis=-1) * 1000
    ok = np.isfinite(error)
    return {"tags": found, "visible tags": len(visible), "tags reported": len(read), "tags wrong": wrong,
            "named right": int(right.sum()), "visible corners": len(truth["frame"]), "named wrong": int((~right).sum()),
            "marker-frames": int(ok.sum()), "median mm": float(np.median(error[ok])),
            "p95 mm": float(np.percentile(error[ok], 95))}


def rougher(rig: CameraRig, seed: int) -> CameraRig:
    """``rig`` with every camera turned and moved at random by :data:`OFF` (standard deviations)."""
    rng = np.random.default_rng(seed)
    return replace(rig, cameras=tuple(replace(c, rotation=np.asarray(c.rotation) + rng.normal(0, OFF, 3),
                                              translation=np.asarray(c.translation) + rng.normal(0, OFF, 3))
                                      for c in rig.cameras))


def reprojection(arrays: dict, rig: CameraRig) -> float:
    """Median reprojection error of the named corners triangulated from two views or more, pixels."""
    d = Detections(arrays["camera_names"], arrays["marker_names"], arrays["frame"], arrays["camera"],
                   arrays["marker"], arrays["xy"], arrays["score"], arrays["rate"], int(arrays["n_frames"]))
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


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="one take")
    args = parser.parse_args()
    detector = Detector(load_corner_net(int8=True), load_reader(), refiner=load_refiner(), checker=load_checker())
    totals = {"before": [], "after": [], "rough": []}
    for seed, subject in SEEDS[:1] if args.quick else SEEDS:
        config = SynthConfig(layout="dense-patches", motion="grasp", frames=11, rate=4.0, seed=seed,
                             subject_seed=subject, cameras=13, min_views=3)
        with tempfile.TemporaryDirectory() as folder:
            capture = film_take(config, folder, progress=False)
            pattern = Pattern.load(Path(folder) / "pattern.toml")
            detector.pattern = pattern
            sources = frame_sources([Path(folder) / "images" / c.name for c in capture.rig])
            start = time.perf_counter()
            run = detect_capture(detector, sources, pattern.corner_names(), config.rate, progress=False,
                                 response="linear")
            seconds = time.perf_counter() - start
            start = time.perf_counter()
            named = name_from_views(run.arrays, run.unread, capture.rig, pattern, progress=False)
            naming = time.perf_counter() - start
            truth = np.load(Path(folder) / "image_truth.npz")
            before = scores(run.arrays, truth, capture.rig, pattern)
            after = scores(named.arrays, truth, capture.rig, pattern)
            rough = rougher(capture.rig, seed)
            roughly = name_from_views(run.arrays, run.unread, rough, pattern, progress=False)
            off = (reprojection(run.arrays, capture.rig), reprojection(run.arrays, rough))
            rough_scores = scores(roughly.arrays, truth, capture.rig, pattern)
        totals["before"].append(before)
        totals["after"].append(after)
        totals["rough"].append(rough_scores)
        print(f"take seed {seed} (subject {subject}), {run.images} images: detection {seconds:.1f} s "
              f"({seconds / run.images:.2f} s/image); {named.summary()}, {named.refused} refused, in {naming:.2f} s"
              + (f"; warnings: {'; '.join(named.warnings)}" if named.warnings else ""))
        print(line("detected", before))
        print(line("named from the other cameras too", after))
        print(line(f"the same with a rig calibrated less well (median reprojection {off[1]:.2f} px, against "
                   f"{off[0]:.2f} px; {roughly.squares} squares named)", rough_scores))
    if len(totals["before"]) > 1:
        print("all takes:")
        for key, what in (("before", "detected"), ("after", "named from the other cameras too"),
                          ("rough", "the same with the rigs calibrated less well")):
            summed = {k: sum(s[k] for s in totals[key]) for k in totals[key][0]}
            summed["median mm"] = float(np.median([s["median mm"] for s in totals[key]]))
            summed["p95 mm"] = float(np.median([s["p95 mm"] for s in totals[key]]))
            print(line(what + " (median of the takes' mm)", summed))


if __name__ == "__main__":
    main()
