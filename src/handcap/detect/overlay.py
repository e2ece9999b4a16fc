"""Detections drawn over the camera images they came from, to check them by eye.

Every named corner is a dot in its owner's colour (the right hand, the left
hand and each object apart), every patch's name is written at the middle of
its corners, and every read block is outlined, its underlined side (the bottom, in reading order)
drawn thicker, and the tag it was read as written on the black square above it
(in reading order), beside the printed glyphs, so a misreading or a tag read
upside down shows; a tag named from the other cameras (not read) is written in
magenta. Reprojected 3D markers, where given, are crosses beside the dots of
the same name: a cross far from its dot is a corner the triangulation (or the
calibration) does not agree with. 2D hand keypoints (``handcap keypoints``) are
dots joined by their hand's bones, where the caller gives them (``links``).

Coordinates are pixels ``(x, y)`` at column x, row y, pixel centres at integers (as the detections file
gives them); images are BGR uint8 ``(H, W, 3)``.
"""

from __future__ import annotations

import re
from dataclasses import dataclass

from pathlib import Path

import cv2
import numpy as np
from tqdm import tqdm

from handcap.core.errors import HandcapError
from handcap.core.files import atomic_output

#: Block rows ``handcap detect`` adds to the detections file (optional: other detections files lack them).
BLOCK_KEYS = ("block_text", "block_frame", "block_camera", "block_xy")
#: JPEG quality of the pictures written.
QUALITY = 90
#: Owner colours, BGR: the right hand orange, the left hand blue, then objects in turn.
HAND_COLOURS = {"right": (0, 140, 255), "left": (255, 120, 0)}
OBJECT_COLOURS = ((60, 200, 60), (200, 60, 200), (0, 220, 220), (220, 220, 0), (60, 60, 230), (160, 160, 160))
#: Colour of a read tag's text, and of a tag named from the other cameras, BGR.
READ_TEXT, VIEWS_TEXT = (255, 255, 0), (255, 0, 255)
#: Outline drawn under text, BGR.
_SHADE = (0, 0, 0)
_CORNER = re.compile(r"^(?:(?P<owner>[^:]+):)?(?P<patch>.+)_r\d+c\d+$")


@dataclass(frozen=True)
class FrameMarks:
    """What to draw over one camera's frame.

    Attributes
    ----------
    xy : ndarray (N, 2)
        Named corners, pixels.
    names : ndarray (N,) str
        Their marker names (``OWNER:PATCH_rRcC`` for coded patches; any name otherwise).
    blocks : ndarray (B, 4, 2)
        Read blocks' corners in reading order (top-left, top-right, bottom-right, bottom-left), pixels.
    tags : ndarray (B,) str
        Their tags.
    projected : ndarray (P, 2), optional
        Reprojected 3D markers, pixels.
    projected_names : ndarray (P,) str, optional
        Their names (matched to ``names`` for the colour).
    links : ndarray (L, 2) int, optional
        Pairs of indices into ``xy`` joined by a line in the first one's colour: a hand's bones where the names
        are 2D hand keypoints.
    from_views : ndarray (B,) bool, optional
        Blocks named from the other cameras (:mod:`~handcap.detect.views`), not read: their tag is written in
        :data:`VIEWS_TEXT` instead of :data:`READ_TEXT`.
    """

    xy: np.ndarray
    names: np.ndarray
    blocks: np.ndarray
    tags: np.ndarray
    projected: np.ndarray | None = None
    projected_names: np.ndarray | None = None
    links: np.ndarray | None = None
    from_views: np.ndarray | None = None


def owner_colour(name: str, owners: dict) -> tuple:
    """The BGR colour of a marker's owner (the part of its name before ``:``; one colour for unowned names).

    Parameters
    ----------
    name : str
        A marker name.
    owners : dict
        Owner -> colour given so far; a new object owner gets the next colour and is added.

    Returns
    -------
    tuple of 3 int
    """
    owner = name.split(":", 1)[0] if ":" in name else ""
    if owner in HAND_COLOURS:
        return HAND_COLOURS[owner]
    if owner not in owners:
        owners[owner] = OBJECT_COLOURS[len(owners) % len(OBJECT_COLOURS)]
    return owners[owner]


def draw_frame(image: np.ndarray, marks: FrameMarks, title: str = "", owners: dict | None = None) -> np.ndarray:
    """``image`` with ``marks`` drawn over it (see the module docstring).

    Parameters
    ----------
    image : ndarray (H, W) or (H, W, 3) uint8
        The camera's frame, grey or BGR.
    marks : FrameMarks
    title : str
        A line written at the top left (the camera, the frame, the counts).
    owners : dict, optional
        Owner colours shared across frames (:func:`owner_colour`), so an object keeps its colour.

    Returns
    -------
    ndarray (H, W, 3) uint8
        A new image; ``image`` is not changed.
    """
    owners = {} if owners is None else owners
    canvas = cv2.cvtColor(image, cv2.COLOR_GRAY2BGR) if image.ndim == 2 else image.copy()
    canvas = (canvas.astype(np.float32) * 0.75).astype(np.uint8)  # dimmed, so the marks stand out
    side = _block_side(marks, canvas.shape)
    thin = max(1, int(round(side / 24)))
    views = np.zeros(len(marks.tags), bool) if marks.from_views is None else np.asarray(marks.from_views, bool)
    for quad, text, named in zip(np.asarray(marks.blocks, float).reshape(-1, 4, 2), marks.tags, views):
        points = _fixed(quad)
        cv2.polylines(canvas, [points], True, (255, 255, 255), thin, cv2.LINE_AA, shift=4)
        cv2.line(canvas, tuple(points[3]), tuple(points[2]), (255, 255, 255), 2 * thin + 1, cv2.LINE_AA, shift=4)
        width = float(np.linalg.norm(quad[1] - quad[0]))
        # On the black square above the tag (in reading order), so the printed glyphs stay in view beside it.
        above = quad.mean(axis=0) + 2.0 * ((quad[0] + quad[1]) / 2 - quad.mean(axis=0))
        _text(canvas, str(text), above, max(width, 6.0) * 0.8, VIEWS_TEXT if named else READ_TEXT)
    radius = max(2.0, side / 10)
    colours = [owner_colour(str(n), owners) for n in marks.names]
    points = np.asarray(marks.xy, float).reshape(-1, 2)
    for a, b in np.asarray(marks.links if marks.links is not None else np.zeros((0, 2)), int).reshape(-1, 2):
        cv2.line(canvas, tuple(_fixed(points[a])), tuple(_fixed(points[b])), colours[a], thin + 1, cv2.LINE_AA,
                 shift=4)
    for (x, y), colour in zip(np.asarray(marks.xy, float).reshape(-1, 2), colours):
        cv2.circle(canvas, _fixed(np.array([x, y])), int(round(radius * 16)), colour, -1, cv2.LINE_AA, shift=4)
    if marks.projected is not None:
        names = marks.projected_names if marks.projected_names is not None else [""] * len(marks.projected)
        arm = int(round(radius * 1.6 * 16))
        for (x, y), name in zip(np.asarray(marks.projected, float).reshape(-1, 2), names):
            centre = _fixed(np.array([x, y]))
            colour = owner_colour(str(name), owners)
            for dx, dy in ((arm, arm), (arm, -arm)):
                cv2.line(canvas, (centre[0] - dx, centre[1] - dy), (centre[0] + dx, centre[1] + dy), colour, thin,
                         cv2.LINE_AA, shift=4)
    for patch, where, colour in _patch_labels(marks, owners, side):
        _text(canvas, patch, where, 3.0 * max(side, 8.0), colour)
    if title:
        scale = max(0.5, canvas.shape[1] / 1600)
        _text(canvas, title, None, 0.0, (255, 255, 255), scale=scale)
    return canvas


def _block_side(marks: FrameMarks, shape) -> float:
    """The median side of the read blocks (pixels), or of the grid the corners make, or a share of the image."""
    blocks = np.asarray(marks.blocks, float).reshape(-1, 4, 2)
    if len(blocks):
        return float(np.median(np.linalg.norm(blocks - np.roll(blocks, 1, axis=1), axis=2)))
    xy = np.asarray(marks.xy, float).reshape(-1, 2)
    if len(xy) > 1:
        gaps = np.linalg.norm(xy[:, None] - xy[None], axis=2) if len(xy) <= 2000 else None
        if gaps is not None:
            np.fill_diagonal(gaps, np.inf)
            return float(np.median(gaps.min(axis=1)))
    return max(shape[:2]) / 100


def _patch_labels(marks: FrameMarks, owners: dict, side: float):
    """(patch name, where to write it, its colour) for every coded patch with corners in the frame: centred over
    its corners, a square's side above the highest."""
    groups = {}
    for name, xy in zip(marks.names, np.asarray(marks.xy, float).reshape(-1, 2)):
        match = _CORNER.match(str(name))
        if match is not None:
            key = (match.group("owner") + ":" if match.group("owner") else "") + match.group("patch")
            groups.setdefault(key, (str(name), []))[1].append(xy)
    return [(key, np.array([np.mean(points, axis=0)[0], np.min(points, axis=0)[1] - side]), owner_colour(name, owners))
            for key, (name, points) in groups.items()]


def _fixed(points: np.ndarray) -> np.ndarray:
    """Pixel positions as OpenCV's drawing takes them with ``shift=4`` (sixteenths of a pixel)."""
    return np.round(np.asarray(points, float) * 16).astype(np.int32)


def _text(canvas, text: str, centre, width: float, colour, scale: float | None = None) -> None:
    """``text`` centred on ``centre`` and fitted to ``width`` pixels (or at the top left at ``scale``), shaded."""
    font = cv2.FONT_HERSHEY_SIMPLEX
    if scale is None:
        (w, _), _ = cv2.getTextSize(text, font, 1.0, 1)
        scale = min(max(width / max(w, 1), 0.3), 4.0)
    thick = max(1, int(round(scale * 1.5)))
    (w, h), _ = cv2.getTextSize(text, font, scale, thick)
    if centre is None:
        origin = (int(8 * scale), int(8 * scale) + h)
    else:
        origin = (int(round(centre[0] - w / 2)), int(round(centre[1] + h / 2)))
    # The shade: the same text moved a pixel each way (a thicker pen would also space the glyphs wider).
    for dx, dy in ((-1, -1), (1, -1), (-1, 1), (1, 1)):
        cv2.putText(canvas, text, (origin[0] + dx, origin[1] + dy), font, scale, _SHADE, thick, cv2.LINE_AA)
    cv2.putText(canvas, text, origin, font, scale, colour, thick, cv2.LINE_AA)


def read_blocks(arrays: dict, what: str = "detections") -> dict:
    """The read blocks of a detections file's arrays, checked: ``text`` (B,), ``frame``, ``camera`` (B,) int,
    ``xy`` (B, 4, 2) pixels, ``views`` (B,) bool (named from the other cameras) and ``present`` (whether the file
    has block rows; none is no error).

    Parameters
    ----------
    arrays : dict
        The file's arrays (:data:`BLOCK_KEYS` where ``handcap detect`` wrote them).
    what : str
        The file, for messages.

    Raises
    ------
    HandcapError
        Some block keys without the others, or arrays that disagree in length or shape.
    """
    present = [k for k in BLOCK_KEYS if k in arrays]
    if not present:
        return {"present": False, "text": np.zeros(0, str), "frame": np.zeros(0, int), "camera": np.zeros(0, int),
                "xy": np.zeros((0, 4, 2)), "views": np.zeros(0, bool)}
    if len(present) != len(BLOCK_KEYS):
        raise HandcapError(f"{what}: has {', '.join(present)} but not "
                           f"{', '.join(k for k in BLOCK_KEYS if k not in present)}; the read blocks need all four")
    n = len(arrays["block_text"])
    try:
        xy = np.asarray(arrays["block_xy"], dtype=float).reshape(n, 4, 2)
        frame, camera = (np.asarray(arrays[k]).astype(np.int64).reshape(n) for k in ("block_frame", "block_camera"))
        views = np.asarray(arrays.get("block_from_views", np.zeros(n, bool))).astype(bool).reshape(n)
    except (ValueError, TypeError):
        raise HandcapError(f"{what}: its read blocks' arrays disagree in length or shape") from None
    return {"present": True, "text": np.asarray(arrays["block_text"]).astype(str), "frame": frame,
            "camera": camera, "xy": xy, "views": views}


def write_pictures(arrays: dict, sources, folder, *, every: int = 1, projected=None, links=None,
                   progress: bool | None = None, what: str = "detections") -> tuple[int, int, int]:
    """Draw a capture's detections over its cameras' frames into ``folder/CAMERA/FRAME.jpg`` (atomically).

    Parameters
    ----------
    arrays : dict
        The detections file's arrays (``camera_names``, ``marker_names``, ``frame``, ``camera``, ``marker``,
        ``xy`` pixels; the block rows where there are).
    sources : sequence
        The cameras to draw (:class:`handcap.detect.sources.FrameSource`), named as in ``camera_names``.
    folder : str or Path
    every : int
        Draw every ``every``-th frame.
    projected : callable, optional
        (camera name, frame) -> (pixels (P, 2), names (P,)) of 3D markers, drawn reprojected where the frame shows
        a detection of the same name (a marker the camera does not see, behind the hand, would only clutter).
    links : ndarray (L, 2) int, optional
        Pairs of markers (indices into ``marker_names``) joined by a line where a frame has both: a hand's bones.
    progress : bool, optional
        A progress bar over frames (default: when stderr is a terminal).
    what : str
        The detections' source, for messages.

    Returns
    -------
    written : int
        Pictures written.
    outside, total : int
        Corners drawn outside their image, and all drawn.
    """
    folder, names = Path(folder), [str(n) for n in arrays["camera_names"]]
    blocks = read_blocks(arrays, what)
    marker_names = np.asarray(arrays["marker_names"])
    frame, camera, xy_all = (np.asarray(arrays[k]) for k in ("frame", "camera", "xy"))
    owners, written, outside, total = {}, 0, 0, 0
    frames = sum(-(-max(s.span(), 1) // every) for s in sources)
    bar = tqdm(total=frames, unit="frame", desc="overlay", disable=(not progress) if progress is not None else None)
    try:
        for source in sources:
            c = names.index(source.camera)
            rows, block_rows = camera == c, blocks["camera"] == c
            (folder / source.camera).mkdir(parents=True, exist_ok=True)
            for t, image in source.frames(colour=True):
                if t % every:
                    continue
                here, block_here = rows & (frame == t), block_rows & (blocks["frame"] == t)
                xy = np.asarray(xy_all[here], dtype=float).reshape(-1, 2)
                height, width = image.shape[:2]
                total += len(xy)
                outside += int(np.sum((xy[:, 0] < -0.5) | (xy[:, 1] < -0.5) | (xy[:, 0] > width - 0.5)
                                      | (xy[:, 1] > height - 0.5)))
                markers = np.asarray(arrays["marker"])[here]
                crosses = (None, None)
                if projected:  # of the markers this frame shows: a cross beside its dot
                    pixels, named = projected(source.camera, t)
                    shown = np.isin(named, marker_names[markers])
                    crosses = pixels[shown], named[shown]
                marks = FrameMarks(xy, marker_names[markers], blocks["xy"][block_here], blocks["text"][block_here],
                                   *crosses, links=_frame_links(links, markers),
                                   from_views=blocks["views"][block_here])
                what_points = "keypoints" if links is not None else "named corners"
                title = (f"{source.camera} frame {t}: {len(xy)} {what_points}"
                         + (f", {int(block_here.sum())} tags" if blocks["present"] else "")
                         + (f" ({int(blocks['views'][block_here].sum())} from the other cameras)"
                            if blocks["views"][block_here].any() else ""))
                ok, code = cv2.imencode(".jpg", draw_frame(image, marks, title, owners),
                                        [cv2.IMWRITE_JPEG_QUALITY, QUALITY])
                if not ok:
                    raise HandcapError(f"{source.camera} frame {t}: the picture could not be encoded as JPEG")
                with atomic_output(folder / source.camera / f"{t:06d}.jpg", "wb") as fh:
                    fh.write(code.tobytes())
                written += 1
                bar.update(1)
    finally:
        bar.close()
    return written, outside, total


def _frame_links(links, markers: np.ndarray) -> np.ndarray | None:
    """``links`` (pairs of marker indices) as pairs of rows of one frame whose ``markers`` hold both ends (the first
    row of a marker seen twice)."""
    if links is None or not len(markers):
        return None
    row = {}
    for k, m in enumerate(markers.tolist()):
        row.setdefault(m, k)
    return np.array([(row[a], row[b]) for a, b in np.asarray(links, int).reshape(-1, 2) if a in row and b in row],
                    int).reshape(-1, 2)
