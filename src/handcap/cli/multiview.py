"""``handcap triangulate`` and ``clean``."""

from __future__ import annotations

from handcap.cli.common import add_units, sync_arg
from handcap.core.errors import HandcapError
from handcap.layouts import SHIPPED
from handcap.multiview import clean
from handcap.multiview.sync import MAX_OFFSET_S
from handcap.steps import multiview


def _cmd_triangulate(a):
    sync = sync_arg(a)
    if a.sync is None and a.sync_reference is not None:
        raise HandcapError("--sync-reference goes with --sync")
    return multiview.triangulate(a.detections, a.cameras, a.out, min_views=a.min_views, threshold_px=a.threshold_px,
                                 chunk_frames=a.chunk_frames, scheduler=a.scheduler, workers=a.workers, units=a.units,
                                 handedness=not a.no_handedness_repair,
                                 sync=sync, sync_reference=a.sync_reference, max_offset_s=a.max_offset)


def _cmd_clean(a):
    for name in ("max_linear", "max_rigid", "max_spline"):
        if getattr(a, name) is not None and getattr(a, name) < 0:
            raise HandcapError(f"--{name.replace('_', '-')} must be 0 or more frames, got {getattr(a, name)}")
    return multiview.clean(a.input, a.out, layout=a.layout, radius=None if a.radius_mm is None else a.radius_mm / 1000,
                           window=a.window, z=a.z, floor=a.floor_mm / 1000, max_linear_frames=a.max_linear,
                           max_rigid_frames=a.max_rigid, max_spline_frames=a.max_spline,
                           rigid_tolerance=a.rigid_tolerance_mm / 1000, units=a.units)


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
    p.add_argument("--threshold-px", type=float, default=None,
                   help="reprojection error of an inlier view, pixels (default 5 for markers, 12 for hand "
                        "keypoints)")
    p.add_argument("--no-handedness-repair", action="store_true",
                   help="hand keypoints: trust each view's left/right labels instead of deciding them by agreement "
                        "between the views")
    p.add_argument("--sync", action="append", metavar="auto|CAM=FRAMES",
                   help="cameras not triggered together (consumer cameras, phones): 'auto' finds each camera's "
                        "offset from the detections; CAM=FRAMES (repeated, or joined by commas) gives it: CAM's "
                        "frame f shows the reference camera's frame f + FRAMES (fractions interpolate); cameras not "
                        "named 0. Without it the cameras are taken as synchronised, and a warning says when they "
                        "seem not to be")
    p.add_argument("--sync-reference", metavar="CAM", help="the camera whose frames the output counts (default: "
                                                          "the detections' first camera)")
    p.add_argument("--max-offset", type=float, default=MAX_OFFSET_S, metavar="SECONDS",
                   help="how far --sync auto searches, seconds either way (default %(default)g)")
    p.add_argument("--scheduler", metavar="ADDR", help="Dask scheduler, e.g. tcp://HOST:8786 (default: local "
                                                        "processes)")
    p.add_argument("--workers", type=int, help="local processes (default: chosen by the size of the take: a small "
                                               "one stays in this process)")
    p.add_argument("--chunk-frames", type=int, help="frames per block of work (default: split evenly)")
    p.add_argument("--out", required=True, help="markers (.c3d .trc .npz)")
    add_units(p, "the camera file's positions (translations)")
    p.add_argument("--rig-units", dest="units", choices=("mm", "cm", "m"), help="the same as --units")
    p.set_defaults(run=_cmd_triangulate)


def add_clean(verbs) -> None:
    p = verbs.add_parser("clean", help="remove mislabelled points and spikes from 3D markers, fill short gaps",
                         description="DexterCap section 3.3: in every frame keep the largest cluster of each "
                                     "patch (or segment) of --layout, remove samples far from a local fit in a "
                                     "sliding window, then fill interior gaps by the rigid motion of the patch, "
                                     "linear and spline interpolation, each up to its own gap length. Nothing is "
                                     "extrapolated past the ends of a marker's data; longer gaps stay missing.")
    p.add_argument("input", help="labeled markers (.c3d .tsv .csv .txt .trc .npz)")
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
    p.add_argument("--max-linear", type=int, metavar="FRAMES",
                   help=f"longest gap filled by linear interpolation (default {clean.MAX_LINEAR_S:g} s of the take's "
                        f"frames: {clean.MAX_LINEAR} at 100 Hz, none at 20 Hz; 0: off)")
    p.add_argument("--max-spline", type=int, metavar="FRAMES",
                   help=f"longest gap filled by a cubic spline (default {clean.MAX_SPLINE_S:g} s of the take's frames: "
                        f"{clean.MAX_SPLINE} at 100 Hz, 2 at 20 Hz, none at 4 Hz; 0: off)")
    p.add_argument("--rigid-tolerance-mm", type=float, default=1000 * clean.RIGID_TOLERANCE,
                   help="largest RMS residual of a rigid fill's fit, millimetres (default %(default)s)")
    p.add_argument("--out", required=True, help="cleaned markers (.c3d .trc .npz)")
    add_units(p)
    p.set_defaults(run=_cmd_clean)
