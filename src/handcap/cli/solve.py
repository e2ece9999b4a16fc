"""``handcap calibrate-markers``, ``solve`` and ``shape``."""

from __future__ import annotations

import argparse

from handcap.cli.common import add_hand_model, add_units, betas_arg, frames_arg, lengths_arg
from handcap.layouts import SHIPPED
from handcap.solve import MEASUREMENTS, METHODS
from handcap.solve.misfit import LIMIT_MM
from handcap.steps import solve


def _cmd_calibrate_markers(a):
    return solve.calibrate_markers(a.input, a.out, layout=a.layout, side=a.side, frames=frames_arg(a.frames),
                                   betas=betas_arg(a.betas), fit_shape=a.fit_shape, estimate_offset=a.estimate_offset,
                                   units=a.units, hand_model=a.hand_model, mano_dir=a.mano_dir,
                                   drop_unseen=a.drop_unseen, drop_misfit_mm=a.drop_misfit)


def _cmd_solve(a):
    return solve.solve(a.input, a.attachment, a.out, method=a.method, filter_cutoff=a.filter_cutoff,
                       filter_order=a.filter_order, units=a.units, hand_model=a.hand_model, mano_dir=a.mano_dir,
                       keep_swaps=a.keep_swaps)


def _cmd_shape(a):
    return solve.shape(a.out, scan=a.scan, lengths=lengths_arg(a.lengths), side=a.side, hand_model=a.hand_model,
                       mano_dir=a.mano_dir)


def add_solve(verbs) -> None:
    p = verbs.add_parser("calibrate-markers", help="find where the markers sit on the hand from a calibration take",
                         description="Calibrate the marker attachment (triangle, barycentric coordinates, offset of "
                                     "every marker on its segment) from a take of an open hand slowly turned.")
    p.add_argument("input", help="labeled markers (.c3d .tsv .csv .txt .trc .npz)")
    p.add_argument("--layout", required=True, help=f"marker layout: {', '.join(SHIPPED)} or a .toml file")
    p.add_argument("--side", choices=("right", "left"), default=None,
                   help="hand side (default: the one the markers' left: or right: prefixes name, else the layout's)")
    p.add_argument("--frames", help="frames to use, A:B (default all)")
    p.add_argument("--betas", help="known shape: 10 comma-separated values or a .npz with betas")
    p.add_argument("--fit-shape", action=argparse.BooleanOptionalAction, default=None,
                   help="estimate the 10 shape values too (default: when the layout has 3 or more palm markers and "
                        "markers on two or more segments of 3 or more digits, and no --betas)")
    p.add_argument("--estimate-offset", action=argparse.BooleanOptionalAction, default=None,
                   help="estimate each marker's height off the skin (default: for sphere markers the layout places "
                        "on a segment with 3 or more markers)")
    p.add_argument("--drop-unseen", action="store_true",
                   help="leave out (with a warning) the layout's markers the take never shows, e.g. corners of dense "
                        "patches that no two cameras saw; without it they are an error")
    p.add_argument("--drop-misfit", nargs="?", type=float, const=LIMIT_MM, metavar="MM",
                   help="calibrate again without the markers whose mean residual exceeds MM millimetres (default "
                        f"{LIMIT_MM:g} when given without a value), with a warning that names them: corners of a "
                        "patch that reaches over a joint move with two bones (layouts from layout new --pattern)")
    p.add_argument("--out", required=True, help="attachment .npz")
    add_units(p)
    add_hand_model(p)
    p.set_defaults(run=_cmd_calibrate_markers)

    p = verbs.add_parser("solve", help="solve hand motion from labeled markers",
                         description="Per-frame hand pose from labeled markers with a calibrated attachment.")
    p.add_argument("input", help="labeled markers (.c3d .tsv .csv .txt .trc .npz)")
    p.add_argument("--attachment", required=True, help="attachment .npz from calibrate-markers")
    p.add_argument("--method", choices=METHODS, default="lm", help="lm (default) or adam (the paper's, slow)")
    p.add_argument("--filter-cutoff", type=float, default=None, help="low-pass the motion at this frequency, Hz")
    p.add_argument("--filter-order", type=int, default=2, help="Butterworth order (default %(default)s)")
    p.add_argument("--keep-swaps", action="store_true",
                   help="solve two labels the hand finds swapped for a stretch of frames (or three gone round a "
                        "cycle) as they are labelled (default: solved exchanged there, with a warning that names them)")
    p.add_argument("--out", required=True, help="hand motion .npz")
    add_units(p)
    add_hand_model(p, "the attachment's")
    p.set_defaults(run=_cmd_solve)

    p = verbs.add_parser("shape", help="estimate the 10 shape values from a scan or measured lengths",
                         description=f"From a 3D scan of an open hand (mesh or .npz points, metres) or measured "
                                     f"lengths in millimetres ({', '.join(MEASUREMENTS)}).")
    p.add_argument("--scan", help="scan mesh (.ply .obj .stl ...) or .npz with points")
    p.add_argument("--lengths", help="e.g. hand_length=190,hand_breadth=87 (millimetres)")
    p.add_argument("--side", choices=("right", "left"), default="right")
    p.add_argument("--out", required=True, help=".npz with betas")
    add_hand_model(p)
    p.set_defaults(run=_cmd_shape)
