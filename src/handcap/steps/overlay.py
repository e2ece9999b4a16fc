"""Step ``overlay``: a detections file drawn over the images it came from, one picture per camera and frame."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from handcap.core.errors import HandcapError
from handcap.core.files import check_output_folder, load_npz
from handcap.detect.overlay import BLOCK_KEYS, read_blocks, write_pictures
from handcap.detect.sources import FrameSelection, frame_sources, select_frames
from handcap.io import read_markers, read_rig
from handcap.markerless.keypoints import BONES, KEYPOINT_NAMES, is_keypoints
from handcap.multiview.detections import read_detections
from handcap.steps.step import Step

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
    read_blocks(arrays, detections)  # checked before any picture is drawn
    sources = frame_sources(inputs)
    if "first_frame" in arrays:  # detect read a selection of the frames (--frames, --every): the same frames here
        try:
            start, step = int(arrays["first_frame"]), int(arrays.get("frame_step", 1))
            span = int(arrays["n_frames"]) if "n_frames" in arrays else int(found.frame.max(initial=-1)) + 1
            pick = FrameSelection(start, start + step * max(span, 1), step)
        except (TypeError, ValueError, HandcapError):
            raise HandcapError(f"{detections}: first_frame, frame_step and n_frames must be whole numbers, 0 or more "
                               "(the input frames detect read)") from None
        sources = select_frames(sources, pick)
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
    rows = {"camera_names": np.asarray(found.camera_names), "marker_names": np.asarray(found.marker_names),
            "frame": found.frame, "camera": found.camera, "marker": found.marker, "xy": found.xy,
            **{k: arrays[k] for k in BLOCK_KEYS if k in arrays}}
    bones = _bones(found.marker_names)
    written, outside, total = write_pictures(rows, drawn, folder, every=every, projected=projected, links=bones,
                                             progress=progress, what=str(detections))
    if total and outside > OUTSIDE_SHARE * total:
        warnings.append(f"{outside} of {total} drawn corners lie outside their images: are these the images "
                        f"{detections} was detected in (the same cameras, in the same order, at the same size)?")
    drew = ("hand keypoints are dots joined by their hand's bones, in its colour" if bones is not None else
            "named corners are dots in their owner's colour, read tags outlined with their underlined side drawn thick")
    lines = (f"{folder}: {written} pictures of {len(drawn)} camera(s), every {every} frame(s); {drew}"
             + ("; the 3D markers reprojected are crosses" if markers is not None else ""),)
    return Step(lines, tuple(warnings), (str(folder),), written)


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


def _bones(marker_names) -> np.ndarray | None:
    """Where the markers are 2D hand keypoints (``[HAND:]wrist``, ...), each hand's bones as pairs of marker
    indices (:data:`handcap.markerless.keypoints.BONES`); None otherwise."""
    if not is_keypoints(marker_names):
        return None
    index = {str(n): k for k, n in enumerate(marker_names)}
    hands = dict.fromkeys(str(n).rpartition(":")[0] for n in marker_names)
    pairs = []
    for hand in hands:
        prefix = f"{hand}:" if hand else ""
        for a, b in BONES:
            ends = index.get(prefix + KEYPOINT_NAMES[a]), index.get(prefix + KEYPOINT_NAMES[b])
            if None not in ends:
                pairs.append(ends)
    return np.array(pairs, int).reshape(-1, 2)
