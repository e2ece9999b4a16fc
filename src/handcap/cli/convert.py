"""``handcap convert``: a marker file to another format."""

from __future__ import annotations

from handcap.cli.common import add_units


def _cmd_convert(args) -> tuple[str, ...]:
    from handcap.io import check_output, read_markers, write_markers
    from handcap.quality import plausibility as q
    check_output(args.output, args.input)
    markers = read_markers(args.input, partial=args.partial, units=args.units)
    markers = q.attach(markers, q.marker_warnings(markers))  # stored in the output (.npz, .c3d) as well
    write_markers(markers, args.output)
    print(q.summary(f"{args.output}: {markers.n_frames} frames, {markers.n_markers} markers at {markers.rate:g} Hz",
                    q.marker_figures(markers), markers.warnings))
    return markers.warnings


def add_convert(verbs) -> None:
    p = verbs.add_parser("convert", help="convert a marker file (.c3d .tsv .csv .trc .npz) to another format",
                         description="Convert a marker file; the formats come from the extensions. "
                                     "Reads C3D, Qualisys TSV, OptiTrack Motive CSV, TRC and .npz; "
                                     "writes C3D, TRC and .npz. Units become metres (.npz) or millimetres (C3D, TRC).")
    p.add_argument("input")
    p.add_argument("output")
    p.add_argument("--partial", action="store_true",
                   help="C3D: keep the complete frames of a file shorter than its header promises")
    add_units(p)
    p.set_defaults(run=_cmd_convert)
