"""``handcap train-occlusion`` and ``fill``."""

from __future__ import annotations

from handcap.cli.common import add_units, print_progress
from handcap.layouts import SHIPPED
from handcap.occlusion import FILL_METHODS, SHIPPED_MODELS
from handcap.occlusion.history import HISTORY_S
from handcap.occlusion.train import PAIR_SECONDS, SAMPLES_PER_EPOCH
from handcap.steps import markers, occlusion


def _cmd_train_occlusion(a):
    return occlusion.train_occlusion(a.takes, a.out, layout=a.layout, poses=a.poses, seed=a.seed, epochs=a.epochs,
                                     samples_per_epoch=a.samples_per_epoch, synthetic=a.synthetic, augment=a.augment,
                                     speed_copies=a.speed_copies, pair_seconds=a.pair_seconds, progress=print_progress)


def _cmd_fill(a):
    return markers.fill(a.input, a.out, method=a.method, model=a.model, max_gap_s=a.max_gap, units=a.units,
                        history_s=a.history)


def add_occlusion(verbs) -> None:
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
    p.add_argument("--samples-per-epoch", type=int, default=SAMPLES_PER_EPOCH, metavar="N",
                   help="knocked-out samples the marker predictor sees per epoch (default %(default)s)")
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
    p.add_argument("input", help="labeled markers (.c3d .tsv .csv .txt .trc .npz)")
    p.add_argument("--method", choices=FILL_METHODS, default="nn", help="default %(default)s")
    p.add_argument("--model", help=f"occlusion model .npz, or a shipped one: {', '.join(SHIPPED_MODELS)} (nn)")
    p.add_argument("--max-gap", type=float, default=0.5, metavar="SECONDS",
                   help="longest gap to fill, seconds (default %(default)s)")
    p.add_argument("--history", type=float, default=HISTORY_S, metavar="SECONDS",
                   help="nn: learn the network's error on a hidden marker from this many seconds before its gap "
                        "and carry it in (default %(default)s; 0: the network and its offset alone)")
    p.add_argument("--out", required=True, help="filled markers (.c3d .trc .npz)")
    add_units(p)
    p.set_defaults(run=_cmd_fill)
