"""``handcap label``, ``score-labels`` and ``corrupt``."""

from __future__ import annotations

from handcap.cli.common import add_units
from handcap.core.errors import HandcapError


def _cmd_label(args) -> tuple[str, ...]:
    from handcap.io import check_not_input, read_markers, read_points, write_markers
    from handcap.labeling import LabelingModel, label_take, objects_from_take
    from handcap.layouts import load_layout
    check_not_input(args.out, args.input, *args.train)
    reuse = _is_model_file(args)  # --train is a saved model: it is used, and not written again
    if args.model and not reuse:
        check_not_input(args.model, args.input, *args.train, args.out)
    layouts = [load_layout(name) for name in args.layout]
    if len(layouts) > 1 and (args.model or args.method == "nearest"):
        raise HandcapError("several --layout (hands) label with the viterbi labeler and save no --model; "
                           "give one --layout for those")
    points = read_points(args.input, units=args.units)
    if reuse:
        models = [LabelingModel.load(args.train[0])]
    else:
        hand = [m.name for layout in layouts for m in layout.hand_markers]
        takes = [read_markers(path, units=args.units, hand=hand) for path in args.train]
        models = [LabelingModel.train(takes, layout.names, layout.rigid, seed=args.seed) for layout in layouts]
    options = {} if args.method == "nearest" else dict(hypotheses=args.hypotheses, lag=args.lag)
    if args.object:
        if args.method == "nearest":
            raise HandcapError("--object works with the viterbi labeler")
        if reuse:
            raise HandcapError("--object learns the object's shape from a labeled take: give one as --train")
        options["objects"] = objects_from_take(read_markers(args.train[0]), args.object)
    result = label_take(points, models[0] if len(models) == 1 else models, offline=args.offline,
                        method=args.method, **options)
    write_markers(result.markers, args.out)
    if args.model and not reuse:
        models[0].save(args.model)
    seen = (result.markers.positions[..., 0] == result.markers.positions[..., 0]).mean()
    lost = result.lost_frames
    print(f"{args.out}: {points.n_frames} frames, {len(result.markers.names)} labels, {100 * seen:.1f} % of "
          f"label-frames filled; hand frame not found in {len(lost)} frames"
          + (f" (first: {lost[0]})" if len(lost) else ""))
    return result.warnings


def _is_model_file(args) -> bool:
    from handcap.labeling.model import is_labeling_model
    return bool(args.model) and len(args.train) == 1 and is_labeling_model(args.train[0])


def _cmd_score_labels(args) -> None:
    import json

    from handcap.io import read_markers
    from handcap.labeling import score_labels
    if args.json:
        from handcap.io import check_output
        check_output(args.json, args.labeled, args.truth)
    score = score_labels(read_markers(args.labeled, units=args.units), read_markers(args.truth, units=args.units))
    print(score.table(f"{args.labeled} against {args.truth}"))
    if args.json:
        from handcap.io import atomic_output
        with atomic_output(args.json, "w") as fh:
            json.dump(score.to_dict(), fh, indent=2)


def _cmd_corrupt(args) -> None:
    from pathlib import Path

    from handcap.io import check_not_input, read_markers, write_markers
    from handcap.labeling import corrupt
    out = Path(args.out)
    truth_path = out.with_name(out.stem + ".truth" + out.suffix)
    check_not_input(args.out, args.input)
    check_not_input(truth_path, args.input)
    markers = read_markers(args.input, units=args.units)
    names = None
    if args.layout:
        from handcap.layouts import load_layout
        names = load_layout(args.layout).names
    unlabeled, truth = corrupt(markers, ghost_rate=args.ghost_rate, dropout=args.dropout, seed=args.seed,
                               names=names)
    write_markers(unlabeled, out)
    write_markers(truth, truth_path)
    extra = int((unlabeled.positions[..., 0] == unlabeled.positions[..., 0]).sum()
                - (truth.positions[..., 0] == truth.positions[..., 0]).sum())
    print(f"{out}: {unlabeled.n_frames} frames of unlabeled points ({extra} ghost samples); truth in {truth_path}")


def add_label(verbs) -> None:
    from handcap.layouts import SHIPPED
    p = verbs.add_parser("label", help="label unlabeled finger markers online (GMM + N-best + Kalman + Viterbi)",
                         description="Every point of IN is treated as unlabeled, whatever its name or slot. The "
                                     "labels and the spatial model come from ROM, a labeled range-of-motion take "
                                     "(any marker format) with the layout's markers; the layout's rigid markers give "
                                     "the hand frame. The spatial model is re-aligned to the take as it is labelled "
                                     "(another day's glove, a re-stuck marker, another subject); a hand frame lost "
                                     "in many frames or few points labelled are warnings.")
    p.add_argument("input", help="unlabeled points: any marker file, or a points .npz")
    p.add_argument("--train", required=True, action="append", metavar="ROM",
                   help="labeled range-of-motion take (or a model .npz with --model); repeat for several takes "
                        "(other days, other subjects), each holding every --layout's markers")
    p.add_argument("--layout", required=True, action="append",
                   help=f"marker layout: {', '.join(SHIPPED)} or a .toml file; repeat once per hand in the stream "
                        "(each with its own marker names and rigid markers, which may include wrist markers)")
    p.add_argument("--hypotheses", type=int, default=5, help="N best assignments per frame (default %(default)s)")
    p.add_argument("--lag", type=int, default=0, help="look-ahead frames before deciding (default 0: online)")
    p.add_argument("--offline", action="store_true",
                   help="decide on the whole take, in two passes: the spatial model re-aligned to the take's labels "
                        "between them")
    p.add_argument("--method", choices=("viterbi", "nearest"), default="viterbi",
                   help="the labeler, or the nearest-neighbour baseline")
    p.add_argument("--model", help="also save the trained model here (.npz); if --train is such a model, use it")
    p.add_argument("--seed", type=int, default=0, help="seed of the mixture fits")
    p.add_argument("--object", action="append", metavar="NAMES",
                   help="a rigid object in the stream: comma-separated names of its markers in ROM, or a pattern "
                        "such as 'pillow_*' (its shape is learned there); it is found by that shape, labelled, and "
                        "kept from the fingers (repeat for several)")
    p.add_argument("--out", required=True, help="labeled markers (.c3d .trc .npz)")
    add_units(p, "the input's and --train's coordinates")
    p.set_defaults(run=_cmd_label)

    p = verbs.add_parser("score-labels", help="score a labeling against the truth (Table 1 categories)",
                         description="Correct labels (gaps included), erroneous labels, false markers, false "
                                     "occlusions per marker and overall; gaps, mean gap and segment length.")
    p.add_argument("labeled", help="labeled markers written by handcap label")
    p.add_argument("--truth", required=True, help="the true labels (e.g. the .truth file of handcap corrupt)")
    p.add_argument("--json", help="also write the scores as JSON")
    add_units(p, "both files' coordinates")
    p.set_defaults(run=_cmd_score_labels)

    p = verbs.add_parser("corrupt", help="make a labeling test: strip labels, shuffle, add ghosts and dropouts",
                         description="Writes the unlabeled points to --out and the truth (the labeled take with the "
                                     "same dropouts) beside it as NAME.truth.EXT.")
    p.add_argument("input", help="a labeled take")
    p.add_argument("--out", required=True, help="unlabeled points (.c3d .trc .npz)")
    p.add_argument("--ghost-rate", type=float, default=2.0, help="ghost markers per second (default %(default)s)")
    p.add_argument("--dropout", type=float, default=0.05,
                   help="extra fraction of samples dropped (default %(default)s)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--layout", help="keep only this layout's markers")
    add_units(p)
    p.set_defaults(run=_cmd_corrupt)
