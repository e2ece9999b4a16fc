"""``handcap detect``: camera images of coded patches to 2D detections."""

from __future__ import annotations

from handcap.cli.common import frames_arg, sync_arg
from handcap.multiview.sync import MAX_OFFSET_S
from handcap.steps import detect as detect_step
from handcap.steps import overlay as overlay_step


def _cmd_detect(a):
    return detect_step.detect(a.inputs, a.out, rig=a.rig, pattern=a.pattern, alphabet=a.alphabet, rate=a.rate,
                              corner_weights=a.corner_weights, reader_weights=a.reader_weights,
                              refiner_weights=a.refiner_weights, refine=not a.no_refine, threshold=a.threshold,
                              track=not a.whole_frames, checker_weights=a.checker_weights,
                              checker=not a.no_checker, adapt_steps=a.adapt_steps, denoise=not a.no_denoise,
                              response=a.response, frames=frames_arg(a.frames), every=a.every,
                              views=not a.no_views, sync=sync_arg(a), max_offset_s=a.max_offset,
                              workers=a.workers, scheduler=a.scheduler)


def add_detect(verbs) -> None:
    p = verbs.add_parser("detect", help="find and name the corners of coded patches in images or videos",
                         description="Corners (heatmap network, then a refiner network on full-resolution "
                                     "crops), blocks (white squares between them), their tags "
                                     "(reader network), a vote over the template's patches and the corner ids. "
                                     "Each input is one camera: a folder of images, a video or an image, named "
                                     "after the camera; a take's folder of videos or of folders of images gives "
                                     "a camera to each. Writes the 2D detections file that triangulate reads, "
                                     "with one row per read block as well.")
    p.add_argument("inputs", nargs="+", help="folders of images, videos or image files, one per camera (or a folder of "
                                           "them)")
    p.add_argument("--out", required=True, help="detections file to write (.npz)")
    p.add_argument("--rig", help="cameras file; the inputs must be named after its cameras")
    p.add_argument("--pattern", help="the session's pattern.toml (handcap pattern): without it, blocks only")
    p.add_argument("--alphabet", help="glyphs of the printed tags (default: the template's; DexterCap's patches: "
                                      "0123456789ACEFHPUY)")
    p.add_argument("--rate", type=float, help="frames per second (default 20, with a warning)")
    p.add_argument("--frames", metavar="A:B",
                   help="read only input frames A to B-1 (0-based; either may be left out), e.g. 0:200 to try the "
                        "first ten seconds of a long take")
    p.add_argument("--every", type=int, default=1, metavar="N",
                   help="read every N-th frame (of --frames): the frames read make a take of their own at 1/N of the "
                        "rate (the file records first_frame and frame_step; overlay reads the same frames)")
    p.add_argument("--threshold", type=float, help="least corner probability (default 0.5 from the refiner, 0.3 "
                                                   "from the corner network with --no-refine)")
    p.add_argument("--no-refine", action="store_true", help="keep the corner network's positions (no refiner)")
    p.add_argument("--whole-frames", action="store_true",
                   help="search every frame whole (default: a camera's frame is searched around the patches its "
                        "previous frame showed, and whole every 10th frame or where that search may have missed "
                        "some)")
    p.add_argument("--corner-weights", help="corner network weights instead of the shipped ones")
    p.add_argument("--refiner-weights", help="corner refiner weights instead of the shipped ones")
    p.add_argument("--reader-weights", help="block reader weights instead of the shipped ones")
    p.add_argument("--checker-weights", help="block checker weights instead of the shipped ones")
    p.add_argument("--no-checker", action="store_true",
                   help="check the voted blocks with the hand-set rules instead of the learned checker")
    p.add_argument("--adapt-steps", type=int, default=0, metavar="N",
                   help="without --pattern: fine-tune a copy of the reader on the take's sure readings for N steps "
                        "(200: about 80 s for 20 photographs), which then vouches for more tags of the take's font "
                        "and glyph layout, a little more often wrong (README); default 0, the shipped reader only")
    p.add_argument("--no-views", action="store_true",
                   help="with --pattern, leave a white square a camera could not read unnamed (default: it takes the "
                        "tag of the template's square that the camera's neighbouring frames, or with --rig the other "
                        "cameras, place on it to 1.5 px; the refiner also looks again where the neighbouring frames, "
                        "or with --rig the other cameras, place squares the camera found none of; the file marks "
                        "such blocks in block_from_views)")
    p.add_argument("--sync", action="append", metavar="auto|CAM=FRAMES",
                   help="cameras not triggered together, for naming the squares a camera could not read from the "
                        "other cameras (with --rig and --pattern): auto finds each camera's offset from the corners "
                        "the cameras named, or give CAM=FRAMES (repeatable or comma-joined; camera CAM's frame f shows "
                        "the first camera's frame f + FRAMES, in the frames of the file written, as triangulate "
                        "--sync counts them). Default: the cameras are synchronised")
    p.add_argument("--max-offset", type=float, default=MAX_OFFSET_S, metavar="SECONDS",
                   help="how far --sync auto searches, seconds either way (default %(default)g)")
    p.add_argument("--workers", type=int, default=1, metavar="N",
                   help="cameras detected at once, each in a process of its own with a share of the cores (default 1: "
                        "one camera after another; on two cores that is as fast, README)")
    p.add_argument("--scheduler", metavar="ADDR",
                   help="a Dask scheduler (tcp://HOST:8786) to detect the cameras on, one camera per task; its workers "
                        "need handcap and the inputs at the same paths")
    p.add_argument("--no-denoise", action="store_true",
                   help="search noisy images as they are (default: an image with more sensor noise than the networks "
                        "learned, about 5 grey levels, is denoised first; a warning says how many)")
    p.add_argument("--response", choices=("auto", "linear", "srgb"), default="auto",
                   help="the cameras' response to light: linear (a machine-vision camera's raw grey levels) or sRGB "
                        "(display-encoded, as phones, webcams and most video record), decoded to linear light before "
                        "the search; default auto: chosen for each camera on its first frames that read tags, "
                        "searched both ways (a warning names the cameras read as sRGB)")
    p.set_defaults(run=_cmd_detect)


def _cmd_overlay(a):
    return overlay_step.overlay(a.detections, a.inputs, a.out, every=a.every, markers=a.markers, rig=a.rig,
                                force=a.force)


def add_overlay(verbs) -> None:
    p = verbs.add_parser("overlay", help="draw 2D detections over the images they came from, to check them by eye",
                         description="One JPEG per camera and frame (OUT/CAMERA/FRAME.jpg): every named corner a "
                                     "dot in its owner's colour (right hand orange, left hand blue, objects in "
                                     "turn), each patch's name over it, every read tag outlined with its text and "
                                     "its underlined side drawn thick (a tag read upside down shows); with --markers "
                                     "and --rig the 3D markers reprojected as crosses. 2D hand keypoints (handcap "
                                     "keypoints) are drawn joined by their hand's bones.")
    p.add_argument("detections", help="2D detections file (handcap detect's, or any other with named corners)")
    p.add_argument("inputs", nargs="+", help="the images or videos detect was given, one per camera (or a folder of "
                                             "them), matched to the file's cameras by name")
    p.add_argument("--out", required=True, help="folder to write the pictures into")
    p.add_argument("--every", type=int, default=1, metavar="N", help="draw every N-th frame (default 1: all)")
    p.add_argument("--markers", help="3D markers (triangulate's or clean's) to draw reprojected; needs --rig")
    p.add_argument("--rig", help="cameras file to reproject --markers with")
    p.add_argument("--force", action="store_true", help="write into a folder that already holds files")
    p.set_defaults(run=_cmd_overlay)
