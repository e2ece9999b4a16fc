"""Cameras not triggered together: how well ``triangulate --sync auto`` finds their offsets, and what it saves.

    .venv/bin/python benchmarks/sync.py            # about 2 minutes on 2 cores
    .venv/bin/python benchmarks/sync.py --quick    # one take

Each take is ``handcap synth``'s, made at four times 60 Hz; every camera of the 12 then keeps every fourth frame
from its own phase and starts its own number of frames late (up to 1.5 s either way), so its frame f is the
moment of the reference camera's frame ``f + start + phase / 4`` exactly: consumer cameras started by hand. In the
last take two cameras' clocks also run 0.5 % fast and 0.4 % slow (1.5 and 1.2 frames over its 5 s; consumer
clocks drift 10-100 ppm, as much over 4-40 minutes at 60 Hz). The detections carry 0.5 px of noise and 2 % wrong
marker ids. For each take it prints:

1. the offsets found against the truth (frames, and milliseconds at 60 Hz), the clocks' drift found against the
   truth (as frames over the take), the median epipolar distance of the views before and after, and the time the
   search took (with the detections per second);
2. the triangulated markers against the truth at the reference's frames (median, mm) and the points
   triangulated: the cameras as they came, synchronised by the offsets found, and synchronised by the true
   offsets (the best any estimate can do);
3. the quick check that ``triangulate`` runs without ``--sync``: its warning on these takes, and its time.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from handcap.multiview import Detections, triangulate_detections
from handcap.multiview.sync import check_sync, estimate_sync, shift_detections
from handcap.synth.scene import SynthConfig, synthesize

UP, RATE = 4, 60.0
TAKES = (("glove-13", "random", 300, 11, None), ("dense-patches", "grasp", 240, 12, None),
         ("joints-19", "tapping", 300, 13, None), ("glove-13", "random", 300, 14, {3: 1.005, 7: 0.996}))


def cameras_apart(capture, frames: int, seed: int, clocks=None):
    """The capture's detections, each camera on its own clock (see the module docstring); the true offsets and
    drifts. ``clocks`` {camera: rate}: that camera's clock runs so much fast."""
    d = capture.detections
    rng = np.random.default_rng(seed)
    n = len(d["camera_names"])
    start, phase = rng.integers(-90, 91, n), rng.integers(0, UP, n)
    start[0] = phase[0] = 0
    rate = np.array([(clocks or {}).get(c, 1.0) for c in range(n)])
    own_frames, rows = [], []
    for c in range(n):
        mine = np.flatnonzero(d["camera"] == c)
        wanted = np.round(((np.arange(frames) + start[c]) * UP + phase[c]) * rate[c]).astype(int)
        at = dict(zip(wanted.tolist(), range(frames)))
        own = np.array([at.get(int(f), -1) for f in d["frame"][mine]])
        own_frames.append(own[own >= 0])
        rows.append(mine[own >= 0])
    rows = np.concatenate(rows)
    detections = Detections(d["camera_names"], d["marker_names"], np.concatenate(own_frames), d["camera"][rows],
                            d["marker"][rows], d["xy"][rows], d["score"][rows], RATE, frames)
    return detections, (start + phase / UP) * rate, rate - 1


def error_mm(capture, detections) -> tuple[float, int]:
    """Median distance of the triangulated markers from the truth at the reference's frames (mm), and points."""
    result = triangulate_detections(detections, capture.rig, min_views=2, threshold_px=5.0, workers=1)
    names = [str(n) for n in capture.truth["names"]]
    index = [names.index(n) for n in result.names]
    truth = capture.truth["positions"][::UP][:, index]
    t = min(len(truth), len(result.positions))
    distance = np.linalg.norm(result.positions[:t] - truth[:t], axis=-1)
    return 1000 * float(np.nanmedian(distance)), int(np.isfinite(distance).sum())


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="the first take only")
    args = parser.parse_args()
    for layout, motion, frames, seed, clocks in TAKES[:1] if args.quick else TAKES:
        capture = synthesize(SynthConfig(layout=layout, motion=motion, frames=frames * UP, rate=RATE * UP, seed=seed,
                                         outlier_rate=0.02), progress=False)
        detections, truth, drift = cameras_apart(capture, frames, seed, clocks)
        print(f"{layout}, {motion}, {frames} frames at {RATE:g} Hz, 12 cameras, {len(detections.frame):,} detections; "
              f"true offsets {np.round(truth[1:], 2).tolist()} frames"
              + (f"; clocks running fast: {', '.join(f'cam_{c} {100 * (r - 1):+.1f} %' for c, r in clocks.items())} "
                 f"({abs(drift).max() * frames:.1f} frames over the take at most)" if clocks else ""))
        start = time.perf_counter()
        sync = estimate_sync(detections, capture.rig)
        seconds = time.perf_counter() - start
        miss = np.abs(sync.offsets - truth)
        drift_miss = np.abs((sync.drift if sync.drift is not None else 0) - drift) * frames
        print(f"  offsets found: error median {np.nanmedian(miss):.3f}, largest {np.nanmax(miss):.3f} frames "
              f"({1000 * np.nanmax(miss) / RATE:.2f} ms); clocks: error over the take largest {drift_miss.max():.3f} "
              f"frames; cameras without an offset: {int(np.isnan(sync.offsets).sum())}; "
              f"epipolar distance {sync.before:.1f} px -> {sync.after:.2f} px; {seconds:.1f} s "
              f"({len(detections.frame) / seconds:,.0f} detections/s); warnings: {list(sync.warnings) or 'none'}")
        apart, n_apart = error_mm(capture, detections)
        found, n_found = error_mm(capture, shift_detections(detections, sync.offsets, sync.drift)[0])
        best, n_best = error_mm(capture, shift_detections(detections, truth, drift)[0])
        print(f"  markers from the truth (median) / points: as they came {apart:.2f} mm / {n_apart:,}; offsets found "
              f"{found:.3f} mm / {n_found:,}; true offsets {best:.3f} mm / {n_best:,} "
              f"({apart / found:.0f}x closer synchronised; found / true {found / best:.2f})")
        start = time.perf_counter()
        check = check_sync(detections, capture.rig)
        print(f"  the check without --sync: {check.warnings[0] if check.warnings else 'NO WARNING'} "
              f"({time.perf_counter() - start:.2f} s)")


if __name__ == "__main__":
    main()
