"""Robust triangulation of a synthetic 12-camera dense-patches capture: accuracy and throughput.

    .venv/bin/python benchmarks/triangulate.py             # about 3 minutes on 2 cores
    .venv/bin/python benchmarks/triangulate.py --frames 300 --repeat 2   # quicker

The capture is ``handcap synth``'s: the dense-patches layout (362 checkerboard
corners on 19 patches, DexterCap), a grasp with the hand and the object hiding
markers from cameras (ray cast), 12 cage cameras with lens distortion, 0.5 px
detection noise and 2 % of the detections given a wrong marker id.

1. Accuracy against the truth: median and 95th percentile 3D error, mean
   reprojection error, share of injected wrong ids rejected (targets 0.5 mm,
   1.5 mm, 0.7 px, 99 %); the same without RANSAC (every view, no rejection).
2. The research code's way, per point in Python loops over pairs of views and
   keeping the *last* inlier set found, on a sample of points: its error and
   time per point, against ours on the same points.
3. Throughput in marker-frames per second (markers x frames triangulated, RANSAC
   on) on a longer take (the capture repeated): one process, the local process
   pool on every core, and a Dask LocalCluster with one worker per core (target
   50,000 on 2 cores); the three outputs must be identical.
4. Break-even of the local process pool: takes of growing size (the capture
   repeated), one process against the pool on every core (its start included)
   and against the default, which times the first frames and chooses
   (``handcap.multiview.reconstruct.pool_workers``). ``--break-even`` runs only
   this part.
"""

from __future__ import annotations

import argparse
import os
import time
from itertools import combinations

import numpy as np

from handcap.multiview import Detections, triangulate_detections
from handcap.multiview.triangulation import triangulate_ransac
from handcap.parallel import default_workers
from handcap.synth.scene import SynthConfig, synthesize


def _detections(d, repeat: int, n_frames: int) -> Detections:
    frame = np.concatenate([d["frame"] + k * n_frames for k in range(repeat)])

    def tile(key):
        return np.concatenate([d[key]] * repeat)

    return Detections(d["camera_names"], d["marker_names"], frame, tile("camera"), tile("marker"), tile("xy"),
                      tile("score"), d["rate"], n_frames * repeat, source="synth")


def research_way(pixels, projections, threshold_px, min_views=3):
    """DexterCap's published triangulation, for comparison: per point, every pair of views in a
    Python loop, DLT by SVD, the *last* inlier set of at least ``min_views`` kept, DLT on it."""
    out = np.full((pixels.shape[1], 3), np.nan)
    for n in range(pixels.shape[1]):
        seen = np.flatnonzero(~np.isnan(pixels[:, n, 0]))
        kept = None
        for i, j in combinations(seen, 2):
            x = _dlt(pixels[[i, j], n], projections[[i, j]])
            h = projections[seen] @ np.append(x, 1.0)
            error = np.linalg.norm(h[:, :2] / h[:, 2:] - pixels[seen, n], axis=1)
            inliers = seen[error < threshold_px]
            if len(inliers) >= min_views:
                kept = inliers  # the last one wins
        if kept is not None:
            out[n] = _dlt(pixels[kept, n], projections[kept])
    return out


def _dlt(xy, projections):
    rows = np.concatenate([xy[:, :1] * projections[:, 2] - projections[:, 0],
                           xy[:, 1:] * projections[:, 2] - projections[:, 1]])
    h = np.linalg.svd(rows)[2][-1]
    return h[:3] / h[3]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--frames", type=int, default=600, help="frames synthesised (default %(default)s)")
    parser.add_argument("--repeat", type=int, default=4, help="copies of the take for throughput (default %(default)s)")
    parser.add_argument("--research-points", type=int, default=2000)
    parser.add_argument("--break-even", action="store_true", help="run only part 4")
    args = parser.parse_args()
    if args.break_even:
        break_even(args.frames)
        return

    start = time.perf_counter()
    config = SynthConfig(layout="dense-patches", motion="grasp", frames=args.frames, cameras=12, pixel_noise=0.5,
                         outlier_rate=0.02, seed=7)
    capture = synthesize(config, progress=False)
    d, rig, truth = capture.detections, capture.rig, capture.truth["positions"]
    detections = _detections(d, 1, args.frames)
    wrong = d["wrong_id"]
    print(f"capture: {args.frames} frames x {len(d['marker_names'])} markers, {len(rig)} cameras, "
          f"{len(detections)} detections ({wrong.mean():.1%} wrong ids), synthesised in "
          f"{time.perf_counter() - start:.0f} s")
    print(f"  markers seen by >= 3 cameras: {(capture.truth['camera_visible'].sum(axis=1) >= 3).mean():.1%}")

    # 1. Accuracy.
    result = triangulate_detections(detections, rig, workers=1)
    error = np.linalg.norm(result.positions - truth, axis=-1) * 1000
    found = ~np.isnan(error)
    loose = triangulate_detections(detections, rig, workers=1, threshold_px=1e9)
    loose_error = np.linalg.norm(loose.positions - truth, axis=-1) * 1000
    print("\n1. accuracy (12 cameras, 0.5 px, 2 % wrong ids)          handcap    target   no RANSAC")
    print(f"   median 3D error, mm                               {np.median(error[found]):8.3f}   <= 0.5  "
          f"{np.nanmedian(loose_error):9.3f}")
    print(f"   95th percentile 3D error, mm                      {np.percentile(error[found], 95):8.3f}   <= 1.5  "
          f"{np.nanpercentile(loose_error, 95):9.3f}")
    print(f"   mean reprojection error, px                       {np.nanmean(result.error_px):8.3f}   <= 0.7")
    print(f"   wrong ids rejected                                {(~result.used[wrong]).mean():8.2%}   >= 99 %")
    point = detections.frame * len(detections.marker_names) + detections.marker
    on_found = ~np.isnan(result.positions.reshape(-1, 3)[point, 0])
    print(f"   true detections rejected (triangulated markers)   {(~result.used[~wrong & on_found]).mean():8.3%}")
    print(f"   markers triangulated / seen by >= 3 cameras       {found.mean():8.1%} / "
          f"{(capture.truth['camera_visible'].sum(axis=1) >= 3).mean():.1%}")
    print(f"   mean inlier views                                 {result.views[found].mean():8.2f}")

    # 2. The research code's way on a sample of points that have a wrong id among their views.
    rng = np.random.default_rng(0)
    undistorted = np.full((len(rig), args.frames * len(d["marker_names"]), 2), np.nan)
    for c, camera in enumerate(rig):
        rows = d["camera"] == c
        undistorted[c, point[rows]] = camera.undistort_pixels(d["xy"][rows])  # a repeated id: the last row stays
    dirty = np.unique(point[wrong])
    dirty = dirty[(~np.isnan(undistorted[:, dirty, 0])).sum(axis=0) >= 3]
    sample = rng.choice(dirty, min(args.research_points, len(dirty)), replace=False)
    projections = rig.projections
    t0 = time.perf_counter()
    theirs = research_way(undistorted[:, sample], projections, 5.0)
    t_theirs = time.perf_counter() - t0
    t0 = time.perf_counter()
    ours = triangulate_ransac(undistorted[:, sample], projections, min_views=3, threshold_px=5.0).points
    t_ours = time.perf_counter() - t0
    truth_flat = truth.reshape(-1, 3)[sample]
    e_theirs = np.linalg.norm(theirs - truth_flat, axis=1) * 1000
    e_ours = np.linalg.norm(ours - truth_flat, axis=1) * 1000
    print(f"\n2. research way (Python loops, last inlier set) on {len(sample)} points with a wrong id among "
          "their views")
    print(f"   median / 95th pct 3D error, mm: research {np.nanmedian(e_theirs):.3f} / "
          f"{np.nanpercentile(e_theirs, 95):.3f}, handcap {np.nanmedian(e_ours):.3f} / "
          f"{np.nanpercentile(e_ours, 95):.3f}")
    print(f"   time per point: research {1e6 * t_theirs / len(sample):.0f} us, "
          f"handcap {1e6 * t_ours / len(sample):.1f} us ({t_theirs / t_ours:.0f}x)")

    # 3. Throughput on a longer take.
    long = _detections(d, args.repeat, args.frames)
    marker_frames = long.n_frames * len(long.marker_names)
    cores = default_workers()
    print(f"\n3. throughput, {long.n_frames} frames x {len(long.marker_names)} markers = {marker_frames:,} "
          f"marker-frames, RANSAC on, {cores} cores")
    runs = {}
    t0 = time.perf_counter()
    runs["one process"] = triangulate_detections(long, rig, workers=1, progress=False)
    times = {"one process": time.perf_counter() - t0}
    t0 = time.perf_counter()
    runs["process pool"] = triangulate_detections(long, rig, workers=cores, progress=False)
    times["process pool"] = time.perf_counter() - t0
    from distributed import LocalCluster

    with LocalCluster(n_workers=cores, threads_per_worker=1, processes=True, dashboard_address=None) as cluster:
        t0 = time.perf_counter()
        runs["Dask LocalCluster"] = triangulate_detections(long, rig, scheduler=cluster.scheduler_address,
                                                           chunk_frames=-(-long.n_frames // (2 * cores)),
                                                           progress=False)
        times["Dask LocalCluster"] = time.perf_counter() - t0
    for name, seconds in times.items():
        same = all(np.array_equal(getattr(runs[name], key), getattr(runs["one process"], key), equal_nan=True)
                   for key in ("positions", "error_px", "residual")) and np.array_equal(runs[name].used,
                                                                                         runs["one process"].used)
        print(f"   {name:18s} {seconds:6.2f} s  {marker_frames / seconds:9,.0f} marker-frames/s  "
              f"{'identical' if same else 'DIFFERENT'} output")
    print("   target: 50,000 marker-frames/s on 2 cores (pool and cluster times include starting their processes)")

    break_even(args.frames)


def break_even(frames: int, repeats=(1, 2, 4, 8, 16)) -> None:
    """Part 4: one process, the pool on every core, and the default choice, on takes of growing size."""
    from handcap.multiview import reconstruct
    config = SynthConfig(layout="dense-patches", motion="grasp", frames=frames, rate=20.0, cameras=12,
                         pixel_noise=0.5, outlier_rate=0.02, seed=7)
    capture = synthesize(config, progress=False)
    cores = default_workers()
    from handcap.parallel import idle_workers
    print(f"\n4. break-even of the process pool ({cores} cores, {idle_workers()} idle by the load average "
          f"{os.getloadavg()[0]:.1f}; pool start counted); the default pools on the idle cores W above "
          f"{reconstruct.POOL_START_SECONDS:g} s x W/(W-1) of one-process work")
    print("   frames  detections   one process   pool    pool/one   default (chose)")
    chosen = []
    real = reconstruct.pool_workers
    reconstruct.pool_workers = lambda *a, **k: chosen.append(real(*a, **k)) or chosen[-1]
    try:
        for repeat in repeats:
            detections = _detections(capture.detections, repeat, frames)
            times = {}
            for key, options in (("one", {"workers": 1}), ("pool", {"workers": cores}), ("default", {})):
                t0 = time.perf_counter()
                triangulate_detections(detections, capture.rig, progress=False, **options)
                times[key] = time.perf_counter() - t0
            pick = f"{chosen[-1]} worker(s)" if chosen else "1, all timed"
            chosen.clear()
            print(f"   {detections.n_frames:6d}  {len(detections):10,d}   {times['one']:8.2f} s  {times['pool']:6.2f} s"
                  f"   {times['pool'] / times['one']:6.2f}   {times['default']:6.2f} s ({pick})")
    finally:
        reconstruct.pool_workers = real


if __name__ == "__main__":
    main()
