"""The DIP-PIP coupling prior where markers see the DIP: at the full weight (0.01 m/rad, as before 2026-12-01)
against ``Priors.seen_coupling_weight`` (0.001), each batch solve (``solve_hand``) measured in this run.

Prints, for each weight:

1. The real glove recording (../shared/data/markers/hand_embodiment_glove, 60 s at 100 Hz, 13 markers), calibrated
   on its first 15 s: jerk spikes of the joints, motion signal-to-noise ratio (MSNR), mean marker residual.
2. The thirteen synthetic takes of ``benchmarks/smoothing.py`` (glove-13, joints-19, dense-patches, tips-5; grasps
   and random motion; 30-120 Hz; 10 s each), solved with their true attachment: the joints' median / p99 distance
   from the truth and the MRE. The synthetic free motion bends each DIP exactly 2/3 of its PIP, as the prior says;
   its grasps close each finger until its phalanges touch the object, which the coupling does not describe.

    .venv/bin/python benchmarks/coupling.py [--weights 0.01,0.001] [--threads 1]
"""

from __future__ import annotations

import argparse
import os
import warnings

from smoothing import GLOVE, TAKES


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--weights", default="0.01,0.001", help="seen_coupling_weight values, m/rad, comma separated")
    parser.add_argument("--threads", type=int, default=1)
    parser.add_argument("--seconds", type=float, default=10.0, help="length of each synthetic take")
    args = parser.parse_args()
    for var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ.setdefault(var, str(args.threads))
    import numpy as np

    from handcap.core.errors import HandcapWarning
    from handcap.quality.metrics import msnr
    from handcap.quality.motion_checks import jerk_spikes
    from handcap.solve import solve_hand
    from handcap.solve.lm import Priors
    from handcap.synth.scene import SynthConfig, synthesize

    weights = [float(w) for w in args.weights.split(",")]
    warnings.simplefilter("ignore", HandcapWarning)
    print(f"seen_coupling_weight {' -> '.join(map(str, weights))} m/rad (coupling_weight where no marker sets the "
          f"DIP: {Priors().coupling_weight})")
    if GLOVE.is_file():
        from handcap.io import read_markers
        from handcap.layouts import load_layout
        from handcap.solve import calibrate_attachment

        layout = load_layout("glove-13")
        take = read_markers(GLOVE).select(layout.names)
        attachment = calibrate_attachment(take.frames(0, 1500), layout).attachment
        print(f"real glove, {len(take.positions)} frames at {take.rate:g} Hz")
        for w in weights:
            motion = solve_hand(take, attachment, priors=Priors(seen_coupling_weight=w))
            residual = 1000 * np.nanmean(motion.marker_residuals)
            print(f"  {w:6g}: jerk spikes {len(jerk_spikes(motion.joints, take.rate)):3d}, MSNR "
                  f"{msnr(motion.joints):5.2f} dB, mean marker residual {residual:.3f} mm", flush=True)
    else:
        print(f"real glove: {GLOVE} is absent (put ../shared beside the checkout); skipped")
    print("synthetic takes, joints vs truth median / p99 (MRE), one column per weight")
    for layout_name, motion_name, rate, seed in TAKES:
        capture = synthesize(SynthConfig(layout=layout_name, motion=motion_name, frames=int(args.seconds * rate),
                                         rate=rate, seed=seed, subject_seed=3), progress=False)
        markers = capture.markers.select(list(capture.attachment.marker_names))
        cells = []
        for w in weights:
            motion = solve_hand(markers, capture.attachment, priors=Priors(seen_coupling_weight=w))
            error = np.linalg.norm(motion.joints - capture.hand_motion.joints, axis=-1) * 1000
            cells.append(f"{np.nanmedian(error):.2f} / {np.nanpercentile(error, 99):5.2f} mm "
                         f"({1000 * np.nanmean(motion.marker_residuals):.3f})")
        print(f"  {layout_name:13s} {motion_name:6s} {rate:5g} Hz seed {seed:2d}: " + "  ->  ".join(cells), flush=True)


if __name__ == "__main__":
    main()
