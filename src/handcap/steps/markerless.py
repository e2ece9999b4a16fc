"""Steps of markerless capture: ``keypoints import`` (files people have to 2D detections), ``fit_keypoints``
(3D keypoints to a hand motion) and ``markerless`` (one video's keypoints to a hand motion)."""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from handcap.core.camera import Camera
from handcap.core.errors import HandcapError
from handcap.detect.sources import frame_notes, frame_sources
from handcap.hand import hand_model_from_options
from handcap.io import (check_not_input, read_markers, read_mesh, read_scan_points, write_hand_motion,
                        write_object_motion)
from handcap.io.camera_formats import read_rig
from handcap.markerless import fit_keypoints as fitting
from handcap.markerless import hand_labels, import_keypoints
from handcap.markerless.capture import capture_video, video_keypoints
from handcap.markerless.contact import ContactMap
from handcap.markerless.detector import KeypointDetector, detect_keypoints
from handcap.markerless.fit import ROBUST_SCALE
from handcap.markerless.grasp import capture_grasp
from handcap.markerless.keypoints import hand_names
from handcap.multiview import read_detections, write_detections
from handcap.steps.step import Step


def keypoints_import(paths, fmt: str, out, *, rate: float, cameras=None) -> Step:
    """2D hand keypoints of another tool's files as a 2D detections file (see
    :func:`handcap.markerless.import_keypoints`).

    Parameters
    ----------
    paths : sequence of str or Path
        One input per camera (a file per handedness label of one camera is a candidate hand of it).
    fmt : str
        ``mediapipe-npy``, ``openpose-json`` or ``coco-json``.
    out : str or Path
        Detections .npz to write.
    rate : float
        Frames per second.
    cameras : sequence of str, optional
        Camera names (default: from the inputs' names).
    """
    paths = list(paths)
    check_not_input(out, *paths)
    detections = import_keypoints(paths, fmt, rate=rate, cameras=cameras)
    write_detections(detections, out)
    labels = hand_labels(detections.marker_names)
    per_camera = len(detections) / max(len(detections.camera_names), 1)
    line = (f"{out}: {len(detections)} keypoints of {len(labels)} hand label(s) ({', '.join(labels) or 'unlabelled'}) "
            f"in {len(detections.camera_names)} camera(s), {detections.n_frames} frames ({per_camera:.0f} per camera)")
    warnings = () if len(detections) else (f"{out}: no keypoint in the inputs",)
    return Step((line,), warnings, (str(out),), detections)


def fit_keypoints(path, out, *, label: str | None = None, side: str | None = None, fit_shape: bool = True,
                  robust_scale: float = ROBUST_SCALE, filter_cutoff: float | None = None, units: str | None = None,
                  hand_model: str | None = None, mano_dir=None) -> Step:
    """Fit the hand model to 3D keypoints (see :func:`handcap.markerless.fit_keypoints`) and write the motion.

    Parameters
    ----------
    path, out : str or Path
        3D keypoints (any marker file: names ``[LABEL:]wrist`` ...); the hand motion .npz to write.
    label : str or None
        The hand to fit when the file has several.
    side : {'right', 'left'} or None
        Default: the label when it is one, else right.
    fit_shape : bool
        Fit the shape to the take's bone lengths.
    robust_scale : float
        Cauchy scale of the keypoint residuals, metres.
    filter_cutoff : float or None
        Low-pass the motion at this frequency, Hz.
    units : {'mm', 'cm', 'm'} or None
        Unit of the input's coordinates, overriding what the file says.
    hand_model, mano_dir : str or None
        The hand model (default openhand).
    """
    check_not_input(out, path)
    keypoints = read_markers(path, units=units, hand=list(hand_names(label or "")))
    labels = hand_labels(keypoints.names)
    chosen = label if label is not None else (labels[0] if len(labels) == 1 else None)
    side = side or (chosen if chosen in ("left", "right") else None)
    hand = hand_model_from_options(hand_model, mano_dir, side=side or "right", recorded=None, what=str(path))
    start = time.perf_counter()
    motion = fitting(keypoints, label=label, side=side, hand=hand, fit_shape=fit_shape, robust_scale=robust_scale,
                     filter_cutoff=filter_cutoff)
    seconds = time.perf_counter() - start
    motion = motion.with_warnings(*keypoints.warnings)
    write_hand_motion(motion, out)
    res = motion.marker_residuals
    line = (f"{out}: {motion.side} hand, {motion.n_frames} frames in {seconds:.1f} s "
            f"({motion.n_frames / max(seconds, 1e-9):.0f} frames/s), keypoint MRE {1000 * np.nanmean(res):.2f} mm "
            f"(median {1000 * np.nanmedian(res):.2f}), {int(np.isfinite(res).sum())} of "
            f"{res.size} keypoints seen, shape {np.round(motion.betas, 2).tolist()}")
    return Step((line,), motion.warnings, (str(out),), motion)


def _intrinsics(spec: str, camera: str | None, units: str | None):
    """A Camera from a cameras file (and a name) or from ``fx,fy,cx,cy[,k1,k2,p1,p2,k3]``."""
    parts = spec.split(",")
    if len(parts) in (4, 9) and not Path(spec).exists():
        try:
            v = [float(x) for x in parts]
        except ValueError:
            raise HandcapError(f"--intrinsics {spec!r}: give a cameras file or fx,fy,cx,cy[,k1,k2,p1,p2,k3] in "
                               f"pixels") from None
        if not all(np.isfinite(v)) or v[0] <= 0 or v[1] <= 0:
            raise HandcapError(f"--intrinsics {spec!r}: focal lengths must be positive pixels")
        size = (max(1, int(round(2 * v[2]))), max(1, int(round(2 * v[3]))))
        distortions = v[4:] if len(v) == 9 else (0.0,) * 5
        return Camera("video", size, [[v[0], 0, v[2]], [0, v[1], v[3]], [0, 0, 1]], distortions=distortions)
    rig = read_rig(spec, units=units)
    if camera is None:
        if len(rig) > 1:
            raise HandcapError(f"{spec} has {len(rig)} cameras ({', '.join(rig.names)}): choose one with --camera")
        return rig[0]
    return rig[camera]


def _object_pose(path, factor) -> np.ndarray:
    """A 4 x 4 object-to-camera pose from a text file (16 numbers), ``.npy`` or ``.npz`` (``pose``)."""
    path = Path(path)
    if not path.is_file():
        raise HandcapError(f"{path}: no such object pose file")
    try:
        if path.suffix.lower() == ".npz":
            with np.load(path, allow_pickle=False) as data:
                pose = np.asarray(data["pose"], dtype=np.float64)
        elif path.suffix.lower() == ".npy":
            pose = np.asarray(np.load(path, allow_pickle=False), dtype=np.float64)
        else:  # 16 numbers separated by spaces, commas or semicolons; '#' starts a comment
            text = " ".join(line.split("#")[0] for line in path.read_text(errors="replace").splitlines())
            pose = np.array([float(v) for v in text.replace(",", " ").replace(";", " ").split()])
    except Exception as err:  # numpy's readers raise many types for a bad file
        raise HandcapError(f"{path}: not an object pose (a 4 x 4 matrix: 16 numbers, .npy, or .npz with 'pose'): "
                           f"{' '.join(str(err).split())[:100]}") from None
    pose = np.asarray(pose, dtype=np.float64).reshape(-1)
    if pose.size != 16 or not np.isfinite(pose).all():
        raise HandcapError(f"{path}: an object pose is a 4 x 4 matrix of finite numbers, got {pose.size} values")
    pose = pose.reshape(4, 4).copy()
    pose[:3, 3] *= factor
    return pose


def _object_mesh(obj, contact, factor):
    """The object's mesh (vertices metres, faces) and the contact map, from the files given."""
    contact_map = ContactMap.load(contact) if contact is not None else None
    if obj is None:
        return contact_map.vertices, contact_map.faces, contact_map
    if Path(obj).suffix.lower() == ".npz":
        loaded = ContactMap.load(obj)
        return loaded.vertices, loaded.faces, contact_map
    mesh = read_mesh(obj, "object mesh")
    vertices = np.asarray(getattr(mesh, "vertices", []), dtype=np.float64) * factor
    faces = np.asarray(getattr(mesh, "faces", np.zeros((0, 3))), dtype=np.int64)
    if vertices.ndim != 2 or len(faces) == 0:
        raise HandcapError(f"{obj}: holds no mesh faces; give the object's surface mesh")
    across = float(np.ptp(vertices, axis=0).max())
    if not 0.005 <= across <= 2.0:
        raise HandcapError(f"{obj}: the object is {across:.3g} m across: give its unit with --object-units")
    return vertices, faces, contact_map


def markerless(path, out, *, intrinsics: str, camera: str | None = None, label: str | None = None,
               side: str | None = None, method: str = "joint", scale: float | None = None, rate: float | None = None,
               hand_model: str | None = None, mano_dir=None, obj=None, object_pose=None, object_points=None,
               object_frame: int = 0, contact=None, object_units: str = "m", object_out=None) -> Step:
    """Hand pose and shape of a steady grasp from one camera's 2D keypoints (see
    :func:`handcap.markerless.capture_video`), written as a hand motion in the camera's frame; with an object,
    its motion too (see :func:`handcap.markerless.grasp.capture_grasp`).

    Parameters
    ----------
    path, out : str or Path
        2D keypoints (.npz, a detections file: ``keypoints import`` makes one); the motion .npz to write.
    intrinsics : str
        A cameras file (the camera named ``camera``, or its only one) or ``fx,fy,cx,cy[,k1,k2,p1,p2,k3]``.
    camera : str or None
        The keypoints' camera when they hold several, and its name in the cameras file.
    label : str or None
        The hand to start from when a frame shows several (default: the label given most often).
    side : {'right', 'left'} or None
        Default: the label when it is one, else right.
    method : {'joint', 'two-stage'}
    scale : float or None
        The hand's size relative to an average adult's (default: measured against the object's contact map
        when one is given, else 1).
    rate : float or None
        Frames per second (default: the keypoints').
    hand_model, mano_dir : str or None
    obj : str, Path or None
        The held object's mesh (any format trimesh reads, or a contact map .npz); default: the contact map's.
    object_pose : str, Path or None
        Its pose in ``object_frame`` (object to camera, 4 x 4): the pose, or ICP's start with ``object_points``.
    object_points : str, Path or None
        Points of its surface in ``object_frame``'s camera (.npz ``points``, .ply ...).
    object_frame : int
    contact : str, Path or None
        A contact map .npz (:mod:`handcap.markerless.contact`): measures the hand's size, refines the grasp.
    object_units : {'m', 'cm', 'mm'}
        Unit of the object's mesh, pose and points.
    object_out : str, Path or None
        The object motion .npz to write (default: ``OUT``'s name with ``-object``).
    """
    grasp = obj is not None or contact is not None
    if not grasp and (object_pose is not None or object_points is not None):
        raise HandcapError("--object-pose and --object-points need the object: --object MESH or --contact MAP")
    if scale is not None and not (np.isfinite(scale) and 0.5 <= scale <= 2.0):
        raise HandcapError(f"--scale {scale}: the hand's size relative to an average adult's, 0.5-2")
    object_out = Path(object_out) if object_out else Path(out).with_name(Path(out).stem + "-object.npz")
    inputs = [p for p in (path, obj, object_pose, object_points, contact) if p is not None]
    check_not_input(out, *inputs)
    if grasp:
        check_not_input(object_out, out, *inputs)
    detections = read_detections(path)
    pixels = video_keypoints(detections, camera, label)
    cam = _intrinsics(intrinsics, camera, None)
    chosen = label or (hand_labels(detections.marker_names) or [""])[0]
    side = side or (chosen if chosen in ("left", "right") else "right")
    hand = hand_model_from_options(hand_model, mano_dir, side=side, recorded=None, what=str(path))
    rate = rate or detections.rate
    start = time.perf_counter()
    if not grasp:
        result = capture_video(pixels, cam, hand=hand, method=method, rate=rate, scale=scale or 1.0)
        write_hand_motion(result.motion, out)
        line = (f"{out}: {side} hand, {result.summary()}, {time.perf_counter() - start:.1f} s; shape "
                f"{np.round(result.motion.betas, 2).tolist()}")
        return Step((line,), result.motion.warnings, (str(out),), result)
    factor = {"m": 1.0, "cm": 0.01, "mm": 0.001}.get(object_units)
    if factor is None:
        raise HandcapError(f"--object-units {object_units!r}: choose m, cm or mm")
    vertices, faces, contact_map = _object_mesh(obj, contact, factor)
    pose = _object_pose(object_pose, factor) if object_pose is not None else None
    points = read_scan_points(object_points) * factor if object_points is not None else None
    name = Path(obj).stem if obj is not None else "object"
    result = capture_grasp(pixels, cam, vertices, faces, object_pose=pose, object_points=points, frame=object_frame,
                           contact_map=contact_map, scale=scale, hand=hand, method=method, rate=rate, name=name)
    write_hand_motion(result.video.motion, out)
    write_object_motion(result.object_motion, object_out)
    lines = (f"{out}: {side} hand, {result.video.summary()}, {time.perf_counter() - start:.1f} s",
             f"{object_out}: {name} carried through {len(pixels)} frames; {result.summary()}")
    return Step(lines, result.video.motion.warnings, (str(out), str(object_out)), result)


def keypoints_detect(inputs, out, *, rate: float | None = None, mirrored: bool = False, retry: bool = True,
                     max_hands: int = 2, progress: bool | None = None) -> Step:
    """2D hand keypoints of images or videos (MediaPipe's landmarker with retries), as a 2D detections file.

    Parameters
    ----------
    inputs : sequence of str or Path
        One per camera: a folder of images, a video or an image (its name is the camera's); a take's folder
        of videos or of folders of images gives a camera to each.
    out : str or Path
        Detections .npz to write.
    rate : float or None
        Frames per second (default: a video's own, else 30 with a warning).
    mirrored : bool
        The images are mirrored (a selfie camera).
    retry : bool
        Try again, at other places, scales and turns, where the landmarker finds no hand.
    max_hands : int
        Most hands per image.
    progress : bool or None
    """
    sources = frame_sources(inputs)
    check_not_input(out, *[f for s in sources for f in (s.files or (s.path,))])
    warnings = frame_notes(sources)
    if rate is None:
        rates = [r for r in (s.fps() for s in sources) if r is not None]
        rate = rates[0] if rates else 30.0
        if not rates:
            warnings.append("frame rate not given (--rate): 30 Hz assumed")
    elif not 0 < rate < 100000:
        raise HandcapError(f"--rate {rate}: give frames per second, more than 0")
    detector = KeypointDetector(max_hands=max_hands, mirrored=mirrored, retry=retry)
    try:
        detections, counts = detect_keypoints(sources, detector, rate, progress=progress)
    finally:
        detector.close()
    if not counts["with_hand"]:
        warnings.append(f"no hand found in any of the {counts['frames']} frames")
    write_detections(detections, out)
    retried = {k: v for k, v in counts.items() if k not in ("frames", "with_hand", "plain") and v}
    line = (f"{out}: hands in {counts['with_hand']} of {counts['frames']} frames of {len(sources)} camera(s); "
            f"{counts['plain']} found by the landmarker alone"
            + (", then " + ", ".join(f"{v} by {k}" for k, v in retried.items()) if retried else ""))
    return Step((line,), tuple(warnings), (str(out),), detections)
