"""``handcap track-object`` and ``metrics``."""

from __future__ import annotations

from handcap.cli.common import add_hand_model, add_units
from handcap.steps import metrics, objects


def _cmd_track_object(a):
    return objects.track_object(a.input, a.out, markers=a.markers, canonical=a.canonical, name=a.name,
                                threshold=a.threshold_mm / 1000, units=a.units, articulated=a.articulated,
                                start=a.start, labeled=a.labeled, filled=a.filled)


def _cmd_metrics(a):
    return metrics.metrics(a.motion, truth=a.truth, markers=a.markers, obj=a.object, object_mesh=a.object_mesh,
                           attachment=a.attachment, leave_one_out=a.leave_one_out, out=a.out,
                           hand_model=a.hand_model, mano_dir=a.mano_dir)


def add_objects(verbs) -> None:
    p = verbs.add_parser("track-object", help="6-DoF motion of a rigid object from its markers",
                         description="Kabsch with RANSAC per frame; the object's marker geometry is estimated from "
                                     "the take unless --canonical gives it. Frames with fewer than 3 markers are "
                                     "reported and left empty (NaN), not guessed.")
    p.add_argument("input", help="labeled markers")
    p.add_argument("--markers",
                   help="comma-separated names of the object's markers (3 or more); patterns such as 'boite:*' work")
    p.add_argument("--articulated", metavar="OBJECT",
                   help="an articulated object instead: cube2x2 (the shipped 2x2x2 cube: pose, layer angles and "
                        "the moves, key 'moves', printed) or a TOML description of your own (parts with their "
                        "markers, revolute joints: pose and joint angles)")
    p.add_argument("--start", metavar="LABELLED",
                   help="with --articulated cube2x2: the input holds unlabelled points, and this file the cube's "
                        "labelled markers in at least one frame (the first frame in which every cubie shows 2 "
                        "starts); the cube's markers are labelled by following its cubies")
    p.add_argument("--labeled", metavar="FILE", help="with --start: also write the cube's labelled markers here")
    p.add_argument("--filled", metavar="FILE",
                   help="with --articulated cube2x2: also write the cube's markers with their gaps filled from the "
                        "track (each hidden marker where its cubie is)")
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
