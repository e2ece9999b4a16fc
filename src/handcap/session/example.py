"""``handcap session new DIR``: a commented session file with synthetic takes made in DIR, ready for
``handcap process DIR/session.toml``."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from handcap.core.errors import HandcapError
from handcap.core.files import atomic_output
from handcap.core.markers import MarkerSequence
from handcap.core.motion import HandMotion
from handcap.hand import OpenHand
from handcap.io import write_markers
from handcap.io.npz import write_hand_motion
from handcap.markerless.keypoints import hand_names
from handcap.markerless.synthetic import synthetic_hand
from handcap.synth.filming import film_take
from handcap.synth.scene import SynthConfig, synthesize, write_capture

TEMPLATE = '''# A handcap session: `handcap process session.toml` runs every stage of every take and writes
# results/<take>/ (detections.npz, triangulated.c3d, cleaned.c3d for camera takes; attachment.npz,
# motion.npz, metrics.json, report.html; and a manifest per stage).
# Run it again and finished stages are skipped; edit a setting and only what depends on it runs again.
# `handcap process session.toml --dry-run` prints the plan.

[session]
name = "{name}"
results = "results"
stages = [{stages}]

[stages.calibrate]
layout = "glove-13"          # the marker layout of every take (a take may name its own)

[stages.solve]
method = "lm"
filter_cutoff = 8.0          # Hz: a low-pass on the solved motion; remove the line for none

[stages.metrics]
leave_one_out = false
{image_stages}
{takes}'''

IMAGE_STAGES = '''
[stages.detect]
rate = 4.0                   # frames per second of the image folders (a video says its own)
response = "linear"          # rendered: grey levels linear in the light; "auto" (the default) chooses per camera

[stages.triangulate]
min_views = 2                # cameras that must agree on a corner

[stages.clean]
# Four frames a second: a finger moves too far between frames to interpolate over a gap, so only the
# rigid fill (from patch-mates seen in the same frame) fills, over at most 1.5 s.
max_linear_frames = 0
max_spline_frames = 0
max_rigid_frames = 6
'''

IMAGES = '''[[takes]]
name = "{name}"
kind = "images"              # camera images of coded patches: detect, triangulate, clean, then as markers
images = "{name}/images"     # one sub-folder of images (or one video) per camera
cameras = "{name}/cameras.toml"
pattern = "{name}/pattern.toml"
layout = "dense-patches"
{calibration}truth = "{name}/truth.npz"
[takes.settings.solve]       # this take's own settings over the session's
filter_cutoff = 0            # no low-pass: 4 frames a second

'''

KEYPOINTS = '''[[takes]]
name = "{name}"
kind = "keypoints"           # 3D hand keypoints (21 per hand, as handcap's markerless verbs write them)
keypoints = "{name}/keypoints.c3d"
truth = "{name}/truth.npz"

'''

TAKE = '''[[takes]]
name = "{name}"
kind = "markers"             # labelled markers (.c3d .trc .tsv .csv .txt .npz)
markers = "{name}/markers.c3d"
calibration = "calibration/markers.c3d"   # or attachment = "attachment.npz"
truth = "{name}/truth.npz"   # synthetic takes only: the metrics compare against it
[takes.settings.object]      # the cylinder in the hand, tracked from its markers (its shape learnt from the take)
markers = "cylinder_*"
name = "cylinder"

'''


def _keypoint_take(folder: Path, frames: int) -> list[str]:
    """A synthetic take of 3D hand keypoints (2 mm noise, 5 % missing) and its truth."""
    rng = np.random.default_rng(5)
    hand = synthetic_hand(frames, 30.0, rng, motion="random")
    points = hand.keypoints + rng.normal(0, 0.002, hand.keypoints.shape)
    points[rng.random(points.shape[:2]) < 0.05] = np.nan
    folder.mkdir(parents=True, exist_ok=True)
    write_markers(MarkerSequence(points, hand_names("right"), 30.0), folder / "keypoints.c3d")
    model = OpenHand("right")
    pose = model.hand_pose_from_phi(hand.phi)
    joints = model.forward(hand.betas, hand.global_orient, pose, hand.transl, vertices=False).joints
    write_hand_motion(HandMotion(hand.betas, hand.global_orient, pose, hand.transl, 30.0, "right", hand.phi,
                                 model.name, joints), folder / "truth.npz")
    return [str(folder / "keypoints.c3d"), str(folder / "truth.npz")]


def _image_takes(folder: Path, frames: int, progress: bool | None) -> tuple[list[str], str]:
    """Two filmed takes of printed patches, 6 cameras at 4 Hz: an open hand turned (4 frames, the calibration)
    and another take of ``frames``; the files and their [[takes]] tables."""
    configs = {"calib-images": SynthConfig(layout="dense-patches", motion="calibration", frames=4, rate=4.0, seed=8,
                                           subject_seed=21, cameras=6, min_views=2, object="none"),
               "images1": SynthConfig(layout="dense-patches", motion="calibration", frames=frames, rate=4.0, seed=9,
                                      subject_seed=21, cameras=6, min_views=2, object="none")}
    before = set(folder.rglob("*"))
    tables = ""
    for name, config in configs.items():
        film_take(config, folder / name, progress=progress)
        tables += IMAGES.format(name=name, calibration="" if name == "calib-images" else
                                'calibration_take = "calib-images"   # its cleaned corners calibrate this take\n')
    return sorted(str(p) for p in set(folder.rglob("*")) - before if p.is_file()), tables


def new_session(folder, *, takes: int = 2, frames: int = 300, images: bool = True, image_frames: int = 6,
                progress: bool | None = None) -> list[str]:
    """Write a session into ``folder``: a calibration take, ``takes`` grasp takes (synthetic markers, one
    subject), a take of 3D hand keypoints, two filmed takes of printed patches (``images``), and a commented
    ``session.toml``.

    Parameters
    ----------
    folder : str or Path
        New or empty.
    takes, frames : int
        Number of marker takes and frames of each (100 Hz).
    images : bool
        Film the image takes (needs the extra 'images' and headless OpenGL).
    image_frames : int
        Frames of the filmed take that is not the calibration (4 Hz, 6 cameras).
    progress : bool, optional
        Progress bars while filming (default: on a terminal).

    Returns
    -------
    list of str
        The files written.
    """
    folder = Path(folder)
    if folder.exists() and (not folder.is_dir() or any(folder.iterdir())):
        raise HandcapError(f"{folder}: exists and is not an empty folder; give a new one")
    written = []
    configs = {"calibration": SynthConfig(motion="calibration", frames=400, seed=100, subject_seed=7)}
    for k in range(takes):
        configs[f"take{k + 1}"] = SynthConfig(motion="grasp", frames=frames, seed=k + 1, subject_seed=7)
    for name, config in configs.items():
        written += [str(p) for p in write_capture(synthesize(config, progress=False), folder / name).values()]
    written += _keypoint_take(folder / "hands1", frames)
    tables = "".join(TAKE.format(name=n) for n in configs if n != "calibration") + KEYPOINTS.format(name="hands1")
    stages = ["calibrate", "solve", "object", "fit", "metrics", "report"]
    if images:
        files, image_tables = _image_takes(folder, image_frames, progress)
        written += files
        tables += image_tables
        stages = ["detect", "triangulate", "clean", *stages]
    text = TEMPLATE.format(name=folder.name, takes=tables, stages=", ".join(f'"{s}"' for s in stages),
                           image_stages=IMAGE_STAGES if images else "")
    with atomic_output(folder / "session.toml", "w") as fh:
        fh.write(text)
    return [*written, str(folder / "session.toml")]
