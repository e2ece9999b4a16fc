"""``handcap calibrate``: cameras from a checkerboard or ChArUco board."""

from __future__ import annotations

import argparse

from handcap.core.errors import HandcapError


def _camera_toml_out(out: str, inputs) -> None:
    """Check a camera file's name before the slow work: .toml, in a folder that can be written, not an input."""
    from handcap.core.cameras import check_rig_suffix
    from handcap.io import check_output
    check_rig_suffix(out)
    check_output(out, *inputs)


def _cmd_calibrate_intrinsics(args) -> tuple[str, ...]:
    from handcap.core.cameras import CameraRig
    from handcap.multiview.boards import detect_in_files, parse_board
    from handcap.multiview.calibration import calibrate_intrinsics
    board = parse_board(args.board)
    _camera_toml_out(args.out, args.inputs)
    detections = detect_in_files(args.inputs, board, every=args.every)
    result = calibrate_intrinsics(detections, name=args.name, fix_k3=args.fix_k3,
                                  reject_outliers=not args.keep_outliers)
    from handcap.quality import plausibility as q
    rig = q.attach(CameraRig([result.camera]), q.camera_warnings(result.rms, names=[result.camera.name]))
    rig.save(args.out)  # the warnings go to the file's [metadata]
    warnings = rig.warnings
    camera = result.camera
    (fx, fy), (cx, cy) = camera.matrix[[0, 1], [0, 1]], camera.matrix[:2, 2]
    print(f"{args.out}: camera {camera.name}, {camera.size[0]}x{camera.size[1]} px, f = {fx:.2f}, {fy:.2f} px, "
          f"principal point ({cx:.1f}, {cy:.1f}) px, k1 k2 p1 p2 k3 = "
          f"{' '.join(f'{k:.4g}' for k in camera.distortions)}")
    print(f"reprojection RMS {result.rms:.3f} px over {len(result.views)} views (board seen in "
          f"{int(detections.found.sum())} of {detections.n_frames} frames), worst view "
          f"{result.labels[int(result.view_rms.argmax())]} {result.view_rms.max():.3f} px"
          + (f"; rejected as outliers: {', '.join(detections.labels[t] for t in result.rejected)}"
             if len(result.rejected) else ""))
    print("quality: " + (f"{len(warnings)} warning(s), see below" if warnings else "no warnings"))
    return warnings


def _cmd_calibrate_rig(args) -> tuple[str, ...]:
    from handcap.io.camera_formats import read_rig
    from handcap.multiview.boards import detect_in_files, parse_board
    from handcap.multiview.calibration import calibrate_rig
    board = parse_board(args.board)
    names = args.names
    if names is not None and len(names) == 1 and "," in names[0]:
        names = [n.strip() for n in names[0].split(",")]
    if names is not None and len(names) != len(args.recordings):
        raise HandcapError(f"{len(names)} camera names for {len(args.recordings)} cameras; give one name per camera")
    _camera_toml_out(args.out, args.recordings + ([args.intrinsics] if args.intrinsics else []))
    cameras = None if args.intrinsics is None else read_rig(args.intrinsics, positions=False)  # extrinsics unused
    detections = [detect_in_files(path, board, every=args.every) for path in args.recordings]
    result = calibrate_rig(detections, names=names, cameras=cameras, refine_intrinsics=args.refine_intrinsics,
                           fix_k3=args.fix_k3, origin=args.origin, origin_frame=args.origin_frame,
                           loss=args.loss, f_scale=args.f_scale)
    from handcap.quality import plausibility as q
    rig = q.attach(result.rig, q.camera_warnings(result.rms, names=result.names))
    rig.save(args.out)  # the warnings go to the file's [metadata]
    warnings = rig.warnings
    print(result.summary())
    print(f"{args.out}: {len(result.rig)} cameras; " + (f"{len(warnings)} warning(s), see below" if warnings
                                                        else "no warnings"))
    return warnings


def add_calibrate(verbs) -> None:
    from handcap.multiview.calibration import LOSSES, ORIGINS
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
    q.add_argument("--out", required=True, help="rig file (.toml)")
    q.set_defaults(run=_cmd_calibrate_rig)
