"""Frames per second of OpenHand forward kinematics and skinning (numpy and torch).

Batch of 1,000 random poses within the joint limits, random shape and wrist.
Targets (issue 2, on 2 cores): >= 20,000 frames/s for joints only and
>= 2,000 frames/s with full mesh skinning. Prints the measured rates and their
ratios to the targets; also checks that numpy and torch agree on this batch.

    .venv/bin/python benchmarks/hand_forward.py [--frames 1000] [--repeats 7] [--threads 2]
"""

from __future__ import annotations

import argparse
import os
import time


def best_rate(fn, frames: int, repeats: int) -> float:
    fn()  # warm up
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        fn()
        times.append(time.perf_counter() - start)
    return frames / min(times)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--frames", type=int, default=1000)
    parser.add_argument("--repeats", type=int, default=7)
    parser.add_argument("--threads", type=int, default=2, help="threads for BLAS and torch (default 2)")
    args = parser.parse_args()
    for var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
        os.environ.setdefault(var, str(args.threads))

    import numpy as np
    import torch

    from handcap.hand import PHI_LIMITS, OpenHand

    torch.set_num_threads(args.threads)
    hand = OpenHand()
    rng = np.random.default_rng(0)
    n = args.frames
    phi = rng.uniform(PHI_LIMITS[:, 0], PHI_LIMITS[:, 1], size=(n, 27))
    hand_pose = hand.hand_pose_from_phi(phi)
    orient, transl = rng.normal(size=(n, 3)), rng.normal(scale=0.2, size=(n, 3))
    betas = rng.normal(size=10)
    t = {k: torch.tensor(v) for k, v in dict(betas=betas, orient=orient, hand_pose=hand_pose, transl=transl).items()}
    t32 = {k: v.float() for k, v in t.items()}

    def np_run(vertices):
        return lambda: hand.forward(betas, orient, hand_pose, transl, vertices=vertices)

    def torch_run(d, vertices):
        def run():
            with torch.no_grad():
                return hand.forward(d["betas"], d["orient"], d["hand_pose"], d["transl"], vertices=vertices)
        return run

    ref = np_run(True)()
    out = torch_run(t, True)()
    agree = float(np.abs(out.vertices.numpy() - ref.vertices).max())
    print(f"OpenHand: {hand.n_vertices} vertices, {len(hand.faces)} faces; batch of {n} frames, "
          f"{args.threads} threads; numpy vs torch max difference {agree:.2e} m")
    print(f"{'path':34s} {'frames/s':>12s} {'target':>8s} {'ratio':>7s}")
    rows = [("numpy float64, joints only", np_run(False), 20000),
            ("torch float64, joints only", torch_run(t, False), 20000),
            ("torch float32, joints only", torch_run(t32, False), 20000),
            ("numpy float64, mesh skinning", np_run(True), 2000),
            ("torch float64, mesh skinning", torch_run(t, True), 2000),
            ("torch float32, mesh skinning", torch_run(t32, True), 2000)]
    for name, fn, target in rows:
        rate = best_rate(fn, n, args.repeats)
        print(f"{name:34s} {rate:12,.0f} {target:8,d} {rate / target:7.2f}x")


if __name__ == "__main__":
    main()
