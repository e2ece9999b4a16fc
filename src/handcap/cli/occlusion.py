"""``handcap train-occlusion`` and ``fill``."""

from __future__ import annotations

import sys

from handcap.cli.common import add_units
from handcap.core.errors import HandcapError


def _cmd_train_occlusion(args) -> tuple[str, ...]:
    import time

    from handcap.io import check_not_input
    from handcap.occlusion import read_take, train_occlusion_model
    check_not_input(args.out, *args.takes, *(args.poses or []))
    if args.poses and len(args.poses) != len(args.takes):
        raise HandcapError(f"--poses needs one hand motion per take: {len(args.takes)} takes, {len(args.poses)} poses")
    from dataclasses import replace

    from handcap.occlusion.augment import NO_AUGMENTATION, SUBJECT_AUGMENTATION
    from handcap.occlusion.data import synthetic_hand_takes
    if args.synthetic < 0 or args.speed_copies < 0:
        raise HandcapError("--synthetic and --speed-copies take a number >= 0")
    if not args.takes and not args.synthetic:
        raise HandcapError("give takes to train on, or --synthetic SUBJECTS, or both")
    augmentation = replace(SUBJECT_AUGMENTATION if args.augment else NO_AUGMENTATION, copies=args.speed_copies)
    poses = args.poses or [None] * len(args.takes)
    takes = [read_take(path, poses=pose) for path, pose in zip(args.takes, poses)]
    start = time.perf_counter()
    if args.synthetic:
        from handcap.layouts import load_layout
        takes += synthetic_hand_takes(args.layout, subjects=args.synthetic, seed=args.seed,
                                      side=load_layout(args.layout).side)

    def progress(stage, epoch, loss):
        if epoch % 10 == 9 or epoch == 0:
            print(f"  {stage}: epoch {epoch + 1}, loss {loss:.4f}", file=sys.stderr, flush=True)

    model = train_occlusion_model(takes, args.layout, seed=args.seed, epochs=args.epochs,
                                  regressor_epochs=args.epochs, progress=progress, augmentation=augmentation,
                                  pair_seconds=args.pair_seconds)
    model.save(args.out)
    info = model.info
    posed = int(info["posed_frames"])
    print(f"{args.out}: {model!r}, {time.perf_counter() - start:.0f} s\n"
          f"  saw {info['takes']} take(s) ({info['recorded_takes']} recorded, {info['synthetic_takes']} synthetic) "
          f"of {info['subjects']} subject(s), {info['frames']} frames; {info['augmented_copies']} augmented "
          f"copies ({info['augmented_frames']} frames); {info['samples']} training samples\n"
          f"  augmentation: {info['augmentation']}; gaps up to {args.pair_seconds:g} s\n"
          + (f"  joint regressor on {posed} posed frames" if posed else "  no poses: markers only"))
    return model.warnings


def _cmd_fill(args) -> tuple[str, ...]:
    import time

    from handcap.io import check_not_input, read_markers, write_markers
    from handcap.occlusion import fill_gaps
    check_not_input(args.out, args.input, *([args.model] if args.model else []))
    markers = read_markers(args.input, units=args.units)
    start = time.perf_counter()
    filled, report = fill_gaps(markers, args.method, max_gap_s=args.max_gap, model=args.model)
    seconds = time.perf_counter() - start
    write_markers(filled, args.out)
    print(f"{args.out}: {report.filled_samples} samples in {report.filled_gaps} gaps filled ({args.method}, "
          f"gaps up to {report.max_gap_frames} frames = {args.max_gap:g} s), {report.left_gaps} gaps "
          f"({report.left_samples} samples) left missing, {seconds:.1f} s"
          + (f"; not in the model, left as they were: {', '.join(report.untouched)}" if report.untouched else ""))
    return filled.warnings


def add_occlusion(verbs) -> None:
    from handcap.layouts import SHIPPED
    from handcap.occlusion import FILL_METHODS, SHIPPED_MODELS
    from handcap.occlusion.train import PAIR_SECONDS
    p = verbs.add_parser("train-occlusion", help="train the occluded-marker predictor (and joint regressor) on takes",
                         description="Trains the autoencoder that predicts occluded markers on labeled takes (any "
                                     "marker format, or handcap synth folders); with poses (synth truth, or --poses "
                                     "hand motions from handcap solve) also the joint regressor. Deterministic for a "
                                     "seed. The model is a small .npz used by handcap fill and OcclusionFiller.")
    p.add_argument("takes", nargs="*", metavar="TAKE", help="labeled takes holding the layout's markers "
                                                             "(none: --synthetic only)")
    p.add_argument("--layout", required=True, help=f"marker layout: {', '.join(SHIPPED)} or a .toml file")
    p.add_argument("--poses", nargs="+", metavar="MOTION", help="one hand motion .npz per take (phi, global_orient, "
                                                                 "transl) to train the joint regressor")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--epochs", type=int, default=60, help="training epochs of each network (default %(default)s)")
    p.add_argument("--synthetic", type=int, default=0, metavar="SUBJECTS",
                   help="also train on synthetic takes: SUBJECTS x every synthetic motion, each take a new subject "
                        "(default %(default)s)")
    p.add_argument("--augment", action="store_true",
                   help="augment every sample as another subject (scale, back-of-hand, finger and marker "
                        "placement) for a model that must serve new subjects; it costs on the training subject itself")
    p.add_argument("--speed-copies", type=int, default=0, metavar="N",
                   help="also train on N time-warped copies of every take (0.6-1.6x speed; default %(default)s)")
    p.add_argument("--pair-seconds", type=float, default=PAIR_SECONDS, metavar="SECONDS",
                   help="score the marker predictor as the filler uses it over gaps up to this long (default "
                        "%(default)s); 0 trains on single frames as the paper does")
    p.add_argument("--out", required=True, help="model .npz")
    p.set_defaults(run=_cmd_train_occlusion)

    p = verbs.add_parser("fill", help="fill marker gaps of a recorded take (interpolation or occlusion prediction)",
                         description="linear/spline interpolate interior gaps; lk, ma, ac and nn are the real-time "
                                     "paper's predictors, run forwards and backwards and blended so the fill meets "
                                     "both ends of a gap. Gaps longer than --max-gap stay missing.")
    p.add_argument("input", help="labeled markers (.c3d .tsv .csv .trc .npz)")
    p.add_argument("--method", choices=FILL_METHODS, default="nn", help="default %(default)s")
    p.add_argument("--model", help=f"occlusion model .npz, or a shipped one: {', '.join(SHIPPED_MODELS)} (nn)")
    p.add_argument("--max-gap", type=float, default=0.5, metavar="SECONDS",
                   help="longest gap to fill, seconds (default %(default)s)")
    p.add_argument("--out", required=True, help="filled markers (.c3d .trc .npz)")
    add_units(p)
    p.set_defaults(run=_cmd_fill)
