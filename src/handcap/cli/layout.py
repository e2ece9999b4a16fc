"""``handcap layout new`` and ``layout check``."""

from __future__ import annotations

from handcap.cli.common import add_units
from handcap.core.errors import HandcapError


def _cmd_layout_new(args) -> None:
    from pathlib import Path

    from handcap.io import atomic_output, check_not_input
    from handcap.layouts import SHIPPED, layout_template, load_layout
    out = Path(args.out)
    if out.is_dir():
        raise HandcapError(f"{out}: is a folder; give a file name such as {out / 'my-layout.toml'}")
    if out.suffix.lower() != ".toml":
        raise HandcapError(f"{out}: layouts are TOML files; name it NAME.toml")
    if args.like not in SHIPPED:
        check_not_input(out, args.like)
    if out.exists() and not args.force:
        raise HandcapError(f"{out}: exists; choose another name or add --force to replace it")
    layout = load_layout(args.like, side=args.side)
    with atomic_output(out, "w") as fh:
        fh.write(layout_template(layout, like=args.like, positions=not args.no_positions))
    given = 0 if args.no_positions else sum(m.position is not None for m in layout.markers)
    print(f"{out}: {len(layout)} markers like {args.like} ({layout.side} hand, {given} with positions), every field "
          f"explained in its comments; next: handcap layout check {out} YOUR_TAKE")


def _cmd_layout_check(args):
    from handcap.io import read_markers
    from handcap.layouts import check_layout, load_layout
    layout = load_layout(args.layout, side=args.side)
    markers = None if args.take is None else read_markers(args.take, units=args.units,
                                                          hand=[m.name for m in layout.hand_markers])
    result = check_layout(layout, markers, take=args.take)
    print(result.summary())
    return result.warnings


def add_layout(verbs) -> None:
    from handcap.layouts import SHIPPED
    p = verbs.add_parser("layout", help="write a layout for your own marker set, and check it against a take",
                         description="new: a commented copy of a shipped layout to edit (names, segments, rigid "
                                     "set, positions). check: the layout's names in a take (a Subject: prefix is "
                                     "ignored), its segments, its positions on the template hand, its rigid set, "
                                     "and which positions calibrate-markers will estimate. An unusable layout "
                                     "exits with code 2; other problems are warnings.")
    what = p.add_subparsers(dest="what", metavar="WHAT")
    what.required = True
    q = what.add_parser("new", help="write a commented layout file to edit",
                        description="Copy a layout with every field explained in comments.")
    q.add_argument("--like", default="glove-13", help=f"layout to start from: {', '.join(SHIPPED)} or a .toml file "
                                                      "(default %(default)s)")
    q.add_argument("--side", choices=("right", "left"), default=None, help="write it for this hand (default: as "
                                                                            "--like)")
    q.add_argument("--no-positions", action="store_true",
                   help="leave the hand markers' positions out: calibrate-markers estimates them from a take (for "
                        "markers placed otherwise than in --like)")
    q.add_argument("--force", action="store_true", help="replace --out if it exists")
    q.add_argument("--out", required=True, help="layout file to write (.toml)")
    q.set_defaults(run=_cmd_layout_new)
    q = what.add_parser("check", help="check a layout, against a labeled take if given",
                        description="Names matched / missing / only in the take, segments, positions against the "
                                    "template hand (within 2 cm of their segment), the rigid set (3 or more markers "
                                    "of one segment, not in a line, as far apart in the take as in the layout) and "
                                    "what will be estimated.")
    q.add_argument("layout", help=f"layout: {', '.join(SHIPPED)} or a .toml file")
    q.add_argument("take", nargs="?", help="a labeled take of this marker set (.c3d .tsv .csv .trc .npz)")
    q.add_argument("--side", choices=("right", "left"), default=None, help="hand side (default: the layout's)")
    add_units(q, "the take's coordinates")
    q.set_defaults(run=_cmd_layout_check)
