"""``handcap label``, ``score-labels`` and ``corrupt``."""

from __future__ import annotations

from handcap.cli.common import add_units
from handcap.layouts import SHIPPED
from handcap.steps import label, markers


def _cmd_label(a):
    return label.label(a.input, a.out, train=a.train, layouts=a.layout, model=a.model, method=a.method,
                       hypotheses=a.hypotheses, lag=a.lag, offline=a.offline, seed=a.seed, objects=a.object,
                       units=a.units, hand_check=a.hand_check)


def _cmd_score_labels(a):
    return label.score_labels(a.labeled, a.truth, out=a.json, units=a.units)


def _cmd_corrupt(a):
    return markers.corrupt(a.input, a.out, ghost_rate=a.ghost_rate, dropout=a.dropout, seed=a.seed, layout=a.layout,
                           units=a.units)


def add_label(verbs) -> None:
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
                        "between them; then the labels are checked against the fingers' anatomy (labels moved "
                        "between fingers whose markers do not lie in a line, keep their spans or bend one way) and "
                        "against the hand solved from them (labels it cannot have made removed, points where it "
                        "puts a missing marker labelled)")
    p.add_argument("--no-hand-check", dest="hand_check", action="store_false",
                   help="with --offline: leave the labels as the labeler gave them")
    p.add_argument("--method", choices=("viterbi", "nearest"), default="viterbi",
                   help="the labeler, or the nearest-neighbour baseline")
    p.add_argument("--model", help="also save the trained model here (.npz); if --train is such a model, use it")
    p.add_argument("--seed", type=int, default=0, help="seed of the mixture fits")
    p.add_argument("--object", action="append", metavar="NAMES",
                   help="a rigid object in the stream: comma-separated names of its markers in ROM, or a pattern "
                        "such as 'pillow_*' (its shape is learned there); it is found by that shape, labelled, and "
                        "kept from the fingers (repeat for several). Without it, a rigid body among the points "
                        "the labels leave is named in a warning and, with --offline, labelled object:0, object:1, ...")
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
