"""The ``handcap`` command. Every verb has ``--help``; user mistakes exit with code 2."""

from __future__ import annotations

import argparse
import sys

from handcap.core.errors import HandcapError


def _cmd_convert(args) -> None:
    from handcap.io import convert
    markers = convert(args.input, args.output)
    print(f"{args.output}: {markers.n_frames} frames, {markers.n_markers} markers at {markers.rate:g} Hz")


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="handcap", description=__doc__)
    parser.add_argument("--version", action="version", version=_version())
    verbs = parser.add_subparsers(dest="verb", metavar="VERB")
    verbs.required = True

    p = verbs.add_parser("convert", help="convert a marker file (.c3d .tsv .csv .trc .npz) to another format",
                         description="Convert a marker file; the formats come from the extensions. "
                                     "Reads C3D, Qualisys TSV, OptiTrack Motive CSV, TRC and .npz; "
                                     "writes C3D, TRC and .npz. Units become metres (.npz) or millimetres (C3D, TRC).")
    p.add_argument("input")
    p.add_argument("output")
    p.set_defaults(run=_cmd_convert)
    return parser


def _version() -> str:
    from handcap import __version__
    return f"handcap {__version__}"


def main(argv=None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        args.run(args)
    except HandcapError as err:
        print(f"handcap {args.verb}: error: {err}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("handcap: interrupted", file=sys.stderr)
        return 130
    return 0


if __name__ == "__main__":
    sys.exit(main())
