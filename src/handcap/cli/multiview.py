"""``handcap triangulate`` and ``clean``."""

from __future__ import annotations

from handcap.cli.common import add_units
from handcap.core.errors import HandcapError


def _cmd_triangulate(args) -> tuple[str, ...]:
    import time

    from handcap.io import check_not_input, write_markers
    from handcap.io.camera_formats import read_rig
    from handcap.multiview import merge_detections, read_detections, triangulate_detections, write_quality

    from handcap.multiview import quality_path
    check_not_input(args.out, args.cameras, *args.detections)
    check_not_input(quality_path(args.out), args.cameras, *args.detections)
    detections = merge_detections([read_detections(path) for path in args.detections])
    rig = read_rig(args.cameras, units=args.units)
    start = time.perf_counter()
    result = triangulate_detections(detections, rig, min_views=args.min_views, threshold_px=args.threshold_px,
                                    chunk_frames=args.chunk_frames, scheduler=args.scheduler, workers=args.workers)
    seconds = time.perf_counter() - start
    from handcap.quality import plausibility as q
    markers = result.to_markers()
    markers = q.attach(markers, [*rig.warnings, *q.triangulation_warnings(
        result.error_px, result.views, threshold_px=args.threshold_px, used=result.used), *q.marker_warnings(markers)])
    write_markers(markers, args.out)
    quality = write_quality(result, args.out)
    s = result.summary()
    print(q.summary(f"{args.out}: {s['frames']} frames, {s['markers']} markers, {s['points']} points from "
                    f"{s['detections']} detections ({s['rejected']} rejected), mean reprojection error "
                    f"{s['mean_error_px']:.2f} px over {s['mean_views']:.1f} views, "
                    f"{s['frames'] * s['markers'] / max(seconds, 1e-9):,.0f} marker-frames/s; per-marker errors and "
                    f"view counts in {quality}", q.marker_figures(markers), markers.warnings))
    return markers.warnings


def add_multiview(verbs) -> None:
    p = verbs.add_parser("triangulate", help="3D markers from 2D detections of calibrated cameras (robust)",
                         description="Undistorts the detections, triangulates every marker in every frame from the "
                                     "best inlier set of views (RANSAC over pairs of views, then a non-linear "
                                     "refinement) and writes the markers with their metric residuals. Per marker "
                                     "and frame, the reprojection error (px) and inlier view count go to "
                                     "OUT_STEM.triangulation.npz, with a used/rejected flag per detection. Blocks of "
                                     "frames run on local processes, or on a Dask cluster with --scheduler.")
    p.add_argument("detections", nargs="+", metavar="DETECTIONS",
                   help="2D detections .npz (handcap synth's detections.npz; several files, say one per camera, "
                        "are merged)")
    p.add_argument("--cameras", required=True, help="calibrated rig (.toml anipose or caliscope, .yml/.xml OpenCV, "
                                                    ".qca.txt Qualisys)")
    p.add_argument("--min-views", type=int, default=3, help="inlier views a marker needs (default %(default)s)")
    p.add_argument("--threshold-px", type=float, default=5.0,
                   help="reprojection error of an inlier view, pixels (default %(default)s)")
    p.add_argument("--scheduler", metavar="ADDR", help="Dask scheduler, e.g. tcp://HOST:8786 (default: local "
                                                        "processes)")
    p.add_argument("--workers", type=int, help="local processes (default: chosen by the size of the take: a small "
                                               "one stays in this process)")
    p.add_argument("--chunk-frames", type=int, help="frames per block of work (default: split evenly)")
    p.add_argument("--out", required=True, help="markers (.c3d .trc .npz)")
    add_units(p, "the camera file's positions (translations)")
    p.set_defaults(run=_cmd_triangulate)


def _cmd_clean(args) -> tuple[str, ...]:
    from pathlib import Path

    from handcap.io import MARKER_WRITERS, check_not_input, read_markers, write_markers
    from handcap.layouts import load_layout
    from handcap.multiview.clean import clean_markers
    check_not_input(args.out, args.input)
    suffix = Path(args.out).suffix.lower()
    if suffix not in MARKER_WRITERS:
        raise HandcapError(f"{args.out}: cannot write '{suffix or 'no extension'}' marker files; "
                           f"use one of {', '.join(sorted(MARKER_WRITERS))}")
    for name in ("max_linear", "max_rigid", "max_spline"):
        if getattr(args, name) < 0:
            raise HandcapError(f"--{name.replace('_', '-')} must be 0 or more frames, got {getattr(args, name)}")
    layout = None if args.layout is None else load_layout(args.layout)
    markers = read_markers(args.input, units=args.units,
                           hand=None if layout is None else [m.name for m in layout.hand_markers])
    cleaned, report = clean_markers(
        markers, layout, radius=None if args.radius_mm is None else args.radius_mm / 1000, window=args.window,
        z=args.z, floor=args.floor_mm / 1000, max_linear_frames=args.max_linear, max_rigid_frames=args.max_rigid,
        max_spline_frames=args.max_spline, rigid_tolerance=args.rigid_tolerance_mm / 1000)
    from handcap.quality import plausibility as q
    cleaned = q.attach(cleaned, [*markers.warnings, *q.clean_warnings(report, markers.missing),
                                 *q.marker_warnings(cleaned, hand=None if layout is None else layout.names)])
    write_markers(cleaned, args.out)
    n = report.summary()
    print(q.summary(f"{args.out}: removed {n['cluster_removed']} samples away from their patch and "
                    f"{n['outlier_removed']} spikes; filled {n['rigid_filled']} rigid, {n['linear_filled']} linear, "
                    f"{n['spline_filled']} spline; {n['missing']} of {report.missing.size} samples missing",
                    q.marker_figures(cleaned, hand=None if layout is None else layout.names), cleaned.warnings))
    return cleaned.warnings


def add_clean(verbs) -> None:
    from handcap.layouts import SHIPPED
    from handcap.multiview import clean
    p = verbs.add_parser("clean", help="remove mislabelled points and spikes from 3D markers, fill short gaps",
                         description="DexterCap section 3.3: in every frame keep the largest cluster of each "
                                     "patch (or segment) of --layout, remove samples far from a local fit in a "
                                     "sliding window, then fill interior gaps by the rigid motion of the patch, "
                                     "linear and spline interpolation, each up to its own gap length. Nothing is "
                                     "extrapolated past the ends of a marker's data; longer gaps stay missing.")
    p.add_argument("input", help="labeled markers (.c3d .tsv .csv .trc .npz)")
    p.add_argument("--layout", help=f"marker layout for clustering and the rigid fill: {', '.join(SHIPPED)} or a "
                                    ".toml file (default: none, those steps are skipped)")
    p.add_argument("--radius-mm", type=float, help="cluster radius for every patch, millimetres (default: from "
                                                   "the layout's template)")
    p.add_argument("--window", type=int, default=clean.WINDOW, help="frames in the outlier window, odd "
                                                                    "(default %(default)s)")
    p.add_argument("--z", type=float, default=clean.Z, help="outlier threshold, robust standard deviations "
                                                            "(default %(default)s)")
    p.add_argument("--floor-mm", type=float, default=1000 * clean.FLOOR,
                   help="smaller deviations are never outliers, millimetres (default %(default)s)")
    p.add_argument("--max-rigid", type=int, default=clean.MAX_RIGID, metavar="FRAMES",
                   help="longest gap filled by the rigid motion of the patch (default %(default)s; 0: off)")
    p.add_argument("--max-linear", type=int, default=clean.MAX_LINEAR, metavar="FRAMES",
                   help="longest gap filled by linear interpolation (default %(default)s; 0: off)")
    p.add_argument("--max-spline", type=int, default=clean.MAX_SPLINE, metavar="FRAMES",
                   help="longest gap filled by a cubic spline (default %(default)s; 0: off)")
    p.add_argument("--rigid-tolerance-mm", type=float, default=1000 * clean.RIGID_TOLERANCE,
                   help="largest RMS residual of a rigid fill's fit, millimetres (default %(default)s)")
    p.add_argument("--out", required=True, help="cleaned markers (.c3d .trc .npz)")
    add_units(p)
    p.set_defaults(run=_cmd_clean)
