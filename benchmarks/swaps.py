"""Label swaps found by the solved hand (``handcap.solve.swaps``): each solve with and without ``mend_swaps``,
measured in this run.

Prints:

1. The real glove recording (../shared/data/markers/hand_embodiment_glove, 60 s at 100 Hz, 13 markers), calibrated
   on its first 15 s: the swaps found (none expected: its labels are right, though its markers stray up to 16 mm
   from the fitted hand) and the solve's time either way.
2. The thirteen synthetic takes of ``benchmarks/smoothing.py`` (glove-13, joints-19, dense-patches, tips-5; grasps
   and random motion; 30-120 Hz; 10 s each; ``synth`` swaps two labels now and then, 0.1 a second), solved with
   their true attachment: the swaps synth made (frames first-last, marker numbers) against those found, the
   joints' median / p99 distance from the truth and the time, labels as given -> swaps mended.

    .venv/bin/python benchmarks/swaps.py [--threads 1]
"""

from __future__ import annotations

import argparse
import os
import time
import warnings

from smoothing import GLOVE, TAKES


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--threads", type=int, default=1)
    parser.add_argument("--seconds", type=float, default=10.0, help="length of each synthetic take")
    args = parser.parse_args()
    for var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ.setdefault(var, str(args.threads))
    import numpy as np

    from handcap.core.errors import HandcapWarning
    from handcap.solve import solve_hand
    from handcap.synth.scene import SynthConfig, synthesize

    warnings.simplefilter("ignore", HandcapWarning)

    def solved(markers, attachment, mend):
        start = time.perf_counter()
        motion = solve_hand(markers, attachment, mend_swaps=mend)
        return motion, time.perf_counter() - start

    def found(motion):
        return [w.split(": ", 1)[1].split("; the input file")[0] for w in motion.warnings if "label swap" in w]

    if GLOVE.is_file():
        from handcap.io import read_markers
        from handcap.layouts import load_layout
        from handcap.solve import calibrate_attachment

        layout = load_layout("glove-13")
        take = read_markers(GLOVE).select(layout.names)
        attachment = calibrate_attachment(take.frames(0, 1500), layout).attachment
        (_, plain), (motion, mended) = (solved(take, attachment, mend) for mend in (False, True))
        far = np.nanmax(motion.marker_residuals) * 1000
        print(f"real glove, {len(take.positions)} frames: swaps found {found(motion) or 'none'} (markers up to "
              f"{far:.1f} mm from the fitted hand); {plain:.2f} s -> {mended:.2f} s ({mended / plain:.2f} x)")
    else:
        print(f"real glove: {GLOVE} is absent (put ../shared beside the checkout); skipped")
    print("synthetic takes: swaps made (first, end, markers) / found; joints vs truth median / p99, time: "
          "labels as given -> swaps mended")
    made = hits = extra = 0
    for layout_name, motion_name, rate, seed in TAKES:
        capture = synthesize(SynthConfig(layout=layout_name, motion=motion_name, frames=int(args.seconds * rate),
                                         rate=rate, seed=seed, subject_seed=3), progress=False)
        markers = capture.markers.select(list(capture.attachment.marker_names))
        cells = []
        for mend in (False, True):
            motion, seconds = solved(markers, capture.attachment, mend)
            error = np.linalg.norm(motion.joints - capture.hand_motion.joints, axis=-1) * 1000
            cells.append(f"{np.nanmedian(error):.2f} / {np.nanpercentile(error, 99):5.2f} mm {seconds:5.2f} s")
        names = capture.truth["names"]
        truth = [f"{names[min(i, j)]} and {names[max(i, j)]} in frames {first}-{end - 1}"
                 for first, end, i, j in capture.truth["swaps"]]
        told = found(motion)
        made += len(truth)
        hits += sum(any(t in w for w in told) for t in truth)
        extra += sum(w.count(" in frames ") for w in told) - sum(any(t in w for w in told) for t in truth)
        print(f"  {layout_name:13s} {motion_name:6s} {rate:5g} Hz seed {seed:2d}: " + "  ->  ".join(cells))
        print(f"      made: {'; '.join(truth) or 'none'}\n      found: {'; '.join(told) or 'none'}", flush=True)
    print(f"swaps found where synth made them: {hits} of {made}; found where it made none: {extra}")


if __name__ == "__main__":
    main()
