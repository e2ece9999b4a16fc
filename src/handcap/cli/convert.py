"""``handcap convert``: a marker file to another format."""

from __future__ import annotations

from handcap.cli.common import add_units
from handcap.core.errors import HandcapError
from handcap.steps import markers


def _cmd_convert(args):
    if (args.output is None) == (args.out is None):
        raise HandcapError("give the output file once: handcap convert IN OUT, or handcap convert IN --out OUT")
    return markers.convert(args.input, args.output or args.out, partial=args.partial, units=args.units)


def add_convert(verbs) -> None:
    p = verbs.add_parser("convert", help="convert a marker file (.c3d .tsv .csv .txt .trc .npz) to another format",
                         description="Convert a marker file; the formats come from the extensions. "
                                     "Reads C3D, Qualisys TSV, OptiTrack Motive CSV, Vicon Nexus CSV or .txt, TRC "
                                     "and .npz; writes C3D, TRC and .npz. Units become metres (.npz) or millimetres "
                                     "(C3D, TRC).")
    p.add_argument("input", help="a marker file (.c3d .tsv .csv .txt .trc .npz)")
    p.add_argument("output", nargs="?", help="the file to write (.c3d .trc .npz); or give it with --out")
    p.add_argument("--out", help="the file to write, as the other verbs take it")
    p.add_argument("--partial", action="store_true",
                   help="C3D: keep the complete frames of a file shorter than its header promises")
    add_units(p)
    p.set_defaults(run=_cmd_convert)
