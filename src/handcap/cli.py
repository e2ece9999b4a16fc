"""The ``handcap`` command. Every verb has ``--help``; user mistakes exit with code 2."""

from __future__ import annotations

import argparse
import sys

from handcap.core.errors import HandcapError


def _cmd_convert(args) -> None:
    from handcap.io import convert
    markers = convert(args.input, args.output, partial=args.partial)
    print(f"{args.output}: {markers.n_frames} frames, {markers.n_markers} markers at {markers.rate:g} Hz")


def _cmd_synth(args) -> None:
    from handcap.synth.scene import SynthConfig, config_from_scene, synthesize, write_capture
    if args.scene:
        config = config_from_scene(args.scene)
    else:
        betas = None if args.betas is None else tuple(float(b) for b in args.betas.split(","))
        config = SynthConfig(layout=args.layout, motion=args.motion, frames=args.frames, rate=args.rate,
                             seed=args.seed, side=args.side, object=args.object, betas=betas, cameras=args.cameras,
                             min_views=args.min_views, noise_mm=args.noise_mm, pixel_noise=args.pixel_noise,
                             dropout=args.dropout, ghost_rate=args.ghost_rate, swap_rate=args.swap_rate,
                             outlier_rate=args.outlier_rate, max_view_angle_deg=args.max_view_angle,
                             placement_mm=args.placement_mm, subject_seed=args.subject_seed)
    capture = synthesize(config)
    write_capture(capture, args.out)
    m = capture.markers
    print(f"{args.out}: {m.n_frames} frames, {len(capture.hand_motion.marker_names)} hand markers, "
          f"{m.n_markers} trajectories, {100 * capture.truth['visible'].mean():.1f}% reconstructed")


def _cmd_demo(args) -> None:
    from handcap.demo import run_demo
    summary = run_demo(args.out)
    for key, value in summary.items():
        if key not in ("files", "seen_per_camera_fraction"):
            print(f"{key:28s} {value}")
    print(f"wrote {len(summary['files'])} files to {args.out}/ (picture: {args.out}/hand.png)")


def _add_synth(verbs) -> None:
    from handcap.layouts import SHIPPED
    from handcap.synth.motions import MOTIONS
    from handcap.synth.objects import OBJECTS
    from handcap.synth.scene import SynthConfig
    d = SynthConfig()
    p = verbs.add_parser("synth", help="make a synthetic capture with ground truth",
                         description="Move the open hand (and an object) through a motion, film its markers with a "
                                     "rig of cameras, decide visibility by ray casting and add capture faults. "
                                     "Writes markers.c3d/.npz, points.npz, detections.npz, cameras.toml, truth.npz "
                                     "and scene.toml into OUT; the same settings give the same bytes.")
    p.add_argument("--layout", default=d.layout, help=f"marker layout: {', '.join(SHIPPED)} or a .toml file")
    p.add_argument("--motion", default=d.motion, choices=MOTIONS)
    p.add_argument("--frames", type=int, default=d.frames)
    p.add_argument("--rate", type=float, default=d.rate, help="frames per second (default %(default)s)")
    p.add_argument("--seed", type=int, default=d.seed)
    p.add_argument("--side", default=d.side, choices=("right", "left"))
    p.add_argument("--object", default=d.object, choices=OBJECTS + ("auto", "none"),
                   help="object to manipulate (auto: the motion's usual one)")
    p.add_argument("--betas", help="10 comma-separated shape values (default: drawn from the seed)")
    p.add_argument("--cameras", type=int, default=d.cameras)
    p.add_argument("--min-views", type=int, default=d.min_views, help="cameras needed to reconstruct a marker")
    p.add_argument("--noise-mm", type=float, default=d.noise_mm, help="3D jitter, mm (default %(default)s)")
    p.add_argument("--pixel-noise", type=float, default=d.pixel_noise, help="2D noise, px (default %(default)s)")
    p.add_argument("--dropout", type=float, default=d.dropout, help="extra fraction lost in bursts")
    p.add_argument("--ghost-rate", type=float, default=d.ghost_rate, help="ghost markers per second")
    p.add_argument("--swap-rate", type=float, default=d.swap_rate, help="label swaps per second")
    p.add_argument("--outlier-rate", type=float, default=d.outlier_rate, help="fraction of 2D detections with a wrong id")
    p.add_argument("--max-view-angle", type=float, default=None, help="degrees; default 75 for patches, none for spheres")
    p.add_argument("--placement-mm", type=float, default=d.placement_mm,
                   help="how far markers sit from their nominal layout spots, mm (default %(default)s)")
    p.add_argument("--subject-seed", type=int, default=None,
                   help="seed of the subject (hand shape, marker placement); share it between the takes of a session")
    p.add_argument("--scene", help="take every setting from a scene.toml written by an earlier run")
    p.add_argument("--out", required=True, help="output folder")
    p.set_defaults(run=_cmd_synth)

    p = verbs.add_parser("demo", help="run the main job on built-in data into demo-output/",
                         description="Synthetic DexterCap-style capture, summary and picture (demo-output/).")
    p.add_argument("--out", default="demo-output")
    p.set_defaults(run=_cmd_demo)


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
    p.add_argument("--partial", action="store_true",
                   help="C3D: keep the complete frames of a file shorter than its header promises")
    p.set_defaults(run=_cmd_convert)

    _add_synth(verbs)
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
