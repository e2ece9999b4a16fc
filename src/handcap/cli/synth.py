"""``handcap synth`` (a synthetic capture with its truth) and ``handcap demo``."""

from __future__ import annotations


def _cmd_synth(args) -> tuple[str, ...]:
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
    from handcap.io import check_output_folder
    check_output_folder(args.out, args.scene, force=args.force)
    capture = synthesize(config)
    capture, warnings = _checked_capture(capture)
    write_capture(capture, args.out)
    m = capture.markers
    from handcap.quality import plausibility as q
    print(q.summary(f"{args.out}: {m.n_frames} frames, {len(capture.hand_motion.marker_names)} hand markers, "
                    f"{m.n_markers} trajectories, {100 * capture.truth['visible'].mean():.1f}% reconstructed",
                    {**q.marker_figures(m, hand=capture.hand_motion.marker_names),
                     **q.motion_figures(capture.hand_motion)}, warnings))
    return warnings


def _checked_capture(capture):
    """The capture with the warnings of its markers and true motion stored on both (markers and truth files)."""
    from dataclasses import replace

    from handcap.quality import plausibility as q
    warnings = q.marker_warnings(capture.markers, hand=capture.hand_motion.marker_names) + \
        q.motion_warnings(capture.hand_motion)
    capture = replace(capture, markers=q.attach(capture.markers, warnings),
                      hand_motion=capture.hand_motion.with_warnings(*warnings))
    return capture, capture.markers.warnings


def _cmd_demo(args) -> tuple[str, ...]:
    from handcap.demo import run_demo
    from handcap.io import check_output_folder
    check_output_folder(args.out, force=True)  # demo-output/ is rewritten on every run
    summary = run_demo(args.out)
    for key, value in summary.items():
        if key not in ("files", "seen_per_camera_fraction", "metrics", "warnings"):
            print(f"{key:28s} {value}")
    print("\nsolved motion against the ground truth:")
    print(summary["metrics"])
    warnings = tuple(summary["warnings"])
    from pathlib import Path
    files = [Path(f) for f in summary["files"]]
    print(f"\nwrote {len(files)} files to {args.out}/ (picture of the truth beside the solve: {args.out}/hand.png); "
          + (f"{len(warnings)} warning(s), see below" if warnings else "no warnings"))
    for path in files:
        print(f"  {path.relative_to(args.out) if path.is_relative_to(args.out) else path}")
    return warnings


def add_synth(verbs) -> None:
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
    p.add_argument("--outlier-rate", type=float, default=d.outlier_rate,
                   help="fraction of 2D detections with a wrong id")
    p.add_argument("--max-view-angle", type=float, default=None,
                   help="degrees; default 75 for patches, none for spheres")
    p.add_argument("--placement-mm", type=float, default=d.placement_mm,
                   help="how far markers sit from their nominal layout spots, mm (default %(default)s)")
    p.add_argument("--subject-seed", type=int, default=None,
                   help="seed of the subject (hand shape, marker placement); share it between the takes of a session")
    p.add_argument("--scene", help="take every setting from a scene.toml written by an earlier run")
    p.add_argument("--out", required=True, help="output folder (new or empty, unless --force)")
    p.add_argument("--force", action="store_true", help="write into --out even if it holds files (those of the "
                                                        "same names are replaced)")
    p.set_defaults(run=_cmd_synth)

    p = verbs.add_parser("demo", help="run the main job on built-in data into demo-output/",
                         description="Synthetic DexterCap-style session -> marker calibration -> solve -> "
                                     "5 Hz smoothing -> metrics against the truth, written to demo-output/.")
    p.add_argument("--out", default="demo-output")
    p.set_defaults(run=_cmd_demo)
