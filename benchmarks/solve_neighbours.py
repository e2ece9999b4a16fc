"""Step 6 of the batch solve (``handcap.solve.motion``: every frame pulled towards its neighbours) on and off.

Prints, each measured in this run, for ``NEIGHBOUR_PASSES`` 0 and the default:

1. The real glove recording (../shared/data/markers/hand_embodiment_glove, 60 s at 100 Hz, 13 markers), calibrated
   on its first 15 s and solved whole: jerk spikes of the joints, MSNR, RMS and mean marker residual, solve time.
2. Thirteen synthetic takes with truth (glove-13, joints-19, dense-patches, tips-5; grasps and random motion;
   30-120 Hz; 10 s each): the joints' median / p99 distance from the truth, jerk spikes and MRE. The first five
   chose the pull's strength and the passes, the other eight only checked them.

    .venv/bin/python benchmarks/solve_neighbours.py [--threads 1]
"""

from __future__ import annotations

import argparse
import os
import time
import warnings
from pathlib import Path

GLOVE = Path(__file__).resolve().parents[2] / "shared" / "data" / "markers" / "hand_embodiment_glove" / "recording.tsv"
#: layout, motion, rate (Hz), seed: the five that chose NEIGHBOUR_PULL and NEIGHBOUR_PASSES, then eight held out.
TAKES = [("glove-13", "grasp", 100.0, 1), ("glove-13", "random", 60.0, 2), ("joints-19", "random", 120.0, 4),
         ("joints-19", "grasp", 30.0, 5), ("glove-13", "random", 30.0, 6),
         ("glove-13", "grasp", 60.0, 11), ("joints-19", "random", 100.0, 12), ("glove-13", "random", 120.0, 13),
         ("joints-19", "grasp", 120.0, 14), ("glove-13", "grasp", 30.0, 15), ("joints-19", "random", 30.0, 16),
         ("dense-patches", "grasp", 100.0, 17), ("tips-5", "random", 60.0, 18)]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--threads", type=int, default=1)
    parser.add_argument("--seconds", type=float, default=10.0, help="length of each synthetic take")
    args = parser.parse_args()
    for var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ.setdefault(var, str(args.threads))
    import numpy as np

    import handcap.solve.motion as motion_module
    from handcap.core.errors import HandcapWarning
    from handcap.quality.metrics import msnr
    from handcap.quality.motion_checks import jerk_spikes
    from handcap.solve import solve_hand
    from handcap.synth.scene import SynthConfig, synthesize

    settings = (0, motion_module.NEIGHBOUR_PASSES)

    def solved(take, attachment, passes):
        motion_module.NEIGHBOUR_PASSES = passes
        start = time.perf_counter()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", HandcapWarning)
            motion = solve_hand(take, attachment)
        return motion, time.perf_counter() - start

    if GLOVE.is_file():
        from handcap.io import read_markers
        from handcap.layouts import load_layout
        from handcap.solve import calibrate_attachment

        layout = load_layout("glove-13")
        take = read_markers(GLOVE).select(layout.names)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", HandcapWarning)
            attachment = calibrate_attachment(take.frames(0, 1500), layout).attachment
        print(f"real glove, {len(take.positions)} frames at {take.rate:g} Hz")
        for passes in settings:
            motion, seconds = solved(take, attachment, passes)
            rms = np.sqrt(np.nanmean(motion.marker_residuals ** 2, axis=1))
            print(f"  passes {passes}: jerk spikes {len(jerk_spikes(motion.joints, take.rate)):3d}, MSNR "
                  f"{msnr(motion.joints):5.2f} dB, marker RMS {1000 * np.nanmean(rms):.3f} mm, mean "
                  f"{1000 * np.nanmean(motion.marker_residuals):.3f} mm, solve {seconds:.2f} s")
    else:
        print(f"real glove: {GLOVE} is absent (put ../shared beside the checkout); skipped")
    print("synthetic takes, joints vs truth median / p99 (jerk spikes; MRE), passes " + " -> ".join(map(str, settings)))
    for k, (layout_name, motion_name, rate, seed) in enumerate(TAKES):
        capture = synthesize(SynthConfig(layout=layout_name, motion=motion_name, frames=int(args.seconds * rate),
                                         rate=rate, seed=seed, subject_seed=3), progress=False)
        markers = capture.markers.select(list(capture.attachment.marker_names))
        cells = []
        for passes in settings:
            motion, _ = solved(markers, capture.attachment, passes)
            error = np.linalg.norm(motion.joints - capture.hand_motion.joints, axis=-1) * 1000
            cells.append(f"{np.nanmedian(error):.2f} / {np.nanpercentile(error, 99):5.2f} mm "
                         f"({len(jerk_spikes(motion.joints, rate))}; {1000 * np.nanmean(motion.marker_residuals):.3f})")
        role = "chose" if k < 5 else "held out"
        print(f"  {layout_name:13s} {motion_name:6s} {rate:5g} Hz seed {seed:2d} [{role:8s}]: " + "  ->  ".join(cells))


if __name__ == "__main__":
    main()
