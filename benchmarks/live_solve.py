"""The live solver (``handcap.stream.FrameSolver``) with and without its pull towards the predicted angles.

Prints, each measured in this run, for ``smoothing`` 0 (each frame from its markers alone) and the default:

1. The real glove recording (../shared/data/markers/hand_embodiment_glove, 60 s at 100 Hz, 13 markers), calibrated
   on its first 15 s, every frame streamed: jerk spikes of the joints, motion signal-to-noise ratio (MSNR), RMS
   marker residual, the pull's weight and the time per frame; the batch solver's spikes and MSNR beside them.
2. Synthetic takes with truth (glove-13 and joints-19, grasps and random motion, 30-120 Hz, 10 s each): the joints'
   median and p99 distance from the truth, and jerk spikes. The first five chose the defaults, the other six only
   checked them.

    .venv/bin/python benchmarks/live_solve.py [--threads 1]
"""

from __future__ import annotations

import argparse
import os
import time
import warnings
from pathlib import Path

GLOVE = Path(__file__).resolve().parents[2] / "shared" / "data" / "markers" / "hand_embodiment_glove" / "recording.tsv"
#: layout, motion, rate (Hz), seed: the five that chose SMOOTHING and DAMPING, then six held out.
TAKES = [("glove-13", "grasp", 100.0, 1), ("glove-13", "random", 60.0, 2), ("joints-19", "random", 120.0, 4),
         ("joints-19", "grasp", 30.0, 5), ("glove-13", "random", 30.0, 6),
         ("glove-13", "grasp", 60.0, 11), ("joints-19", "random", 100.0, 12), ("glove-13", "random", 120.0, 13),
         ("joints-19", "grasp", 120.0, 14), ("glove-13", "grasp", 30.0, 15), ("joints-19", "random", 30.0, 16)]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--threads", type=int, default=1)
    parser.add_argument("--seconds", type=float, default=10.0, help="length of each synthetic take")
    args = parser.parse_args()
    for var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ.setdefault(var, str(args.threads))
    import numpy as np

    from handcap.core.errors import HandcapWarning
    from handcap.hand import OpenHand
    from handcap.quality.metrics import msnr
    from handcap.quality.motion_checks import jerk_spikes
    from handcap.stream.solver import SMOOTHING, FrameSolver
    from handcap.synth.scene import SynthConfig, synthesize

    settings = (0.0, SMOOTHING)

    def streamed(attachment, frames, smoothing):
        solver = FrameSolver(attachment, OpenHand(attachment.side), smoothing=smoothing)
        start = time.perf_counter()
        out = [solver.solve(f) for f in frames]
        per_frame = (time.perf_counter() - start) / len(frames)
        weight = solver.weight or 0.0
        return np.array([o[0] for o in out]), np.array([o[2] for o in out]), per_frame, weight

    if GLOVE.is_file():
        from handcap.io import read_markers
        from handcap.layouts import load_layout
        from handcap.solve import calibrate_attachment, solve_hand

        layout = load_layout("glove-13")
        take = read_markers(GLOVE).select(layout.names)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", HandcapWarning)
            attachment = calibrate_attachment(take.frames(0, 1500), layout).attachment
            batch = solve_hand(take, attachment)
        print(f"real glove, {len(take.positions)} frames at {take.rate:g} Hz (batch solver: "
              f"{len(jerk_spikes(batch.joints, take.rate))} jerk spikes, MSNR {msnr(batch.joints):.2f} dB)")
        for smoothing in settings:
            joints, rms, per_frame, weight = streamed(attachment, take.positions, smoothing)
            print(f"  smoothing {smoothing:<4g} jerk spikes {len(jerk_spikes(joints, take.rate)):4d}, MSNR "
                  f"{msnr(joints):6.2f} dB, marker RMS {1000 * np.nanmean(rms):.3f} mm, weight {weight:.4f} m/rad, "
                  f"{1000 * per_frame:.3f} ms/frame")
    else:
        print(f"real glove: {GLOVE} is absent (put ../shared beside the checkout); skipped")
    print("synthetic takes, joints vs truth median / p99 (jerk spikes), smoothing " + " -> ".join(map(str, settings)))
    for k, (layout_name, motion, rate, seed) in enumerate(TAKES):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", HandcapWarning)
            capture = synthesize(SynthConfig(layout=layout_name, motion=motion, frames=int(args.seconds * rate),
                                             rate=rate, seed=seed, subject_seed=3), progress=False)
        markers = capture.markers.select(list(capture.attachment.marker_names)).positions
        cells = []
        for smoothing in settings:
            joints, _, _, _ = streamed(capture.attachment, markers, smoothing)
            error = np.linalg.norm(joints - capture.hand_motion.joints, axis=-1) * 1000
            cells.append(f"{np.nanmedian(error):.2f} / {np.nanpercentile(error, 99):5.2f} mm "
                         f"({len(jerk_spikes(joints, rate))})")
        role = "chose" if k < 5 else "held out"
        print(f"  {layout_name:9s} {motion:6s} {rate:5g} Hz seed {seed:2d} [{role:8s}]: " + "  ->  ".join(cells))


if __name__ == "__main__":
    main()
