"""Importers for 2D hand keypoints people already have: MediaPipe arrays, OpenPose JSON, COCO keypoint files.

Each reads one input (a file or a folder) as the keypoints of one camera, and
:func:`import_keypoints` merges several into the 2D detections File contract
(marker names ``LABEL:keypoint``, :mod:`~handcap.markerless.keypoints`). Several
inputs of one camera (a file per handedness label, as MediaPipe users often
save) are candidate hands of that camera.

Formats (``--format``):

``mediapipe-npy``
    A ``.npy`` array ``(C, T, 21, 2)`` (cameras first) or ``(T, 21, 2)``, pixels; a third column, when
    present, is the score. Negative or NaN coordinates mean missing. The label is the file name's
    ``left``/``right`` when it has one, else ``hand``; cameras are ``cam0``, ``cam1``... unless named.
``openpose-json``
    A folder of OpenPose's per-frame ``*_keypoints.json`` files (``people[].hand_left_keypoints_2d`` and
    ``hand_right_keypoints_2d``, 21 x (x, y, confidence)); the frame is the number in the file name, the
    camera the folder's name. Confidence 0 means missing. A second person's hands are labelled
    ``left1``/``right1``.
``coco-json``
    A COCO keypoint file (``images`` and ``annotations``, or a list of results as mmpose writes them):
    ``keypoints`` of 21 x (x, y, v) per hand, or COCO-WholeBody's ``lefthand_kpts``/``righthand_kpts``.
    v = 0 (or a zero score) means missing. The frame is the image's order by id, the camera the file's
    name; the label is the annotation's ``handedness``/``hand_type`` when given, else ``hand``,
    ``hand1``... in the order of the image's annotations.

Pixels are read as the file gives them (OpenCV's convention: pixel centres at integers, as in handcap).
"""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np

from handcap.core.errors import HandcapError
from handcap.core.files import natural_key
from handcap.markerless.keypoints import hand_names, split_hand_name
from handcap.multiview.detections import Detections

FORMATS = ("mediapipe-npy", "openpose-json", "coco-json")
#: Largest file read as JSON, bytes (a keypoint file of a long take is a few hundred MB at most).
MAX_JSON_BYTES = 2_000_000_000


def _label_from_name(path: Path) -> str:
    stem = path.stem.lower()
    for side in ("left", "right"):
        if re.search(rf"(^|[^a-z]){side}([^a-z]|$)", stem) or stem.startswith(side) or stem.endswith(side):
            return side
    return "hand"


def _rows(points, camera_names, label: str, rate: float, source: str, n_frames=None) -> Detections:
    """Detections from points (C, T, 21, 3) = x, y, score (NaN x where missing)."""
    points = np.asarray(points, dtype=np.float64)
    c, t, k = np.nonzero(np.isfinite(points[..., :2]).all(axis=-1))
    return Detections(tuple(camera_names), hand_names(label), t, c, k, points[c, t, k, :2], points[c, t, k, 2],
                      rate, points.shape[1] if n_frames is None else n_frames, source=source)


def read_mediapipe_npy(path, *, rate: float, cameras=None, label: str | None = None) -> Detections:
    """Keypoints of a MediaPipe-style ``.npy`` array (see the module docstring).

    Parameters
    ----------
    path : str or Path
    rate : float
        Frames per second.
    cameras : sequence of str, optional
        Camera names, one per row of the first axis (default ``cam0``...).
    label : str, optional
        Hand label (default: from the file name).

    Returns
    -------
    Detections
    """
    path = Path(path)
    try:
        array = np.load(path, allow_pickle=False)
    except (OSError, ValueError, EOFError) as exc:
        raise HandcapError(f"{path}: not a readable .npy array ({exc})") from None
    if array.dtype.kind not in "fiu":
        raise HandcapError(f"{path}: keypoints must be numbers, got {array.dtype}")
    if array.ndim == 3:
        array = array[None]
    if array.ndim != 4 or array.shape[2] != 21 or array.shape[3] not in (2, 3):
        raise HandcapError(f"{path}: expected keypoints of shape (C, T, 21, 2|3) or (T, 21, 2|3), got {array.shape}")
    array = array.astype(np.float64)
    xy = array[..., :2]
    score = array[..., 2] if array.shape[3] == 3 else np.ones(array.shape[:3])
    missing = ~np.isfinite(xy).all(axis=-1) | (xy < 0).any(axis=-1) | ~np.isfinite(score)
    if np.isinf(xy).any() or (np.abs(np.nan_to_num(xy)) > 1e6).any():
        raise HandcapError(f"{path}: keypoint coordinates beyond a million pixels: not pixels")
    points = np.concatenate([xy, score[..., None]], axis=-1)
    points[missing] = np.nan
    names = _camera_names(cameras, array.shape[0], path)
    return _rows(points, names, label or _label_from_name(path), rate, str(path))


def _camera_names(cameras, count: int, path) -> tuple:
    if cameras is None:
        return tuple(f"cam{c}" for c in range(count))
    cameras = tuple(str(c) for c in cameras)
    if len(cameras) != count:
        raise HandcapError(f"{path}: {count} cameras in the array but {len(cameras)} names given")
    return cameras


def _load_json(path: Path):
    try:
        if path.stat().st_size > MAX_JSON_BYTES:
            raise HandcapError(f"{path}: over {MAX_JSON_BYTES // 10**9} GB; not a keypoint file")
        with open(path, "rb") as fh:
            return json.load(fh)
    except (OSError, UnicodeDecodeError, json.JSONDecodeError, RecursionError) as exc:
        raise HandcapError(f"{path}: not a readable JSON file ({type(exc).__name__})") from None


def _hand_array(values, where: str) -> np.ndarray:
    """21 x (x, y, c) from a flat list; NaN rows where the confidence is 0 or the point is (0, 0)."""
    try:
        a = np.asarray(values, dtype=np.float64).reshape(-1)
    except (TypeError, ValueError):
        raise HandcapError(f"{where}: hand keypoints must be numbers") from None
    if a.size == 0:
        return np.full((21, 3), np.nan)
    if a.size != 63:
        raise HandcapError(f"{where}: a hand needs 21 x 3 numbers (x, y, confidence), got {a.size}")
    a = a.reshape(21, 3)
    if not np.isfinite(a).all() or (np.abs(a[:, :2]) > 1e6).any():
        raise HandcapError(f"{where}: hand keypoints must be finite pixel coordinates")
    a[(a[:, 2] <= 0) | (a[:, :2] == 0).all(axis=1)] = np.nan
    return a


def read_openpose_folder(folder, *, rate: float, camera: str | None = None) -> Detections:
    """Keypoints of a folder of OpenPose per-frame JSON files (see the module docstring).

    Parameters
    ----------
    folder : str or Path
    rate : float
    camera : str, optional
        Camera name (default: the folder's name).

    Returns
    -------
    Detections
    """
    folder = Path(folder)
    if not folder.is_dir():
        raise HandcapError(f"{folder}: OpenPose keypoints are a folder of per-frame JSON files")
    files = sorted(folder.glob("*.json"), key=natural_key)
    if not files:
        raise HandcapError(f"{folder}: no .json files")
    numbers = []
    for f in files:
        found = re.findall(r"\d+", f.stem)
        numbers.append(int(found[-1]) if found else None)
    if None in numbers or len(set(numbers)) != len(numbers):
        numbers = list(range(len(files)))  # no frame numbers in the names: file order
    first = min(numbers)
    hands: dict[str, dict[int, np.ndarray]] = {}
    for f, n in zip(files, numbers):
        data = _load_json(f)
        people = data.get("people", []) if isinstance(data, dict) else None
        if not isinstance(people, list):
            raise HandcapError(f"{f}: not an OpenPose keypoint file (no 'people' list)")
        for i, person in enumerate(people):
            if not isinstance(person, dict):
                raise HandcapError(f"{f}: person {i} is not an object")
            for side in ("left", "right"):
                key = f"hand_{side}_keypoints_2d"
                if key in person:
                    a = _hand_array(person[key], f"{f}: person {i} {key}")
                    if np.isfinite(a[:, 0]).any():
                        hands.setdefault(side if i == 0 else f"{side}{i}", {})[n - first] = a
    n_frames = max(numbers) - first + 1
    return _merge_hands(hands, camera or folder.name, rate, str(folder), n_frames)


def _merge_hands(hands: dict, camera: str, rate: float, source: str, n_frames: int) -> Detections:
    parts = []
    for label, frames in sorted(hands.items()):
        points = np.full((1, n_frames, 21, 3), np.nan)
        for t, a in frames.items():
            points[0, t] = a
        parts.append(_rows(points, (camera,), label, rate, source, n_frames))
    if not parts:
        return Detections((camera,), hand_names("hand"), np.zeros(0, int), np.zeros(0, int), np.zeros(0, int),
                          np.zeros((0, 2)), np.zeros(0), rate, n_frames, source=source)
    return merge_keypoints(parts)


def read_coco_json(path, *, rate: float, camera: str | None = None) -> Detections:
    """Keypoints of a COCO keypoint file (see the module docstring).

    Parameters
    ----------
    path : str or Path
    rate : float
    camera : str, optional
        Camera name (default: the file's stem).

    Returns
    -------
    Detections
    """
    path = Path(path)
    data = _load_json(path)
    if isinstance(data, list):
        images, annotations = None, data
    elif isinstance(data, dict) and isinstance(data.get("annotations"), list):
        images, annotations = data.get("images"), data["annotations"]
    else:
        raise HandcapError(f"{path}: not a COCO keypoint file (no 'annotations' list, nor a list of results)")
    ids = []
    for i, ann in enumerate(annotations):
        if not isinstance(ann, dict) or not _is_id(ann.get("image_id")):
            raise HandcapError(f"{path}: annotation {i} has no image_id (a number or a string)")
        ids.append(ann["image_id"])
    if isinstance(images, list) and images:
        if not all(isinstance(img, dict) and _is_id(img.get("id")) for img in images):
            raise HandcapError(f"{path}: every image needs an id (a number or a string)")
        order = sorted({img["id"] for img in images}, key=lambda v: (isinstance(v, str), v))
    else:
        order = sorted(set(ids), key=lambda v: (isinstance(v, str), v))
    frame_of = {image_id: k for k, image_id in enumerate(order)}
    hands: dict[str, dict[int, np.ndarray]] = {}
    count: dict[tuple, int] = {}
    for i, ann in enumerate(annotations):
        if ann["image_id"] not in frame_of:
            raise HandcapError(f"{path}: annotation {i} names image {ann['image_id']!r} that the file lacks")
        t = frame_of[ann["image_id"]]
        where = f"{path}: annotation {i}"
        found = [(side, ann[f"{side}hand_kpts"]) for side in ("left", "right") if f"{side}hand_kpts" in ann]
        if not found and "keypoints" in ann:
            side = str(ann.get("handedness", ann.get("hand_type", "hand"))).lower()
            side = side if re.fullmatch(r"[a-z][a-z0-9_]*", side) else "hand"
            k = count.get((t, side), 0)
            count[(t, side)] = k + 1
            found = [(side if k == 0 else f"{side}{k}", ann["keypoints"])]
        for label, values in found:
            a = _hand_array(values, where)
            score = ann.get("score")
            if score is not None:
                if isinstance(score, bool) or not isinstance(score, (int, float)) or not np.isfinite(score):
                    raise HandcapError(f"{where}: score must be a number, got {score!r}")
                a[:, 2] = np.where(np.isfinite(a[:, 2]), float(score), np.nan)
            if np.isfinite(a[:, 0]).any():
                hands.setdefault(label, {})[t] = a
    return _merge_hands(hands, camera or path.stem, rate, str(path), max(len(order), 1))


def _is_id(value) -> bool:
    return isinstance(value, str) or (isinstance(value, int) and not isinstance(value, bool))


def import_keypoints(paths, fmt: str, *, rate: float, cameras=None) -> Detections:
    """Read keypoint files of one format and merge them into one set of 2D detections.

    Parameters
    ----------
    paths : sequence of str or Path
        One input per camera (several inputs may name the same camera: its candidate hands).
    fmt : str
        One of :data:`FORMATS`.
    rate : float
        Frames per second.
    cameras : sequence of str, optional
        Camera name of each input; for mediapipe-npy, of each row of the camera axis (the same in every file).

    Returns
    -------
    Detections
    """
    if fmt not in FORMATS:
        raise HandcapError(f"unknown keypoint format {fmt!r}; choose one of {', '.join(FORMATS)}")
    paths = [Path(p) for p in paths]
    if not paths:
        raise HandcapError("give at least one keypoint file")
    for p in paths:
        if not p.exists():
            raise HandcapError(f"{p}: no such file or folder")
    if not (np.isfinite(rate) and rate > 0):
        raise HandcapError(f"rate must be a positive number of frames per second, got {rate}")
    if fmt == "mediapipe-npy":  # every file has the camera axis: the names apply to each
        parts = [read_mediapipe_npy(p, rate=rate, cameras=cameras) for p in paths]
    else:
        if cameras is not None and len(cameras) != len(paths):
            raise HandcapError(f"{len(paths)} inputs but {len(cameras)} camera names")
        names = [None] * len(paths) if cameras is None else list(cameras)
        read = read_openpose_folder if fmt == "openpose-json" else read_coco_json
        parts = [read(p, rate=rate, camera=n) for p, n in zip(paths, names)]
    return merge_keypoints(parts)


def merge_keypoints(parts) -> Detections:
    """One set of 2D keypoints from several, cameras and candidate hands pooled.

    Unlike :func:`handcap.multiview.merge_detections`, a camera may come from several inputs (one per
    handedness label): their hands are candidates of that camera. A hand label that an earlier input already
    gave in the same camera is numbered (``hand`` -> ``hand1``) so no two candidates share a name. The take
    is as long as the longest input.

    Parameters
    ----------
    parts : sequence of Detections
        Keypoint detections (marker names ``LABEL:keypoint``), all at one rate.

    Returns
    -------
    Detections
    """
    parts = list(parts)
    if not parts:
        raise HandcapError("no keypoints to merge")
    rate = parts[0].rate
    cameras, markers, taken = [], [], set()
    columns = {"frame": [], "camera": [], "marker": [], "xy": [], "score": []}
    for part in parts:
        if part.rate != rate:
            raise HandcapError(f"{part.source}: rate {part.rate:g} Hz differs from {parts[0].source} ({rate:g} Hz)")
        labels = sorted({split_hand_name(n)[0] for n in part.marker_names})
        rename = {}
        for label in labels:
            new, k = label, 0
            while any((c, new) in taken for c in part.camera_names):
                k += 1
                new = f"{label or 'hand'}{k}"
            rename[label] = new
            taken.update((c, new) for c in part.camera_names)
        for c in part.camera_names:
            if c not in cameras:
                cameras.append(c)
        names = []
        for n in part.marker_names:
            label, point = split_hand_name(n)
            names.append(f"{rename[label]}:{point}" if rename[label] else point)
        markers.extend(n for n in names if n not in markers)
        columns["frame"].append(part.frame)
        columns["camera"].append(np.array([cameras.index(n) for n in part.camera_names], np.int64)[part.camera])
        columns["marker"].append(np.array([markers.index(n) for n in names], np.int64)[part.marker])
        columns["xy"].append(part.xy)
        columns["score"].append(part.score)
    joined = {key: np.concatenate(value) for key, value in columns.items()}
    order = np.lexsort((joined["marker"], joined["camera"], joined["frame"]))
    return Detections(tuple(cameras), tuple(markers), *(joined[k][order] for k in ("frame", "camera", "marker", "xy",
                                                                                  "score")),
                      rate, max(p.n_frames for p in parts), source=" + ".join(p.source for p in parts))
