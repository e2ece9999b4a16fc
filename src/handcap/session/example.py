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
from handcap.synth.scene import SynthConfig, synthesize, write_capture

TEMPLATE = '''# A handcap session: `handcap process session.toml` runs every stage of every take and writes
# results/<take>/ (attachment.npz, motion.npz, metrics.json, report.html, and a manifest per stage).
# Run it again and finished stages are skipped; edit a setting and only what depends on it runs again.
# `handcap process session.toml --dry-run` prints the plan.

[session]
name = "{name}"
results = "results"
stages = ["calibrate", "solve", "fit", "metrics", "report"]   # fit: the keypoint takes

[stages.calibrate]
layout = "glove-13"          # the marker layout of every take (a take may name its own)

[stages.solve]
method = "lm"
filter_cutoff = 8.0          # Hz: a low-pass on the solved motion; remove the line for none

[stages.metrics]
leave_one_out = false

{takes}'''

KEYPOINTS = '''[[takes]]
name = "{name}"
kind = "keypoints"           # 3D hand keypoints (21 per hand, as handcap's markerless verbs write them)
keypoints = "{name}/keypoints.c3d"
truth = "{name}/truth.npz"

'''

TAKE = '''[[takes]]
name = "{name}"
kind = "markers"             # labelled markers (.c3d .trc .tsv .csv .npz)
markers = "{name}/markers.c3d"
calibration = "calibration/markers.c3d"   # or attachment = "attachment.npz"
truth = "{name}/truth.npz"   # synthetic takes only: the metrics compare against it

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


def new_session(folder, *, takes: int = 2, frames: int = 300) -> list[str]:
    """Write a session into ``folder``: a calibration take, ``takes`` grasp takes (synthetic markers, one
    subject), a take of 3D hand keypoints, and a commented ``session.toml``.

    Parameters
    ----------
    folder : str or Path
        New or empty.
    takes, frames : int
        Number of takes and frames of each (100 Hz).

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
    takes = "".join(TAKE.format(name=n) for n in configs if n != "calibration") + KEYPOINTS.format(name="hands1")
    text = TEMPLATE.format(name=folder.name, takes=takes)
    with atomic_output(folder / "session.toml", "w") as fh:
        fh.write(text)
    return [*written, str(folder / "session.toml")]
