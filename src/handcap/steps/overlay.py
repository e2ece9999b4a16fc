"""Step ``overlay``: a detections file drawn over the images it came from, one picture per camera and frame."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
from tqdm import tqdm

from handcap.core.errors import HandcapError
from handcap.core.files import atomic_output, check_output_folder, load_npz
from handcap.detect.overlay import FrameMarks, draw_frame
from handcap.detect.sources import frame_sources
from handcap.io import read_markers, read_rig
from handcap.multiview.detections import read_detections
from handcap.steps.step import Step

#: Block rows ``handcap detect`` adds to the detections file (optional: other detections files lack them).
BLOCK_KEYS = ("block_text", "block_frame", "block_camera", "block_xy")
#: JPEG quality of the pictures written.
QUALITY = 90
#: Share of a frame's corners that may lie outside its image before the inputs are said not to match.
OUTSIDE_SHARE = 0.05


def overlay(detections, inputs, out, *, every: int = 1, markers=None, rig=None, force: bool = False,
            progress: bool | None = None) -> Step:
    """Draw ``detections`` over the frames of ``inputs`` into ``out/CAMERA/FRAME.jpg`` (:mod:`handcap.detect.overlay`).

    Parameters
    ----------
    detections : str or Path
        A 2D detections file (``handcap detect``'s, with its read blocks, or any other with named corners).
    inputs : sequence of str or Path
        The cameras' images or videos, as given to ``handcap detect`` (matched to the file's cameras by name).
    out : str or Path
        Folder to write into (new or empty, or ``force``); one sub-folder per camera.
    every : int
        Draw every ``every``-th frame (1: all).
    markers : str or Path, optional
        3D markers (``handcap triangulate``'s or ``clean``'s), drawn reprojected as crosses; needs ``rig``.
    rig : str or Path, optional
        The cameras file to reproject ``markers`` with.
    force : bool
        Write into a folder that holds files.
    progress : bool, optional
        Show a progress bar over frames (default: when stderr is a terminal).

    Returns
    -------
    Step
        ``result`` is the number of pictures written.

    Raises
    ------
    HandcapError
        A file that cannot be read, no camera of the file among the inputs, an output folder inside an input's,
        ``markers`` without ``rig``, or ``every`` below 1.
    """
    if every < 1:
        raise HandcapError(f"--every {every}: give 1 (every frame) or more")
    if (markers is None) != (rig is None):
        raise HandcapError("--markers and --rig go together: the 3D markers are reprojected with the cameras file")
    found = read_detections(detections)
    arrays = load_npz(detections, (), what="detections file")
    blocks = _blocks(arrays, detections)
    sources = frame_sources(inputs)
    folder = Path(out)
    for source in sources:
        place, given = folder.resolve(), Path(source.path).resolve()
        if place.is_relative_to(given) or given.is_relative_to(place):
            raise HandcapError(f"{folder}: lies in the input {source.path} or holds it; write the pictures to another "
                               "folder")
    folder = check_output_folder(out, detections, markers, rig, force=force)
    names = list(found.camera_names)
    drawn = [s for s in sources if s.camera in names]
    warnings = []
    if not drawn:
        raise HandcapError(f"{detections}: none of its cameras ({', '.join(names[:4])}) is among the inputs "
                           f"({', '.join(s.camera for s in sources[:4])}); give the inputs detect was given")
    missing = [n for n in names if n not in {s.camera for s in sources}]
    if missing:
        warnings.append(f"{len(missing)} camera(s) of {detections} not among the inputs, not drawn: "
                        + ", ".join(missing[:4]) + (" ..." if len(missing) > 4 else ""))
    projected = _projected(markers, rig, [s.camera for s in drawn]) if markers is not None else None
    owners, written, outside, total = {}, 0, 0, 0
    frames = sum(-(-max(s.span(), 1) // every) for s in drawn)
    bar = tqdm(total=frames, unit="frame", desc="overlay", disable=(not progress) if progress is not None else None)
    try:
        for source in drawn:
            c = names.index(source.camera)
            rows, block_rows = found.camera == c, blocks["camera"] == c
            (folder / source.camera).mkdir(parents=True, exist_ok=True)
            for t, image in source.frames(colour=True):
                if t % every:
                    continue
                here, block_here = rows & (found.frame == t), block_rows & (blocks["frame"] == t)
                xy = found.xy[here]
                height, width = image.shape[:2]
                total += len(xy)
                outside += int(np.sum((xy[:, 0] < -0.5) | (xy[:, 1] < -0.5) | (xy[:, 0] > width - 0.5)
                                      | (xy[:, 1] > height - 0.5)))
                marks = FrameMarks(xy, np.asarray(found.marker_names)[found.marker[here]], blocks["xy"][block_here],
                                   blocks["text"][block_here], *(projected(source.camera, t) if projected else ()))
                title = (f"{source.camera} frame {t}: {len(xy)} named corners"
                         + (f", {int(block_here.sum())} tags" if blocks["present"] else ""))
                picture = draw_frame(image, marks, title, owners)
                ok, code = cv2.imencode(".jpg", picture, [cv2.IMWRITE_JPEG_QUALITY, QUALITY])
                if not ok:
                    raise HandcapError(f"{source.camera} frame {t}: the picture could not be encoded as JPEG")
                with atomic_output(folder / source.camera / f"{t:06d}.jpg", "wb") as fh:
                    fh.write(code.tobytes())
                written += 1
                bar.update(1)
    finally:
        bar.close()
    if total and outside > OUTSIDE_SHARE * total:
        warnings.append(f"{outside} of {total} drawn corners lie outside their images: are these the images "
                        f"{detections} was detected in (the same cameras, in the same order, at the same size)?")
    lines = (f"{folder}: {written} pictures of {len(drawn)} camera(s), every {every} frame(s); named corners are "
             "dots in their owner's colour, read tags outlined with their underlined side drawn thick"
             + ("; the 3D markers reprojected are crosses" if markers is not None else ""),)
    return Step(lines, tuple(warnings), (str(folder),), written)


def _blocks(arrays: dict, path) -> dict:
    """The read blocks of a detections file (none where it has no block rows), checked."""
    present = [k for k in BLOCK_KEYS if k in arrays]
    if not present:
        return {"present": False, "text": np.zeros(0, str), "frame": np.zeros(0, int), "camera": np.zeros(0, int),
                "xy": np.zeros((0, 4, 2))}
    if len(present) != len(BLOCK_KEYS):
        raise HandcapError(f"{path}: has {', '.join(present)} but not {', '.join(set(BLOCK_KEYS) - set(present))}; "
                           "the read blocks need all four")
    n = len(arrays["block_text"])
    try:
        xy = np.asarray(arrays["block_xy"], dtype=float).reshape(n, 4, 2)
        frame, camera = (np.asarray(arrays[k]).astype(np.int64).reshape(n) for k in ("block_frame", "block_camera"))
    except (ValueError, TypeError):
        raise HandcapError(f"{path}: its read blocks' arrays disagree in length or shape") from None
    return {"present": True, "text": np.asarray(arrays["block_text"]).astype(str), "frame": frame,
            "camera": camera, "xy": xy}


def _projected(markers, rig, cameras):
    """A function (camera name, frame) -> (pixels (P, 2), names (P,)) of the 3D markers reprojected."""
    sequence, cameras_file = read_markers(markers), read_rig(rig)
    known = {c.name: c for c in cameras_file}
    lacking = [name for name in cameras if name not in known]
    if lacking:
        raise HandcapError(f"{rig}: has no camera {lacking[0]!r}; give the cameras file the markers were triangulated "
                           "with")
    names = np.asarray(sequence.names)

    def at(camera: str, t: int):
        if not 0 <= t < len(sequence.positions):
            return np.zeros((0, 2)), np.zeros(0, str)
        points = sequence.positions[t]
        seen = np.isfinite(points).all(axis=1)
        pixels, _ = known[camera].project(points[seen])
        keep = np.isfinite(pixels).all(axis=1)
        return pixels[keep], names[seen][keep]

    return at
