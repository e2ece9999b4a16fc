"""Occluded markers and joint angles: the paper's Tables 3 and 4, and streaming latency.

    .venv/bin/python benchmarks/occlusion.py            # about 11 minutes on 2 cores
    .venv/bin/python benchmarks/occlusion.py --quick    # fewer windows and seeds, shorter training
    .venv/bin/python benchmarks/occlusion.py --skip table3 table4 latency   # issue 14's measure only

1. Table 3 on the real Qualisys glove (13 markers): the marker predictor is trained
   on the first 60 % of the take (no augmentation; offset-consistent pairs, the
   default) and every method is scored on the last 40 %:
   k = 1..4 markers hidden for d = 0.1 .. 2 s, error on the last hidden frame,
   5 seeds. Target: NN at most 0.6 x AC and below LK in every cell. Then a joint
   regressor trained on poses the optimisation solver finds on the first 60 %,
   scored against the solver on the last 40 %.
1c. Issue 14's measure: whole 0.5 s gaps, the error averaged over EVERY hidden frame (not
   the last), k = 1..4, as NN / AC. A model trained on synthetic takes only (no frame of
   the glove), with and without augmentation, and augmented but on single frames (the
   paper's training, before offset-consistent pairs), the shipped model, and the model of 1
   (first 60 % of the take), scored on the same windows of the last 40 %, each with the filler's
   history correction (the network's error over the 2 s before each gap, learned and carried into
   it: ``handcap.occlusion.history``) and without it. Target: NN/AC <= 0.6 for the synthetic-only
   model.
2. Table 4 on synthetic active-9 and glove-13 takes of unseen subjects, with the
   shipped models: end-to-end joint position error; no occlusion <= 5 mm. The
   optimisation solver (``solve_hand`` with the true marker attachment) is scored
   on the same frames for comparison. Then the streaming filler on ``handcap synth``
   captures, whose occlusions come from ray casting against the hand and object.
3. Streaming latency of ``OcclusionFiller.update`` (registration, prediction,
   discontinuity handling, joint regression) for one and two hands on the real
   glove stream with realistic occlusions. Target: p99 under 0.5 ms for one hand.
"""

from __future__ import annotations

import argparse
import gc
import time
from pathlib import Path

import numpy as np

from handcap.io import read_markers
from handcap.occlusion import OcclusionFiller, OcclusionModel, marker_error_table, train_occlusion_model
from handcap.occlusion.augment import NO_AUGMENTATION
from handcap.occlusion.data import PosedTake, simulate_take
from handcap.occlusion.evaluate import COUNTS, DURATIONS, gap_error_table, joint_error_table, joints_from_pose
from handcap.occlusion.filler import MIRROR
from handcap.occlusion.history import HISTORY_S
from handcap.occlusion.train import PAIR_SECONDS

DATA = Path(__file__).resolve().parents[2] / "shared" / "data" / "markers" / "hand_embodiment_glove" / "recording.tsv"
HAND = ("hand_top", "hand_left", "hand_right", "thumb_middle", "thumb_tip", "index_middle", "index_tip",
        "middle_middle", "middle_tip", "ring_middle", "ring_tip", "little_middle", "little_tip")


def grid(title, table, unit=100.0, fmt="{:6.2f}"):
    print(f"\n{title}")
    print("        k  " + " ".join(f"{d:>6g}s" for d in DURATIONS))
    for i, k in enumerate(COUNTS):
        print(f"      {k:3d}  " + " ".join(fmt.format(v * unit) + " " for v in table[i]))


def table3(args):
    markers = read_markers(DATA).select(HAND)
    n = int(0.6 * markers.n_frames)
    train, test = markers.positions[:n], markers.positions[n:]
    print(f"== 1. Table 3, real glove: train frames 0-{n - 1} ({n / markers.rate:.0f} s), "
          f"test {n}-{markers.n_frames - 1} ({(markers.n_frames - n) / markers.rate:.0f} s)")
    start = time.perf_counter()
    # No augmentation: the network has seen this subject and placement.
    model = train_occlusion_model([PosedTake(train, HAND, markers.rate)], "glove-13", seed=0, epochs=args.epochs,
                                  augmentation=NO_AUGMENTATION)
    args.model60 = model
    print(f"trained the marker predictor in {time.perf_counter() - start:.0f} s ({args.epochs} epochs, seed 0)")
    start = time.perf_counter()
    table = marker_error_table(test, markers.rate, model.predictor, seeds=range(args.seeds), windows=args.windows)
    print(f"scored {args.seeds} seeds x {args.windows} windows per cell in {time.perf_counter() - start:.0f} s; "
          "errors in cm (the paper's unit)")
    for name in ("lk", "ma", "ac", "nn", "nn-raw"):
        label = {"nn-raw": "NN without the discontinuity offset"}.get(name, name.upper())
        grid(label, table[name])
    ratio = table["nn"] / table["ac"]
    grid("NN / AC (target <= 0.6)", ratio, unit=1.0)
    grid("NN / LK (target < 1)", table["nn"] / table["lk"], unit=1.0, fmt="{:6.3f}")
    ok = (ratio <= 0.6).all() and (table["nn"] < table["lk"]).all()
    print(f"\nworst NN/AC {ratio.max():.2f}, mean {ratio.mean():.2f}; NN below LK everywhere: "
          f"{(table['nn'] < table['lk']).all()} -> {'PASS' if ok else 'FAIL'}")
    real_poses(args, markers, model, n)
    return ok


def whole_gaps(args, model60=None):
    """Issue 14: every hidden frame of 0.5 s gaps; synthetic-only training against the take's own 60 %."""
    from handcap.occlusion.augment import SUBJECT_AUGMENTATION
    from handcap.occlusion.data import synthetic_hand_takes

    markers = read_markers(DATA).select(HAND)
    n = int(0.6 * markers.n_frames)
    test = markers.positions[n:]
    print(f"\n== 1c. issue 14: whole 0.5 s gaps of the real glove, error over every hidden frame, frames {n}-"
          f"{markers.n_frames - 1}; {args.seeds} seeds x {args.windows} windows per k")
    start = time.perf_counter()
    synthetic = synthetic_hand_takes("glove-13", subjects=args.gap_subjects, seconds_per_motion=6.0, seed=0)
    print(f"{len(synthetic)} synthetic takes ({sum(len(t.positions) for t in synthetic)} frames) in "
          f"{time.perf_counter() - start:.0f} s")
    models = {}
    for label, augmentation, pairs in (("synthetic only, augmented", SUBJECT_AUGMENTATION, PAIR_SECONDS),
                                       ("synthetic only, not augmented", NO_AUGMENTATION, PAIR_SECONDS),
                                       ("synthetic only, augmented, single frames", SUBJECT_AUGMENTATION, 0.0)):
        start = time.perf_counter()
        models[label] = train_occlusion_model(synthetic, "glove-13", seed=0, epochs=args.gap_epochs,
                                              regressor_epochs=0, augmentation=augmentation, pair_seconds=pairs)
        info = models[label].info
        print(f"trained '{label}' in {time.perf_counter() - start:.0f} s: {info['takes']} takes of "
              f"{info['subjects']} subjects, {info['frames']} frames + {info['augmented_copies']} copies "
              f"({info['augmented_frames']} frames); augmentation: {info['augmentation']}")
    models["shipped glove-13"] = OcclusionModel.shipped("glove-13")
    if model60 is None:
        model60 = train_occlusion_model([PosedTake(markers.positions[:n], HAND, markers.rate)], "glove-13", seed=0,
                                        epochs=args.epochs, augmentation=NO_AUGMENTATION)
    own = "first 60 % of this take (Table 3's)"
    models[own] = model60
    print(f"\n{'model (NN with the history correction unless said)':58s} " + " ".join(f"k={k:<5d}" for k in COUNTS)
          + "  mean   NN mm   AC mm")
    ratios, alone = {}, {}
    for label, model in models.items():
        for history_s, kind in ((HISTORY_S, ""), (0.0, " (network alone)")):
            table = gap_error_table(test, markers.rate, model.predictor, methods=("ac", "nn"),
                                    seeds=range(args.seeds), windows=args.windows, history_s=history_s)
            ratio = table["nn"] / table["ac"]
            (alone if kind else ratios)[label] = ratio.mean()
            print(f"{label + kind:58s} " + " ".join(f"{r:7.3f}" for r in ratio) + f"  {ratio.mean():5.3f}  "
                  f"{1000 * table['nn'].mean():6.3f}  {1000 * table['ac'].mean():6.3f}")
    key = "synthetic only, augmented"
    ok = ratios[key] <= 0.6
    print(f"\nNN/AC over every frame of 0.5 s gaps, synthetic-only training, with the filler's {HISTORY_S:g} s history "
          f"correction: {ratios[key]:.3f} (network alone {alone[key]:.3f}; not augmented "
          f"{ratios['synthetic only, not augmented']:.3f}; on single frames "
          f"{ratios['synthetic only, augmented, single frames']:.3f}; trained on the take's first 60 %: "
          f"{ratios[own]:.3f}, network alone {alone[own]:.3f}); target <= 0.6 -> {'PASS' if ok else 'FAIL'}")
    return ok


def real_poses(args, markers, model, n):
    """The joint regressor trained on poses solved from the real recording, against the solver."""
    from handcap.hand import OpenHand
    from handcap.layouts import load_layout
    from handcap.occlusion.regressor import train_joint_regressor
    from handcap.solve import calibrate_attachment, solve_hand

    print("\n== 1b. joint regressor on the real glove, trained on poses solved by the optimisation solver")
    hand = OpenHand("right")
    start = time.perf_counter()
    attachment = calibrate_attachment(markers, load_layout("glove-13"), hand, frames=slice(0, 1000),
                                      fit_shape=True).attachment
    solved = solve_hand(markers, attachment, hand, progress=False)
    seconds = time.perf_counter() - start
    print(f"calibrated the attachment on frames 0-999 and solved all {markers.n_frames} frames in {seconds:.0f} s "
          f"({markers.n_frames / seconds:.0f} frames/s with the calibration)")
    train = slice(0, n)
    regressor = train_joint_regressor(markers.positions[train], solved.phi[train], solved.global_orient[train],
                                      solved.transl[train], HAND, template=model.predictor.template,
                                      weights=model.predictor.weights, seed=0, epochs=args.epochs)
    both = OcclusionModel(model.predictor, regressor, "right", "glove-13")
    test = slice(n, None)
    take = PosedTake(markers.positions[test], HAND, markers.rate, solved.phi[test], solved.global_orient[test],
                     solved.transl[test], attachment.betas, solved.joints[test])
    table = joint_error_table([take], both, seeds=range(args.seeds), windows=args.windows // 2)
    print(f"test part, no occlusion: joint regressor vs solver {1000 * table['none_all']:.2f} mm over all 21 joints, "
          f"{1000 * table['none_fingers']:.2f} mm over the finger joints")
    grid("all 21 joints vs the solver (mm), k markers hidden for d s (the solver sees them all)", table["all"],
         unit=1000.0)


def table4(args):
    from handcap.core.markers import MarkerSequence
    from handcap.solve import solve_hand

    print("\n== 2. Table 4, synthetic takes of unseen subjects, shipped models; errors in mm")
    ok = True
    for layout in ("active-9", "glove-13"):
        model = OcclusionModel.shipped(layout)
        takes = [simulate_take(layout, motion, args.synthetic_frames, 100.0, 70_000 + i)
                 for i, motion in enumerate(("random", "grasp", "precision", "open-close"))]
        start = time.perf_counter()
        table = joint_error_table(takes, model, seeds=range(args.seeds), windows=args.windows // 4)
        print(f"\n{layout}: {len(takes)} takes x {args.synthetic_frames} frames, {time.perf_counter() - start:.0f} s")
        print(f"no occlusion: finger joints (the paper's p1-p3) {1000 * table['none_fingers']:.2f} mm, "
              f"all 21 joints {1000 * table['none_all']:.2f} mm (target <= 5 mm)")
        grid("finger joints, k hidden for d s", table["fingers"], unit=1000.0)
        grid("all 21 joints", table["all"], unit=1000.0)
        ok &= table["none_all"] <= 0.005
        # The optimisation solver on the first take (no occlusion), with the true marker attachment.
        take = takes[0]
        frames = slice(0, min(300, len(take.positions)))
        start = time.perf_counter()
        solved = solve_hand(MarkerSequence(take.positions[frames], take.names, take.rate), take.attachment,
                            progress=False)
        seconds = time.perf_counter() - start
        solver_error = np.linalg.norm(solved.joints - take.joints[frames], axis=-1).mean()
        phi, orient, transl = model.regressor.predict(take.positions[frames])
        nn_error = np.linalg.norm(joints_from_pose(phi, orient, transl, take.betas, "right") - take.joints[frames],
                                  axis=-1).mean()
        print(f"first {frames.stop} frames of the 'random' take: optimisation solver {1000 * solver_error:.2f} mm "
              f"({frames.stop / seconds:.0f} frames/s), joint regressor {1000 * nn_error:.2f} mm")
    return ok


def synthetic_captures(args):
    """The whole streaming pipeline on ``handcap synth`` captures: occlusions come from ray casting.

    Seed 9001: its subject is none of the training subjects (seeds 0-53 of the shipped build).
    """
    from handcap.synth.scene import SynthConfig, synthesize

    print("\n== 2b. streaming on synthetic captures (cameras, ray-cast occlusion by hand and object, dropouts), "
          "shipped models; errors in mm")
    for layout in ("active-9", "glove-13"):
        model = OcclusionModel.shipped(layout)
        capture = synthesize(SynthConfig(layout=layout, motion="grasp", frames=args.capture_frames, seed=9001,
                                         cameras=8, ghost_rate=0.0, swap_rate=0.0), progress=False)
        markers = capture.markers.select(model.names).positions
        truth = capture.hand_motion.joints
        filler = OcclusionFiller(model, rate=capture.markers.rate)
        errors, hidden, lost = [], [], 0
        for t, frame in enumerate(markers):
            out = filler.update(frame)
            if out.lost:
                lost += 1
                continue
            joints = joints_from_pose(out.phi, out.global_orient, out.transl, capture.hand_motion.betas, "right")
            errors.append(np.linalg.norm(joints - truth[t], axis=-1).mean())
            hidden.append(out.filled.sum())
        errors, hidden = np.array(errors), np.array(hidden)
        missing = np.isnan(markers[..., 0]).mean()
        print(f"{layout}: {len(markers)} frames of a grasp, 8 cameras, {100 * missing:.1f} % of marker samples "
              f"missing, {lost} frames lost; joint error {1000 * errors.mean():.2f} mm "
              f"(all seen {1000 * errors[hidden == 0].mean():.2f} mm in {np.sum(hidden == 0)} frames, "
              f"some filled {1000 * errors[hidden > 0].mean():.2f} mm in {np.sum(hidden > 0)} frames)")


def realistic_occlusions(n, m, rate, rng, fraction=0.05):
    """Occlusion runs per marker: about ``fraction`` of the samples hidden, durations log-normal with
    median 0.1 s (90 % under about 0.35 s, the paper's Fig. 13)."""
    hidden = np.zeros((n, m), bool)
    mean = 0.1 * np.exp(0.9 ** 2 / 2) * rate
    p = fraction / mean
    for j in range(m):
        t = 0
        while t < n:
            if rng.random() < p:
                d = max(1, int(round(rate * rng.lognormal(np.log(0.1), 0.9))))
                hidden[t:t + d, j] = True
                t += d
            t += 1
    return hidden


def latency(args):
    print("\n== 3. Streaming latency of OcclusionFiller.update (shipped glove-13 model: registration, "
          "autoencoder, discontinuity offsets, re-entry, joint regression)")
    markers = read_markers(DATA).select(HAND)
    test = markers.positions[int(0.6 * markers.n_frames):]
    hidden = realistic_occlusions(len(test), len(HAND), markers.rate, np.random.default_rng(0))
    stream = test.copy()
    stream[hidden] = np.nan
    changes = np.diff(np.isnan(stream[..., 0]), axis=0).any(axis=1).mean()
    print(f"stream: {len(stream)} frames, {100 * np.isnan(stream[..., 0]).mean():.1f} % of samples occluded, "
          f"visible set changes in {100 * changes:.1f} % of frames; {args.passes} passes, garbage collector "
          "paused while timing (as a real-time loop would)")
    model = OcclusionModel.shipped("glove-13")
    results = {}
    for hands, history_s in ((1, HISTORY_S), (2, HISTORY_S), (1, 0.0)):
        filler = OcclusionFiller(model, rate=markers.rate, hands=("right", "left")[:hands], history_s=history_s)
        frames = stream if hands == 1 else np.stack([stream, stream * MIRROR], axis=1)
        times, p99s = [], []
        for _ in range(args.passes):
            filler.reset()
            gc.collect()
            gc.disable()
            try:
                one = np.empty(len(frames))
                for t, frame in enumerate(frames):
                    t0 = time.perf_counter()
                    filler.update(frame)
                    one[t] = time.perf_counter() - t0
            finally:
                gc.enable()
            times.append(one)
            p99s.append(np.percentile(one, 99))
        all_times = np.concatenate(times) * 1000
        p50, p99 = np.percentile(all_times, [50, 99])
        results[hands, history_s] = p99
        print(f"{hands} hand{'s' if hands > 1 else ' '}{'' if history_s else ', no history correction'}: p50 "
              f"{p50:.3f} ms, p99 {p99:.3f} ms (per pass "
              f"{1000 * min(p99s):.3f}-{1000 * max(p99s):.3f}), max {all_times.max():.2f} ms, "
              f"{1000 / p50:.0f} frames/s at the median; the paper's C# pipeline: 1.2 ms (one hand)")
    ok = results[1, HISTORY_S] < 0.5
    print(f"one hand p99 {results[1, HISTORY_S]:.3f} ms (target < 0.5 ms) -> {'PASS' if ok else 'FAIL'}")
    return ok


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="fewer windows, seeds and epochs")
    parser.add_argument("--skip", nargs="*", default=(), choices=("table3", "gaps", "table4", "latency"))
    args = parser.parse_args()
    args.seeds = 2 if args.quick else 5
    args.windows = 200 if args.quick else 500
    args.epochs = 20 if args.quick else 60
    args.synthetic_frames = 1000 if args.quick else 2000
    args.passes = 2 if args.quick else 5
    args.capture_frames = 400 if args.quick else 1000
    args.gap_subjects = 3 if args.quick else 6
    args.gap_epochs = 20 if args.quick else 40
    args.model60 = None
    verdicts = {}
    if "table3" not in args.skip:
        verdicts["table 3 (real glove)"] = table3(args)
    if "gaps" not in args.skip:
        verdicts["issue 14: NN/AC <= 0.6, every frame of 0.5 s gaps, synthetic-only training"] = whole_gaps(
            args, args.model60)
    if "table4" not in args.skip:
        verdicts["table 4 (synthetic, <= 5 mm)"] = table4(args)
        synthetic_captures(args)
    if "latency" not in args.skip:
        verdicts["latency (p99 < 0.5 ms)"] = latency(args)
    print("\n" + "\n".join(f"{k}: {'PASS' if v else 'FAIL'}" for k, v in verdicts.items()))


if __name__ == "__main__":
    main()
