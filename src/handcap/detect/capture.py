"""The detector over a whole capture: every frame of every camera, into the 2D detections arrays.

The arrays are the 2D detections File contract (``camera_names``,
``marker_names``, ``frame``, ``camera``, ``marker``, ``xy``, ``score``,
``rate``) plus one row per read block (``block_text``, ``block_frame``,
``block_camera``, ``block_xy``, ``block_score``); ``handcap detect`` writes
them, ``handcap demo --images`` uses them directly.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from tqdm import tqdm

from handcap.detect.pipeline import Detector


@dataclass(frozen=True)
class CaptureDetections:
    """The detections of a capture and what was counted on the way.

    Attributes
    ----------
    arrays : dict of str to ndarray
        The detections file's arrays (see the module docstring), no warnings entry.
    images : int
        Images read.
    empty : int
        Images with no corner found.
    corrected : int
        Readings the vote over the template changed.
    """

    arrays: dict
    images: int
    empty: int
    corrected: int


def detect_capture(detector: Detector, sources, marker_names, rate: float, *,
                   progress: bool | None = None) -> CaptureDetections:
    """Run ``detector`` on every frame of ``sources`` (one per camera, in the rig's order).

    Parameters
    ----------
    detector : Detector
    sources : sequence of FrameSource
        Camera ``c`` of the output is ``sources[c]``.
    marker_names : sequence of str
        The markers a corner id may name (the template's corner names, or a subset of them); a corner
        named otherwise is left out.
    rate : float
        Frames per second.
    progress : bool, optional
        Progress bar over the images (default: on a terminal).

    Returns
    -------
    CaptureDetections
    """
    index = {n: k for k, n in enumerate(marker_names)}
    rows = {"frame": [], "camera": [], "marker": [], "xy": [], "score": []}
    blocks = {"block_text": [], "block_frame": [], "block_camera": [], "block_xy": [], "block_score": []}
    images = empty = corrected = 0
    hidden = None if progress is None else not progress
    with tqdm(total=sum(s.count() for s in sources), desc="detect", unit="image", disable=hidden,
              leave=False) as bar:
        for c, source in enumerate(sources):
            for t, image in source.frames():
                found = detector.image(image)
                images += 1
                empty += len(found.corners) == 0
                corrected += found.corrected
                named = [k for k, n in enumerate(found.names) if n is not None and n in index]
                rows["frame"] += [t] * len(named)
                rows["camera"] += [c] * len(named)
                rows["marker"] += [index[found.names[k]] for k in named]
                rows["xy"] += [found.corners[k] for k in named]
                rows["score"] += [found.corner_score[k] for k in named]
                blocks["block_text"] += list(found.block_text)
                blocks["block_frame"] += [t] * len(found.block_text)
                blocks["block_camera"] += [c] * len(found.block_text)
                blocks["block_xy"] += list(found.block_xy)
                blocks["block_score"] += list(found.block_score)
                bar.update()
    arrays = {
        "camera_names": np.array([s.camera for s in sources]), "marker_names": np.array(marker_names, dtype=str),
        "frame": np.array(rows["frame"], dtype=np.int64), "camera": np.array(rows["camera"], dtype=np.int64),
        "marker": np.array(rows["marker"], dtype=np.int64),
        "xy": np.array(rows["xy"], dtype=np.float64).reshape(-1, 2),
        "score": np.array(rows["score"], dtype=np.float64), "rate": np.array(float(rate)),
        "n_frames": np.array(max((s.count() for s in sources), default=0), dtype=np.int64),
        "block_text": np.array(blocks["block_text"], dtype="<U2"),
        "block_frame": np.array(blocks["block_frame"], dtype=np.int64),
        "block_camera": np.array(blocks["block_camera"], dtype=np.int64),
        "block_xy": np.array(blocks["block_xy"], dtype=np.float64).reshape(-1, 4, 2),
        "block_score": np.array(blocks["block_score"], dtype=np.float64),
    }
    return CaptureDetections(arrays, images, empty, corrected)
