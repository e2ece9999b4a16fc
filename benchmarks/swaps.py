"""Label swaps found by the solved hand (``handcap.solve.swaps``): each solve with and without ``mend_swaps``,
measured in this run.

Prints:

1. The real glove recording (../shared/data/markers/hand_embodiment_glove, 60 s at 100 Hz, 13 markers), calibrated
   on its first 15 s: the swaps found (none expected: its labels are right, though its markers stray up to 16 mm
   from the fitted hand) and the solve's time either way.
2. The thirteen synthetic takes of ``benchmarks/smoothing.py`` (glove-13, joints-19, dense-patches, tips-5; grasps
   and random motion; 30-120 Hz; 10 s each; ``synth`` swaps two labels now and then, 0.1 a second), solved with
   their true attachment: the swaps synth made (frames first-last, marker numbers) against those found, the
   joints' median / p99 distance from the truth and the time, labels as given -> swaps mended; in the takes with
   index, middle and ring fingertips, the same with three of their labels made to go round a cycle for 0.3 s in the
   middle of the take (index_tip's marker labelled middle_tip, middle_tip's ring_tip, ring_tip's index_tip).
3. The same, live (``handcap.stream.FrameSolver``, each frame judged on its own): on the real glove the changes of
   labels found (none expected) and the p50 / p99 time of a frame; on each synthetic take the changes found (the
   frame a swap starts and the frame after its last) and the joints' median / p99 distance from the truth and the
   p99 time of a frame, labels as given -> swaps mended; then the made-up cycles of section 2, streamed: the changes
   found and the worst joint's distance from the truth in the cycle's frames, labels as given -> mended.
4. The live pipeline with the labeller in the loop (``handcap.stream.LivePipeline``: label, fill, solve), on the take
   of ``benchmarks/stream.py`` (joints-19, 120 Hz, 20 s, its points unlabelled; the labelling model trained on
   another take of the subject): the labels wrong against the truth as the labeller gave them and as the solve read
   them, the changes found and the joints' p99 distance from the truth, labels as given -> swaps mended.

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
    from handcap.core.markers import MarkerSequence
    from handcap.hand import OpenHand
    from handcap.solve import solve_hand
    from handcap.stream.solver import FrameSolver
    from handcap.synth.scene import SynthConfig, synthesize

    warnings.simplefilter("ignore", HandcapWarning)

    def solved(markers, attachment, mend):
        start = time.perf_counter()
        motion = solve_hand(markers, attachment, mend_swaps=mend)
        return motion, time.perf_counter() - start

    def live(markers, attachment, mend):
        """Joints (T, 21, 3) streamed frame by frame, each frame's milliseconds, and the solver."""
        solver = FrameSolver(attachment, OpenHand(attachment.side), mend_swaps=mend)
        joints, ms = [], []
        for frame in markers.positions:
            start = time.perf_counter()
            joints.append(solver.solve(frame)[0])
            ms.append(1000 * (time.perf_counter() - start))
        return np.array(joints), np.array(ms), solver

    def changes(solver):
        return "; ".join(f"{solver.named(s)} {'back ' if s.back else ''}at {s.frame}" for s in solver.swaps) or "none"

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
        glove = [live(take, attachment, mend) for mend in (False, True)]
    else:
        print(f"real glove: {GLOVE} is absent (put ../shared beside the checkout); skipped")
    print("synthetic takes: swaps made (first, end, markers) / found; joints vs truth median / p99, time: "
          "labels as given -> swaps mended")
    made = hits = extra = 0
    cycles = [0, 0]  # made up, found
    lines = []  # section 3's
    live_cycles = []  # section 3's made-up cycles: (line, found at its first frame and back after its last)
    for layout_name, motion_name, rate, seed in TAKES:
        capture = synthesize(SynthConfig(layout=layout_name, motion=motion_name, frames=int(args.seconds * rate),
                                         rate=rate, seed=seed, subject_seed=3), progress=False)
        markers = capture.markers.select(list(capture.attachment.marker_names))
        cells = []
        for mend in (False, True):
            motion, seconds = solved(markers, capture.attachment, mend)
            error = np.linalg.norm(motion.joints - capture.hand_motion.joints, axis=-1) * 1000
            cells.append(f"{np.nanmedian(error):.2f} / {np.nanpercentile(error, 99):5.2f} mm {seconds:5.2f} s")
        names = list(capture.truth["names"])
        truth = [f"{names[min(i, j)]} and {names[max(i, j)]} in frames {first}-{end - 1}"
                 for first, end, i, j in capture.truth["swaps"]]
        told = found(motion)
        made += len(truth)
        hits += sum(any(t in w for w in told) for t in truth)
        extra += sum(w.count(" in frames ") for w in told) - sum(any(t in w for w in told) for t in truth)
        print(f"  {layout_name:13s} {motion_name:6s} {rate:5g} Hz seed {seed:2d}: " + "  ->  ".join(cells))
        print(f"      made: {'; '.join(truth) or 'none'}\n      found: {'; '.join(told) or 'none'}", flush=True)
        tips = [names.index(n) for n in ("index_tip", "middle_tip", "ring_tip") if n in names]
        if len(tips) == 3:  # a cycle of three fingertip labels made up in 0.3 s from the middle of the take
            span = slice(len(markers.positions) // 2, len(markers.positions) // 2 + int(0.3 * rate))
            positions = markers.positions.copy()
            i, m, r = (list(markers.names).index(names[k]) for k in tips)
            positions[span, [m, r, i]] = markers.positions[span][:, [i, m, r]]
            cycled = MarkerSequence(positions, markers.names, markers.rate)
            cells = []
            for mend in (False, True):
                motion, seconds = solved(cycled, capture.attachment, mend)
                error = np.linalg.norm(motion.joints - capture.hand_motion.joints, axis=-1) * 1000
                cells.append(f"{np.nanpercentile(error, 99):5.2f} mm {seconds:5.2f} s")
            cycle = f"in frames {span.start}-{span.stop - 1}"
            told = [w for w in found(motion) if "round a cycle" in w]
            cycles[0] += 1
            cycles[1] += any(cycle in w and "index_tip read from middle_tip's label" in w for w in told)
            print(f"      a made-up cycle of index_tip, middle_tip and ring_tip {cycle}: p99 {cells[0]} -> {cells[1]};"
                  f" found: {'; '.join(told) or 'none'}", flush=True)
            worst = []
            for mend in (False, True):
                joints, _, solver = live(cycled, capture.attachment, mend)
                worst.append(np.nanmax(np.linalg.norm(joints[span] - capture.hand_motion.joints[span], axis=-1)) * 1000)
            hit = [(s.frame, s.back) for s in solver.swaps if s.c >= 0] == [(span.start, False), (span.stop, True)]
            live_cycles.append((f"  {layout_name:13s} {motion_name:6s} {rate:5g} Hz seed {seed:2d}: the cycle {cycle}, "
                                f"worst joint there {worst[0]:5.1f} -> {worst[1]:5.1f} mm; found: {changes(solver)}",
                                hit))
        cells = []
        for mend in (False, True):
            joints, ms, solver = live(markers, capture.attachment, mend)
            error = np.linalg.norm(joints - capture.hand_motion.joints, axis=-1) * 1000
            cells.append(f"{np.nanmedian(error):.2f} / {np.nanpercentile(error, 99):5.2f} mm p99 "
                         f"{np.percentile(ms, 99):.2f} ms")
        events = [(int(first), names[min(i, j)], names[max(i, j)]) for first, _, i, j in capture.truth["swaps"]] + [
            (int(end), names[min(i, j)], names[max(i, j)]) for _, end, i, j in capture.truth["swaps"]]
        got = [(s.frame, *sorted((solver.names[s.a], solver.names[s.b]), key=names.index)) for s in solver.swaps]
        lines.append((f"  {layout_name:13s} {motion_name:6s} {rate:5g} Hz seed {seed:2d}: " + "  ->  ".join(cells),
                      f"      found: {changes(solver)}", len(events), len(set(events) & set(got)),
                      len(set(got) - set(events))))
    print(f"swaps found where synth made them: {hits} of {made}; found where it made none: {extra}; made-up cycles "
          f"of three found: {cycles[1]} of {cycles[0]}")
    print("\n== 3. live (FrameSolver), labels as given -> swaps mended ==")
    if GLOVE.is_file():
        for mend, (_, ms, solver) in zip((False, True), glove):
            print(f"real glove, {'mended' if mend else 'as given'}: changes {changes(solver)}; a frame p50 "
                  f"{np.percentile(ms, 50):.3f} ms, p99 {np.percentile(ms, 99):.3f} ms")
    print("synthetic takes: joints vs truth median / p99 and a frame's p99 time; the changes of labels found "
          "(a swap's first frame, and back at the frame after its last)")
    for line, listed, *_ in lines:
        print(f"{line}\n{listed}")
    print(f"live: changes at a swap's first frame or the frame after its last: {sum(x[3] for x in lines)} of "
          f"{sum(x[2] for x in lines)}; elsewhere: {sum(x[4] for x in lines)}")
    print("made-up cycles of index_tip, middle_tip and ring_tip (as in section 2), live: labels as given -> mended")
    for line, _ in live_cycles:
        print(line)
    print(f"live: made-up cycles read round the cycle from their first frame and back after their last: "
          f"{sum(hit for _, hit in live_cycles)} of {len(live_cycles)}")
    labelled_loop(np)


def labelled_loop(np) -> None:
    """Section 4: the labeller's labels, as given and as the live solve read them, against the truth."""
    from handcap.hand import OpenHand
    from handcap.labeling import LabelingModel
    from handcap.layouts import load_layout
    from handcap.stream.pipeline import LivePipeline
    from handcap.synth.scene import SynthConfig, synthesize

    rate, layout = 120.0, load_layout("joints-19")
    capture = synthesize(SynthConfig(layout=layout.name, motion="random", frames=int(20 * rate), rate=rate, seed=4,
                                     subject_seed=3), progress=False)
    rom = synthesize(SynthConfig(layout=layout.name, motion="random", frames=int(30 * rate), rate=rate, seed=11,
                                 subject_seed=3), progress=False)
    model = LabelingModel.train(rom.markers, layout.names, layout.rigid)
    names = list(capture.attachment.marker_names)
    truth = capture.labeled_points(names).positions
    points = capture.points.padded()
    print("\n== 4. live pipeline with the labeller (benchmarks/stream.py's take, 20 s), labels as given -> mended ==")
    cells = []
    for mend in (False, True):
        pipeline = LivePipeline(capture.attachment, OpenHand("right"), rate=rate, labeling=model, fill=layout.name,
                                mend_swaps=mend)
        given, read, joints = [], [], []
        for frame in points:
            live = pipeline.frame(frame)
            order = pipeline.solver.order
            as_given = np.empty_like(live.markers)
            as_given[order] = live.markers
            given.append(as_given)
            read.append(live.markers)
            joints.append(live.joints)

        def wrong(markers):
            markers = np.array(markers)
            both = np.isfinite(markers[..., 0]) & np.isfinite(truth[..., 0])
            return int((both & (np.linalg.norm(np.nan_to_num(markers - truth), axis=-1) > 1e-6)).sum())

        error = np.linalg.norm(np.array(joints) - capture.hand_motion.joints, axis=-1) * 1000
        changes = "; ".join(f"{pipeline.solver.named(s)} {'back ' if s.back else ''}at {s.frame}"
                            for s in pipeline.solver.swaps) or "none"
        cells.append(f"labels wrong as given {wrong(given)}, as solved {wrong(read)}; joints median / p99 "
                     f"{np.nanmedian(error):.2f} / {np.nanpercentile(error, 99):.2f} mm; changes: {changes}")
    print("  as given: " + cells[0] + "\n  mended:   " + cells[1])


if __name__ == "__main__":
    main()
