"""``handcap calibrate-markers``, ``solve``, ``track-object``, ``metrics`` and ``shape``."""

from __future__ import annotations

import argparse

from handcap.cli.common import add_hand_model, add_units, betas_arg, frames_arg, hand_model, motion_file_warnings
from handcap.core.markers import expand_names
from handcap.core.errors import HandcapError


def _cmd_calibrate_markers(args) -> tuple[str, ...]:
    from handcap.io import check_not_input, read_markers
    from handcap.layouts import load_layout
    from handcap.solve import calibrate_attachment
    check_not_input(args.out, args.input)
    layout = load_layout(args.layout, side=args.side)
    markers = read_markers(args.input, units=args.units, hand=[m.name for m in layout.hand_markers])
    hand = hand_model(args, layout.side)
    result = calibrate_attachment(markers, layout, hand, betas=betas_arg(args.betas), frames=frames_arg(args.frames),
                                  fit_shape=args.fit_shape, estimate_offset=args.estimate_offset)
    result.attachment.save(args.out)
    shape = ("shape fitted: " + " ".join(f"{b:+.2f}" for b in result.attachment.betas)) if result.fit_shape \
        else "shape not fitted (use --fit-shape)"
    print(f"{args.out}: {len(result.attachment)} markers from {len(result.frames)} frames, {result.rounds} rounds, "
          f"calibration MRE {1000 * result.mre:.2f} mm; {shape}")
    return result.warnings


def _cmd_solve(args) -> tuple[str, ...]:
    import time

    import numpy as np

    from handcap.hand.attachment import MarkerAttachment
    from handcap.io import check_not_input, read_markers, write_hand_motion
    from handcap.solve import solve_hand
    check_not_input(args.out, args.input, args.attachment)
    attachment = MarkerAttachment.load(args.attachment)
    markers = read_markers(args.input, units=args.units, hand=attachment.marker_names)
    hand = hand_model(args, attachment.side, recorded=attachment.model, what=args.attachment)
    start = time.perf_counter()
    motion = solve_hand(markers, attachment, hand, method=args.method, filter_cutoff=args.filter_cutoff,
                        filter_order=args.filter_order)
    seconds = time.perf_counter() - start
    motion = motion.with_warnings(*markers.warnings)  # e.g. the unit of the input guessed: kept with the result
    write_hand_motion(motion, args.out)
    residuals = motion.marker_residuals
    print(f"{args.out}: {motion.n_frames} frames in {seconds:.1f} s ({motion.n_frames / seconds:.0f} frames/s, "
          f"{args.method}), MRE {1000 * np.nanmean(residuals):.2f} ± {1000 * np.nanstd(residuals):.2f} mm"
          + (f", low-passed at {args.filter_cutoff:g} Hz" if args.filter_cutoff else ""))
    return motion.warnings


def _cmd_track_object(args) -> tuple[str, ...]:
    import numpy as np

    from handcap.io import check_not_input, load_npz, read_markers, write_object_motion
    from handcap.objects import track_rigid
    check_not_input(args.out, args.input, args.canonical)
    markers = read_markers(args.input, units=args.units)
    names = expand_names(markers, args.markers)
    canonical = None if args.canonical is None else load_npz(args.canonical, ("canonical",), "object file")["canonical"]
    track = track_rigid(markers, names, canonical, name=args.name, threshold=args.threshold_mm / 1000)
    from handcap.quality import plausibility as q
    motion = q.attach(track.motion, [*markers.warnings, *q.object_warnings(track, threshold=args.threshold_mm / 1000)])
    write_object_motion(motion, args.out)
    unsolved = track.unsolved
    listed = ", ".join(map(str, unsolved[:10])) + (" ..." if len(unsolved) > 10 else "")
    print(f"{args.out}: {track.motion.n_frames} frames, mean residual {1000 * track.mean_residual:.2f} mm, "
          f"{int(np.sum(~track.inliers & ~np.isnan(markers.select(names).positions[..., 0])))} outlier samples, "
          f"{len(unsolved)} frames with fewer than 3 markers" + (f": {listed}" if len(unsolved) else ""))
    print("  quality: " + (f"{len(motion.warnings)} warning(s), see below" if motion.warnings else "no warnings"))
    return motion.warnings


def _cmd_metrics(args) -> tuple[str, ...]:
    import json

    from handcap.report import metrics_table, motion_metrics
    if args.out:
        from handcap.io import check_output
        check_output(args.out, args.motion, args.truth, args.markers, args.attachment, args.object, args.object_mesh)
    hand = None
    if args.hand_model or args.mano_dir or (args.object_mesh and args.object) or args.leave_one_out:
        from handcap.io import read_hand_motion
        motion = read_hand_motion(args.motion)  # the model is needed for the mesh: the one it was solved with
        hand = hand_model(args, motion.side, recorded=motion.model, what=args.motion)
    metrics = motion_metrics(args.motion, truth=args.truth, markers=args.markers, obj=args.object,
                             object_mesh=args.object_mesh, attachment=args.attachment,
                             leave_one_out=args.leave_one_out, hand=hand)
    stored, warnings = motion_file_warnings(args.motion, args.markers)
    metrics["warnings"] = list(warnings)
    print(metrics_table(metrics))
    print(f"{'quality':22s} " + (f"{len(warnings)} warning(s), {len(stored)} of them stored in {args.motion}; see below"
                                 if warnings else "no warnings"))
    if args.out:
        from handcap.io import atomic_output
        with atomic_output(args.out, "w") as fh:
            json.dump(metrics, fh, indent=2)
    return warnings


def _cmd_shape(args) -> tuple[str, ...]:
    import numpy as np

    from handcap.io import save_npz
    from handcap.io import read_scan_points
    from handcap.solve import MEASUREMENTS, betas_from_measurements, betas_from_scan, hand_measurements
    hand = hand_model(args, args.side)
    if (args.scan is None) == (args.lengths is None):
        raise HandcapError("give either --scan or --lengths")
    from handcap.io import check_output
    check_output(args.out, args.scan)
    if args.scan:
        betas, chamfer = betas_from_scan(hand, read_scan_points(args.scan))
        note = f"Chamfer distance {1000 * chamfer:.2f} mm"
    else:
        lengths = {}
        for item in args.lengths.split(","):
            key, _, value = item.partition("=")
            try:
                lengths[key.strip()] = float(value) / 1000
            except ValueError:
                raise HandcapError(f"--lengths takes name=millimetres pairs ({', '.join(MEASUREMENTS)}), "
                                   f"got {item!r}") from None
        betas = betas_from_measurements(hand, **lengths)
        note = "from " + ", ".join(lengths)
    from handcap.core.files import warnings_entry
    from handcap.quality import plausibility as q
    warnings = tuple(q.shape_warnings(betas))
    save_npz(args.out, {"betas": betas, **warnings_entry(warnings)})
    m = hand_measurements(hand, betas)
    print(f"{args.out}: betas {np.round(betas, 2).tolist()} ({note}); hand length {1000 * m['hand_length']:.1f} mm, "
          f"breadth {1000 * m['hand_breadth']:.1f} mm; " + (f"{len(warnings)} warning(s), see below" if warnings
                                                             else "no warnings"))
    return warnings


def add_solve(verbs) -> None:
    from handcap.layouts import SHIPPED
    from handcap.solve import MEASUREMENTS, METHODS
    p = verbs.add_parser("calibrate-markers", help="find where the markers sit on the hand from a calibration take",
                         description="Calibrate the marker attachment (triangle, barycentric coordinates, offset of "
                                     "every marker on its segment) from a take of an open hand slowly turned.")
    p.add_argument("input", help="labeled markers (.c3d .tsv .csv .trc .npz)")
    p.add_argument("--layout", required=True, help=f"marker layout: {', '.join(SHIPPED)} or a .toml file")
    p.add_argument("--side", choices=("right", "left"), default=None, help="hand side (default: the layout's)")
    p.add_argument("--frames", help="frames to use, A:B (default all)")
    p.add_argument("--betas", help="known shape: 10 comma-separated values or a .npz with betas")
    p.add_argument("--fit-shape", action=argparse.BooleanOptionalAction, default=None,
                   help="estimate the 10 shape values too (default: when the layout has 3 or more palm markers and "
                        "markers on two or more segments of 3 or more digits, and no --betas)")
    p.add_argument("--estimate-offset", action=argparse.BooleanOptionalAction, default=None,
                   help="estimate each marker's height off the skin (default: for sphere markers the layout places "
                        "on a segment with 3 or more markers)")
    p.add_argument("--out", required=True, help="attachment .npz")
    add_units(p)
    add_hand_model(p)
    p.set_defaults(run=_cmd_calibrate_markers)

    p = verbs.add_parser("solve", help="solve hand motion from labeled markers",
                         description="Per-frame hand pose from labeled markers with a calibrated attachment.")
    p.add_argument("input", help="labeled markers (.c3d .tsv .csv .trc .npz)")
    p.add_argument("--attachment", required=True, help="attachment .npz from calibrate-markers")
    p.add_argument("--method", choices=METHODS, default="lm", help="lm (default) or adam (the paper's, slow)")
    p.add_argument("--filter-cutoff", type=float, default=None, help="low-pass the motion at this frequency, Hz")
    p.add_argument("--filter-order", type=int, default=2, help="Butterworth order (default %(default)s)")
    p.add_argument("--out", required=True, help="hand motion .npz")
    add_units(p)
    add_hand_model(p, "the attachment's")
    p.set_defaults(run=_cmd_solve)

    p = verbs.add_parser("track-object", help="6-DoF motion of a rigid object from its markers",
                         description="Kabsch with RANSAC per frame; the object's marker geometry is estimated from "
                                     "the take unless --canonical gives it. Frames with fewer than 3 markers are "
                                     "reported and left empty (NaN), not guessed.")
    p.add_argument("input", help="labeled markers")
    p.add_argument("--markers", required=True,
                   help="comma-separated names of the object's markers (3 or more); patterns such as 'boite:*' work")
    p.add_argument("--canonical", help="object .npz with canonical (M, 3) marker positions")
    p.add_argument("--name", default="object")
    p.add_argument("--threshold-mm", type=float, default=5.0, help="RANSAC inlier distance (default %(default)s)")
    p.add_argument("--out", required=True, help="object motion .npz")
    add_units(p)
    p.set_defaults(run=_cmd_track_object)

    p = verbs.add_parser("metrics", help="quality metrics of a solved motion",
                         description="MRE, joint error against ground truth, leave-one-marker-out error, MSNR, jerk, "
                                     "penetration, diversity and coherence (definitions in handcap.quality.metrics).")
    p.add_argument("motion", help="hand motion .npz")
    p.add_argument("--truth", help="ground truth (truth.npz of handcap synth, or a hand motion .npz)")
    p.add_argument("--markers", help="the labeled markers the motion was solved from (for MRE)")
    p.add_argument("--attachment", help="attachment .npz (for --leave-one-out)")
    p.add_argument("--leave-one-out", action="store_true", help="solve again without each marker (slow)")
    p.add_argument("--object", help="object motion .npz (for penetration)")
    p.add_argument("--object-mesh", help="the object's mesh (any format trimesh reads), metres, object frame")
    p.add_argument("--out", help="also write the metrics as JSON")
    add_hand_model(p, "the motion's")
    p.set_defaults(run=_cmd_metrics)

    p = verbs.add_parser("shape", help="estimate the 10 shape values from a scan or measured lengths",
                         description=f"From a 3D scan of an open hand (mesh or .npz points, metres) or measured "
                                     f"lengths in millimetres ({', '.join(MEASUREMENTS)}).")
    p.add_argument("--scan", help="scan mesh (.ply .obj .stl ...) or .npz with points")
    p.add_argument("--lengths", help="e.g. hand_length=190,hand_breadth=87 (millimetres)")
    p.add_argument("--side", choices=("right", "left"), default="right")
    p.add_argument("--out", required=True, help=".npz with betas")
    add_hand_model(p)
    p.set_defaults(run=_cmd_shape)
