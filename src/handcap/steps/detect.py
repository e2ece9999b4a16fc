"""Step ``detect``: camera images of coded patches to 2D detections (named corners and read blocks)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from tqdm import tqdm

from handcap.core.errors import HandcapError
from handcap.core.files import check_output, save_npz, warnings_entry
from handcap.patterns.pattern import Pattern
from handcap.detect.sources import frame_sources
from handcap.io import read_rig
from handcap.steps.step import Step

DEFAULT_RATE = 20.0  # DexterCap's cameras; said in a warning when assumed


def detect(inputs, out, *, rig=None, pattern=None, alphabet: str | None = None, rate: float | None = None,
           corner_weights=None, reader_weights=None, threshold: float = 0.3, progress: bool | None = None) -> Step:
    """Detect coded patches in images or videos and write the 2D detections ``.npz``.

    Parameters
    ----------
    inputs : sequence of str or Path
        One per camera: a folder of images, a video or an image file (its name is the camera's).
    out : str or Path
        The detections file (.npz).
    rig : str, Path or None
        Cameras file: every input must be one of its cameras; the file lists them in the rig's order.
    pattern : str, Path or None
        The session's ``pattern.toml``: tags are voted over it and corners named from it. Without it the file
        holds the read blocks only.
    alphabet : str, optional
        Glyphs of the printed tags (default: the template's, else handcap's).
    rate : float, optional
        Frames per second (default: a video's own, else 20 with a warning).
    corner_weights, reader_weights : str, Path or None
        Networks to use instead of the shipped ones.
    threshold : float
        Least corner probability.
    progress : bool, optional
        Progress bar (default: on a terminal).
    """
    out = Path(out)
    if out.suffix.lower() != ".npz":
        raise HandcapError(f"{out}: detections are written as .npz; name it NAME.npz")
    sources = frame_sources(inputs)
    check_output(out, *[f for s in sources for f in (s.files or (s.path,))], rig, pattern)
    template = Pattern.load(pattern) if pattern is not None else None
    names = [s.camera for s in sources]
    if rig is not None:
        cameras = read_rig(rig)
        missing = [n for n in names if n not in cameras.names]
        if missing:
            raise HandcapError(f"{rig}: has no camera {missing[0]!r} (it has {', '.join(cameras.names)}); name each "
                               "input folder or video after its camera")
        names = [n for n in cameras.names if n in names]
        sources = sorted(sources, key=lambda s: names.index(s.camera))
    # The networks load torch (a second and a half): only when detecting, not with the command line.
    from handcap.detect.networks import load_corner_net, load_reader, shipped_notes  # loads torch
    from handcap.detect.pipeline import Detector  # loads torch

    detector = Detector(load_corner_net(corner_weights), load_reader(reader_weights), template, alphabet, threshold)
    warnings = []
    if corner_weights is None or reader_weights is None:
        # Issue 16: the shipped networks are a first, short training; say how good they measured, every time.
        warnings.append("the shipped detector networks are a first training, short of handcap's targets (corner "
                        "recall >= 97 %, every tag read right or not at all); as measured on held-out rendered "
                        "images: " + "; ".join(shipped_notes()) + "; check the corner ids before relying on them")
    if template is None:
        warnings.append("no template (--pattern): blocks and their pixels only, no corner ids; triangulate needs ids")
    if rate is None:
        rates = [r for r in (s.fps() for s in sources) if r is not None]
        rate = rates[0] if rates else DEFAULT_RATE
        if not rates:
            warnings.append(f"frame rate not given (--rate): {DEFAULT_RATE:g} Hz assumed")
    elif not 0 < rate < 100000:
        raise HandcapError(f"--rate {rate}: give frames per second, more than 0")
    marker_names = template.corner_names() if template is not None else []
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
    if empty:
        warnings.append(f"no corner found in {empty} of {images} images (no patches in view, or not in focus)")
    if images and not blocks["block_text"]:
        warnings.append("no tag was read in any image: wrong --alphabet, patches too small in the images, or not "
                        "coded patches")
    arrays = {
        "camera_names": np.array(names), "marker_names": np.array(marker_names, dtype=str),
        "frame": np.array(rows["frame"], dtype=np.int64), "camera": np.array(rows["camera"], dtype=np.int64),
        "marker": np.array(rows["marker"], dtype=np.int64),
        "xy": np.array(rows["xy"], dtype=np.float64).reshape(-1, 2),
        "score": np.array(rows["score"], dtype=np.float64), "rate": np.array(float(rate)),
        "block_text": np.array(blocks["block_text"], dtype="<U2"),
        "block_frame": np.array(blocks["block_frame"], dtype=np.int64),
        "block_camera": np.array(blocks["block_camera"], dtype=np.int64),
        "block_xy": np.array(blocks["block_xy"], dtype=np.float64).reshape(-1, 4, 2),
        "block_score": np.array(blocks["block_score"], dtype=np.float64),
        **warnings_entry(warnings),
    }
    save_npz(out, arrays)
    line = (f"{out}: {images} images from {len(names)} camera(s): {len(arrays['frame'])} named corners, "
            f"{len(arrays['block_text'])} read tags" + (f" ({corrected} corrected by the vote)" if template else ""))
    return Step((line,), tuple(warnings), (str(out),), arrays)
