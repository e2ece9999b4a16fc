"""``handcap synth`` (a synthetic capture with its truth) and ``handcap demo``."""

from __future__ import annotations

from handcap import demo
from handcap.core.errors import HandcapError
from handcap.layouts import SHIPPED
from handcap.steps import synth
from handcap.synth.cube import CUBE_MOTION
from handcap.synth.motions import MOTIONS
from handcap.synth.objects import OBJECTS
from handcap.synth.scene import SynthConfig

_SETTINGS = ("layout", "frames", "rate", "seed", "side", "object", "cameras", "min_views", "noise_mm",
             "pixel_noise", "dropout", "ghost_rate", "swap_rate", "outlier_rate", "placement_mm", "subject_seed")


def _cmd_synth(a):
    betas = None if a.betas is None else tuple(float(b) for b in a.betas.split(","))
    motion = a.motion or (CUBE_MOTION if a.moves is not None else SynthConfig.motion)
    settings = {k: getattr(a, k) for k in _SETTINGS}
    if a.layout is None:  # images film printed patches: the patch layout unless another is asked for
        settings["layout"] = "dense-patches" if a.images else SynthConfig.layout
    config = None if a.scene else SynthConfig(**settings, betas=betas, motion=motion,
                                              moves=a.moves, max_view_angle_deg=a.max_view_angle)
    return synth.synth(a.out, config, scene=a.scene, force=a.force, images=a.images, image_scale=a.image_scale,
                       image_style=a.image_style, image_response=a.image_response)


def _cmd_demo(a):
    if a.images and a.markerless:
        raise HandcapError("--images and --markerless are two demos: choose one")
    if a.images:
        return synth.demo_images(a.out or "demo-images")
    if a.markerless:
        return synth.demo_markerless(a.out or "demo-markerless")
    return demo.demo(a.out or "demo-output")


def add_synth(verbs) -> None:
    d = SynthConfig()
    p = verbs.add_parser("synth", help="make a synthetic capture with ground truth",
                         description="Move the open hand (and an object) through a motion, film its markers with a "
                                     "rig of cameras, decide visibility by ray casting and add capture faults. "
                                     "Writes markers.c3d/.npz, points.npz, detections.npz, cameras.toml, truth.npz "
                                     "and scene.toml into OUT; the same settings give the same bytes.")
    p.add_argument("--layout", help=f"marker layout: {', '.join(SHIPPED)} or a .toml file (default {d.layout}; "
                                    "dense-patches with --images)")
    p.add_argument("--motion", choices=MOTIONS + (CUBE_MOTION,),
                   help=f"default {d.motion}, or {CUBE_MOTION} with --moves")
    p.add_argument("--frames", type=int, default=d.frames)
    p.add_argument("--rate", type=float, default=d.rate, help="frames per second (default %(default)s)")
    p.add_argument("--seed", type=int, default=d.seed)
    p.add_argument("--side", default=d.side, choices=("right", "left"))
    p.add_argument("--object", default=d.object, choices=OBJECTS + ("auto", "none"),
                   help="object to manipulate (auto: the motion's usual one)")
    p.add_argument("--moves", help=f"the hand turns the 2x2x2 cube's layers through these moves, e.g. \"R U R' U' D2\" "
                                   f"(motion {CUBE_MOTION}; without --moves it draws a 10-move scramble); the take "
                                   f"lasts as long as they need and truth.npz holds every layer's angle")
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
    p.add_argument("--images", action="store_true",
                   help="also film the patched hand (and the held cuboid, cylinder or sphere, with its faces' "
                        "patches) from every camera: images/CAMERA/FRAME.png, image_truth.npz (every visible corner "
                        "and tag) and pattern.toml (needs a patch layout and the extra 'images')")
    p.add_argument("--image-scale", type=float, default=1.0,
                   help="image size relative to the cameras' (default %(default)s: 2448 x 2048)")
    p.add_argument("--image-style", choices=("default", "clean"), default="default",
                   help="default: blur, noise, exposure, glints and occluders drawn per image; clean: none")
    p.add_argument("--image-response", choices=("linear", "srgb"), default="linear",
                   help="the cameras' response: grey levels linear in the light, as a machine-vision camera records "
                        "(default), or encoded as sRGB, as phones, webcams and most video do")
    p.add_argument("--scene", help="take every setting from a scene.toml written by an earlier run")
    p.add_argument("--out", required=True, help="output folder (new or empty, unless --force)")
    p.add_argument("--force", action="store_true", help="write into --out even if it holds files (those of the "
                                                        "same names are replaced)")
    p.set_defaults(run=_cmd_synth)

    p = verbs.add_parser("demo", help="run the main job on built-in data into demo-output/",
                         description="Synthetic DexterCap-style session -> marker calibration -> solve -> "
                                     "5 Hz smoothing -> metrics against the truth, written to demo-output/.")
    p.add_argument("--out", help="output folder, rewritten on every run (default demo-output/, with --images "
                                 "demo-images/, with --markerless demo-markerless/)")
    p.add_argument("--images", action="store_true",
                   help="the path from pixels instead: render 13 cameras' images of the patched hand and the "
                        "object it holds, and 6 cameras' of it turning the patched 2x2x2 cube; detect the coded "
                        "patches, triangulate, clean, calibrate and solve, track the object and the cube's moves, "
                        "each stage against the truth (about 5 minutes on 2 cores)")
    p.add_argument("--markerless", action="store_true",
                   help="a grasp from one video instead: synthetic keypoints of a hand holding a box, structure "
                        "from motion, the hand fitted, the box placed by ICP and carried through the frames, "
                        "the grasp refined with a contact map, each against the truth (demo-markerless/)")
    p.set_defaults(run=_cmd_demo)
