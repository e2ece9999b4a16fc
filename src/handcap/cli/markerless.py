"""``handcap keypoints import`` and ``fit-keypoints``."""

from __future__ import annotations

from handcap.cli.common import add_hand_model, add_units, names_arg
from handcap.markerless import FORMATS
from handcap.markerless.fit import ROBUST_SCALE
from handcap.steps import markerless


def _cmd_keypoints_import(a):
    cameras = names_arg([a.cameras]) if a.cameras else None
    return markerless.keypoints_import(a.inputs, a.format, a.out, rate=a.rate, cameras=cameras)


def _cmd_keypoints_detect(a):
    return markerless.keypoints_detect(a.inputs, a.out, rate=a.rate, mirrored=a.mirrored, retry=not a.no_retry,
                                       max_hands=a.max_hands)


def _cmd_fit_keypoints(a):
    return markerless.fit_keypoints(a.input, a.out, label=a.hand, side=a.side, fit_shape=not a.no_shape,
                                    robust_scale=a.robust_mm / 1000, filter_cutoff=a.filter_cutoff, units=a.units,
                                    hand_model=a.hand_model, mano_dir=a.mano_dir)


def _cmd_markerless(a):
    return markerless.markerless(a.input, a.out, intrinsics=a.intrinsics, camera=a.camera, label=a.hand,
                                 side=a.side, method=a.method, scale=a.scale, rate=a.rate,
                                 hand_model=a.hand_model, mano_dir=a.mano_dir, obj=a.object,
                                 object_pose=a.object_pose, object_points=a.object_points,
                                 object_frame=a.object_frame, contact=a.contact, object_units=a.object_units,
                                 object_out=a.object_out)


def add_markerless(verbs) -> None:
    p = verbs.add_parser("keypoints", help="2D hand keypoints: detect them in images and videos, or import them",
                         description="import: MediaPipe arrays (.npy), OpenPose JSON folders or COCO keypoint "
                                     "files to handcap's 2D detections file (marker names LABEL:wrist ... in the "
                                     "usual 21-point order), which triangulate reads. One input per camera; "
                                     "several inputs of one camera (a file per handedness label) are its "
                                     "candidate hands.")
    what = p.add_subparsers(dest="what", metavar="WHAT")
    what.required = True
    q = what.add_parser("detect", help="2D hand keypoints of images or videos (MediaPipe's landmarker)",
                        description="MediaPipe's hand landmarker (the markerless extra: pip install "
                                    "'handcap[markerless]' && pip install --no-deps mediapipe==0.10.14), and where it "
                                    "finds no hand, retries: around the hand of the frame before, the image "
                                    "padded, enlarged crops, turned, mirrored. One input per camera: a folder of "
                                    "images, a video (read frame by frame) or an image, named after the camera; a "
                                    "take's folder of videos or of folders of images gives a camera to each.")
    q.add_argument("inputs", nargs="+", help="folders of images, videos or images, one per camera (or a folder "
                                              "of them)")
    q.add_argument("--out", required=True, help="2D detections file to write (.npz)")
    q.add_argument("--rate", type=float, help="frames per second (default: the video's, else 30)")
    q.add_argument("--mirrored", action="store_true", help="the images are mirrored (a selfie camera): keep "
                                                           "MediaPipe's left/right labels as they are")
    q.add_argument("--no-retry", action="store_true", help="the landmarker alone, no retries")
    q.add_argument("--max-hands", type=int, default=2, help="most hands per image (default %(default)s)")
    q.set_defaults(run=_cmd_keypoints_detect)
    q = what.add_parser("import", help="keypoint files of another tool to a 2D detections file",
                        description="mediapipe-npy: arrays (C, T, 21, 2|3) or (T, 21, 2|3) in pixels, negative for "
                                    "missing, the label from the file name (left/right). openpose-json: a folder "
                                    "of *_keypoints.json per camera. coco-json: a COCO keypoint file (or mmpose "
                                    "results) per camera, COCO-WholeBody hands included.")
    q.add_argument("inputs", nargs="+", help="keypoint files or folders")
    q.add_argument("--format", required=True, choices=FORMATS, help="the inputs' format")
    q.add_argument("--rate", type=float, required=True, help="frames per second of the videos")
    q.add_argument("--cameras", help="camera names, comma-separated: one per input (mediapipe-npy: one per row of "
                                     "the camera axis, the same in every file); default: from the inputs' names")
    q.add_argument("--out", required=True, help="2D detections file to write (.npz)")
    q.set_defaults(run=_cmd_keypoints_import)

    p = verbs.add_parser("fit-keypoints", help="hand motion (pose and shape) from 3D hand keypoints",
                         description="Umeyama's similarity of the six palm points (wrist and finger bases) checks "
                                     "the scale and places the hand; the shape is fitted to the take's median bone "
                                     "lengths; then every frame's pose is solved within the joint limits under a "
                                     "robust loss (wrong keypoints count little). Writes the usual hand motion.")
    p.add_argument("input", help="3D keypoints (.npz from triangulate, .c3d .trc ...), names [LABEL:]wrist ...")
    p.add_argument("--out", required=True, help="hand motion to write (.npz)")
    p.add_argument("--hand", help="the hand to fit when the file holds several (its label, e.g. right)")
    p.add_argument("--side", choices=("right", "left"), help="hand side (default: the label when it is one, else "
                                                             "right)")
    p.add_argument("--no-shape", action="store_true", help="keep the average hand's shape")
    p.add_argument("--robust-mm", type=float, default=1000 * ROBUST_SCALE,
                   help="scale of the robust loss on keypoint residuals, mm (default %(default)g)")
    p.add_argument("--filter-cutoff", type=float, help="low-pass the motion at this frequency, Hz")
    add_units(p)
    add_hand_model(p)
    p.set_defaults(run=_cmd_fit_keypoints)

    p = verbs.add_parser("markerless", help="hand pose and shape of a steady grasp from one video's 2D keypoints",
                         description="The paper's single-video capture: the hand held still and turned in front of "
                                     "one camera is a stationary hand seen by a moving virtual camera. Structure "
                                     "from motion of the 21 keypoints (a sparse bundle adjustment, robust to wrong "
                                     "keypoints), the hand model fitted to it, then (--method joint, default) pose, "
                                     "shape and camera poses together from the reprojection error (the paper's "
                                     "eq. 2). One camera cannot measure the hand's size: the average adult's is "
                                     "taken unless --scale says otherwise. Writes the hand motion in the camera's "
                                     "frame.")
    p.add_argument("input", help="2D keypoints of the video (.npz from handcap keypoints import)")
    p.add_argument("--intrinsics", required=True,
                   help="the camera: a cameras file (.toml .yml ...; --camera names it) or "
                        "fx,fy,cx,cy[,k1,k2,p1,p2,k3] in pixels")
    p.add_argument("--camera", help="the camera to use when the keypoints or the cameras file hold several")
    p.add_argument("--hand", help="the hand label to start from when frames show several (default: the most given)")
    p.add_argument("--side", choices=("right", "left"), help="hand side (default: the label when it is one, else "
                                                             "right)")
    p.add_argument("--method", choices=("joint", "two-stage"), default="joint",
                   help="joint: eq. 2 after the two stages (default); two-stage: the paper's pipeline")
    p.add_argument("--scale", type=float, help="the hand's size relative to an average adult's (default: "
                                               "measured against the object's contact map with --contact, else 1)")
    p.add_argument("--rate", type=float, help="frames per second (default: the keypoints file's)")
    p.add_argument("--out", required=True, help="hand motion to write (.npz)")
    g = p.add_argument_group("held object", "the object's mesh and its pose in one frame (given, or fitted to "
                                            "a depth camera's points of it by ICP), carried to every frame by "
                                            "the virtual cameras; a contact map measures the hand's size and "
                                            "refines the grasp")
    g.add_argument("--object", help="the object's mesh (.ply .obj .stl ..., or a contact map .npz)")
    g.add_argument("--object-pose", help="its pose in --object-frame: object to camera, a 4 x 4 matrix (text "
                                         "file of 16 numbers, .npy, or .npz with 'pose'); ICP's start with "
                                         "--object-points")
    g.add_argument("--object-points", help="points of its surface in --object-frame, camera frame (.npz with "
                                           "'points', .ply ...)")
    g.add_argument("--object-frame", type=int, default=0, help="the frame the object's pose or points belong "
                                                               "to (default %(default)s)")
    g.add_argument("--contact", help="contact map .npz (object mesh and which vertices were touched)")
    g.add_argument("--object-units", choices=("m", "cm", "mm"), default="m",
                   help="unit of the object's mesh, pose and points (default %(default)s; contact maps are metres)")
    g.add_argument("--object-out", help="object motion to write (default: OUT's name with -object)")
    add_hand_model(p)
    p.set_defaults(run=_cmd_markerless)
