"""``handcap layout new`` and ``layout check``."""

from __future__ import annotations

from handcap.cli.common import add_units
from handcap.core.errors import HandcapError
from handcap.layouts import SHIPPED
from handcap.steps import layout


def _cmd_layout_new(a):
    if a.pattern is not None and a.like is not None:
        raise HandcapError("--like copies a layout and --pattern makes one from a template's patches; give one")
    return layout.new(a.out, like=a.like or "glove-13", side=a.side, positions=not a.no_positions, force=a.force,
                      pattern=a.pattern, segments=a.segment or ())


def _cmd_layout_check(a):
    return layout.check(a.layout, a.take, side=a.side, units=a.units)


def add_layout(verbs) -> None:
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
    q.add_argument("--like", help=f"layout to start from: {', '.join(SHIPPED)} or a .toml file (default glove-13)")
    q.add_argument("--pattern", metavar="PATTERN_TOML",
                   help="instead of --like: every corner of this template's hand patches is a marker, on the segment "
                        "of its patch (--segment), without a position: calibrate-markers places them (patches printed "
                        "by another generator, imported with handcap pattern --import)")
    q.add_argument("--segment", action="append", metavar="PATCHES=SEGMENT",
                   help="with --pattern: the patches whose name matches the shell pattern are stuck on this hand "
                        "segment, e.g. 'thumb_1=thumb_distal' (repeat; the first that matches wins; handcap's own "
                        "patches know theirs)")
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
    q.add_argument("take", nargs="?", help="a labeled take of this marker set (.c3d .tsv .csv .txt .trc .npz)")
    q.add_argument("--side", choices=("right", "left"), default=None, help="hand side (default: the layout's)")
    add_units(q, "the take's coordinates")
    q.set_defaults(run=_cmd_layout_check)
