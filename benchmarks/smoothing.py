"""The hand solve's pulls towards the motion's course, on and off: live (``handcap.stream.FrameSolver``, towards the
angles the frames before predict) and batch (step 6 of ``handcap.solve.motion.solve_lm``, towards each frame's
neighbours).

Prints, each measured in this run, for each solver with its pull off and on (its default):

1. The real glove recording (../shared/data/markers/hand_embodiment_glove, 60 s at 100 Hz, 13 markers), calibrated
   on its first 15 s: jerk spikes of the joints, motion signal-to-noise ratio (MSNR), RMS and mean marker residual,
   time (per frame live, the whole solve batch) and the live pull's weight.
2. Thirteen synthetic takes with truth (glove-13, joints-19, dense-patches, tips-5; grasps and random motion;
   30-120 Hz; 10 s each): the joints' median / p99 distance from the truth, jerk spikes and the MRE. The first five
   chose the pulls' strengths, the other eight only checked them (the live choice used the first five and six of
   the others).

    .venv/bin/python benchmarks/smoothing.py [--only live|batch] [--threads 1]
"""

from __future__ import annotations

import argparse
import os
import time
import warnings
from pathlib import Path

GLOVE = Path(__file__).resolve().parents[2] / "shared" / "data" / "markers" / "hand_embodiment_glove" / "recording.tsv"
#: layout, motion, rate (Hz), seed: the five that chose the defaults, then eight held out.
TAKES = [("glove-13", "grasp", 100.0, 1), ("glove-13", "random", 60.0, 2), ("joints-19", "random", 120.0, 4),
         ("joints-19", "grasp", 30.0, 5), ("glove-13", "random", 30.0, 6),
         ("glove-13", "grasp", 60.0, 11), ("joints-19", "random", 100.0, 12), ("glove-13", "random", 120.0, 13),
         ("joints-19", "grasp", 120.0, 14), ("glove-13", "grasp", 30.0, 15), ("joints-19", "random", 30.0, 16),
         ("dense-patches", "grasp", 100.0, 17), ("tips-5", "random", 60.0, 18)]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--only", choices=("live", "batch"), help="one solver only")
    parser.add_argument("--threads", type=int, default=1)
    parser.add_argument("--seconds", type=float, default=10.0, help="length of each synthetic take")
    args = parser.parse_args()
    for var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ.setdefault(var, str(args.threads))
    import numpy as np

    import handcap.solve.motion as motion_module
    from handcap.core.errors import HandcapWarning
    from handcap.hand import OpenHand
    from handcap.quality.metrics import msnr
    from handcap.quality.motion_checks import jerk_spikes
    from handcap.solve import solve_hand
    from handcap.stream.solver import SMOOTHING, FrameSolver
    from handcap.synth.scene import SynthConfig, synthesize

    passes = motion_module.NEIGHBOUR_PASSES

    def live(markers, attachment, on):
        """Joints (T, 21, 3), per-marker residuals, seconds per frame and the pull's weight, streamed frame by
        frame."""
        solver = FrameSolver(attachment, OpenHand(attachment.side), smoothing=SMOOTHING if on else 0.0)
        start = time.perf_counter()
        out = [solver.solve(f) for f in markers.positions]
        seconds = (time.perf_counter() - start) / len(out)
        return np.array([o[0] for o in out]), np.array([o[2] for o in out])[:, None], seconds, solver.weight or 0.0

    def batch(markers, attachment, on):
        """As :func:`live`, solved whole (seconds for the whole solve)."""
        motion_module.NEIGHBOUR_PASSES = passes if on else 0
        start = time.perf_counter()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", HandcapWarning)
            motion = solve_hand(markers, attachment)
        return motion.joints, motion.marker_residuals, time.perf_counter() - start, 0.0

    solvers = {"live": (live, f"smoothing 0 -> {SMOOTHING}", "ms/frame"),
               "batch": (batch, f"step 6 passes 0 -> {passes}", "s")}
    if args.only:
        solvers = {args.only: solvers[args.only]}
    glove = None
    if GLOVE.is_file():
        from handcap.io import read_markers
        from handcap.layouts import load_layout
        from handcap.solve import calibrate_attachment

        layout = load_layout("glove-13")
        take = read_markers(GLOVE).select(layout.names)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", HandcapWarning)
            glove = take, calibrate_attachment(take.frames(0, 1500), layout).attachment
    else:
        print(f"real glove: {GLOVE} is absent (put ../shared beside the checkout); skipped")
    captures = []
    for layout_name, motion_name, rate, seed in TAKES:
        capture = synthesize(SynthConfig(layout=layout_name, motion=motion_name, frames=int(args.seconds * rate),
                                         rate=rate, seed=seed, subject_seed=3), progress=False)
        captures.append((capture.markers.select(list(capture.attachment.marker_names)), capture))
    for name, (solve, what, unit) in solvers.items():
        print(f"== {name} solver, {what} ==")
        if glove is not None:
            take, attachment = glove
            print(f"real glove, {len(take.positions)} frames at {take.rate:g} Hz")
            for on in (False, True):
                joints, residuals, seconds, weight = solve(take, attachment, on)
                rms = np.sqrt(np.nanmean(residuals ** 2, axis=1))
                print(f"  {'on ' if on else 'off'}: jerk spikes {len(jerk_spikes(joints, take.rate)):4d}, MSNR "
                      f"{msnr(joints):6.2f} dB, marker RMS {1000 * np.nanmean(rms):.3f} mm, mean "
                      f"{1000 * np.nanmean(residuals):.3f} mm, {seconds * (1000 if name == 'live' else 1):.3f} "
                      f"{unit}" + (f", weight {weight:.4f} m/rad" if weight else ""))
        print("synthetic takes, joints vs truth median / p99 (jerk spikes; MRE), off -> on")
        for k, ((markers, capture), (layout_name, motion_name, rate, seed)) in enumerate(zip(captures, TAKES)):
            cells = []
            for on in (False, True):
                joints, residuals, _, _ = solve(markers, capture.attachment, on)
                error = np.linalg.norm(joints - capture.hand_motion.joints, axis=-1) * 1000
                cells.append(f"{np.nanmedian(error):.2f} / {np.nanpercentile(error, 99):5.2f} mm "
                             f"({len(jerk_spikes(joints, rate))}; {1000 * np.nanmean(residuals):.3f})")
            role = "chose" if k < 5 else "held out"
            print(f"  {layout_name:13s} {motion_name:6s} {rate:5g} Hz seed {seed:2d} [{role:8s}]: "
                  + "  ->  ".join(cells))


if __name__ == "__main__":
    main()
