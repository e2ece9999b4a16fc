"""``handcap calibrate``: cameras from a checkerboard or ChArUco board."""

from __future__ import annotations

import argparse

from handcap.cli.common import names_arg, sync_arg
from handcap.core.errors import HandcapError
from handcap.multiview.calibration import LOSSES, ORIGINS
from handcap.steps import calibrate


def _cmd_calibrate_intrinsics(a):
    return calibrate.intrinsics(a.inputs, a.out, board=a.board, name=a.name, every=a.every, fix_k3=a.fix_k3,
                                keep_outliers=a.keep_outliers)


def _cmd_calibrate_rig(a):
    return calibrate.rig(a.recordings, a.out, board=a.board, names=names_arg(a.names), every=a.every,
                         intrinsics=a.intrinsics, refine_intrinsics=a.refine_intrinsics, fix_k3=a.fix_k3,
                         origin=a.origin, origin_frame=a.origin_frame, loss=a.loss, f_scale=a.f_scale,
                         sync=_sync_arg(a), max_offset=a.max_offset)


def _sync_arg(a):
    if a.max_offset is not None and a.max_offset < 1:
        raise HandcapError(f"--max-offset must be at least one frame, got {a.max_offset}")
    return sync_arg(a)


def add_calibrate(verbs) -> None:
    board_help = ("checkerboard:COLSxROWS:SQUARE_M (inner corners, metres) or "
                  "charuco:COLSxROWS:SQUARE_M[:MARKER_M][:DICT][:inverted] (squares; marker 0.75 x square and "
                  "DICT_4X4_1000 by default), e.g. charuco:4x5:0.054:0.0405:DICT_4X4_1000:inverted")
    p = verbs.add_parser("calibrate", help="calibrate cameras from a checkerboard or ChArUco board",
                         description="intrinsics: one camera's matrix and distortion (OpenCV, k1 k2 p1 p2 k3) "
                                     "from images or a video of the board. rig: every camera of a rig from "
                                     "synchronised recordings of the board (frame number = time), by a bundle "
                                     "adjustment of all cameras and board poses. Both write anipose-style TOML.")
    what = p.add_subparsers(dest="what", metavar="WHAT")
    what.required = True

    q = what.add_parser("intrinsics", help="one camera's matrix and lens distortion",
                        description="Find the board in the images (or video frames), calibrate with OpenCV and "
                                    "drop views reprojecting far worse than the others (3 x the median, and "
                                    "0.5 px). Writes one camera at the origin.")
    q.add_argument("inputs", nargs="+", metavar="IMAGES_OR_VIDEO",
                   help="image files, a folder of images, or one video")
    q.add_argument("--board", required=True, help=board_help)
    q.add_argument("--name", help="camera name (default: the file or folder name)")
    q.add_argument("--every", type=int, default=1, metavar="N", help="video: use every N-th frame (default 1)")
    q.add_argument("--fix-k3", action="store_true", help="keep k3 = 0 (for few views)")
    q.add_argument("--keep-outliers", action="store_true", help="keep every view")
    q.add_argument("--out", required=True, help="camera file (.toml)")
    q.set_defaults(run=_cmd_calibrate_intrinsics)

    q = what.add_parser("rig", help="all cameras of a rig from synchronised recordings of the board",
                        description="One video or folder of images per camera, all of the same frames (frame t "
                                    "of every camera is the same instant). Each camera's intrinsics are "
                                    "calibrated first (or read from --intrinsics); the cameras are placed by "
                                    "chaining relative poses from shared views of the board, then all cameras "
                                    "and board poses are refined by a robust bundle adjustment. The world is the "
                                    "board at --origin-frame (x along the board, z out of its printed face) or "
                                    "the first camera. Cameras that never see the board or share no view with "
                                    "the others are named in the error.")
    q.add_argument("recordings", nargs="+", metavar="VIDEO_OR_FOLDER", help="one video or image folder per camera")
    q.add_argument("--board", required=True, help=board_help)
    q.add_argument("--names", nargs="+", metavar="NAME",
                   help="camera names in the order of the recordings (default: their file names)")
    q.add_argument("--every", type=int, default=1, metavar="N", help="videos: use every N-th frame (default 1)")
    q.add_argument("--intrinsics", metavar="FILE", help="known intrinsics: a camera file (anipose or caliscope "
                                                        "TOML, OpenCV YAML/XML, Qualisys QCA) with one camera per "
                                                        "recording, in the same order")
    q.add_argument("--refine-intrinsics", action=argparse.BooleanOptionalAction, default=None,
                   help="refine the intrinsics in the bundle adjustment (default: yes, unless --intrinsics)")
    q.add_argument("--fix-k3", action="store_true", help="keep k3 = 0")
    q.add_argument("--origin", choices=ORIGINS, default="board",
                   help="world frame: the board at --origin-frame, or the first camera (default %(default)s)")
    q.add_argument("--origin-frame", type=int, metavar="FRAME",
                   help="frame number of the board pose that is the world (default: the first frame in which "
                        "the first camera sees the board)")
    q.add_argument("--loss", choices=LOSSES, default="soft_l1", help="robust loss (default %(default)s)")
    q.add_argument("--f-scale", type=float, default=1.0, metavar="PX",
                   help="pixel error where the robust loss starts to discount (default %(default)s)")
    q.add_argument("--sync", action="append", metavar="auto|CAM=FRAMES",
                   help="cameras not triggered together (consumer cameras, phones): 'auto' finds each camera's "
                        "offset from the board's motion (each camera's view of the board, one rigid transform "
                        "between two cameras at the right offset); CAM=FRAMES (repeated, or joined by commas) "
                        "gives it: CAM's frame f shows the first camera's frame f + FRAMES (fractions "
                        "interpolate); cameras not named 0. The recordings may then differ in length")
    q.add_argument("--max-offset", type=int, metavar="FRAMES",
                   help="how far --sync auto searches, frames either way (default: half the shortest recording)")
    q.add_argument("--out", required=True, help="rig file (.toml)")
    q.set_defaults(run=_cmd_calibrate_rig)
