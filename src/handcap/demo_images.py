"""``handcap demo --images``: the whole DexterCap path from pixels, on rendered takes with their truth.

1. Synthesize a calibration take (open hand, slowly turned) and a grasp take of
   one subject wearing the ``dense-patches`` layout, seen by 13 cameras, and a
   take of the same hand turning the patched 2x2x2 cube through two moves, seen by
   6, and render every frame of every camera (:func:`handcap.synth.filming.film_capture`).
   The cameras read out the window of their 5 MP sensor that holds the hand
   (:func:`~handcap.synth.filming.region_rig`): the same lens and pixels, a
   fraction of the rendering and detection time.
2. Detect the coded patches in every image with the shipped networks and the
   takes' template (:mod:`handcap.detect`); name the squares a camera could not
   read from its neighbouring frames and the other cameras
   (:mod:`handcap.detect.motion`, :mod:`handcap.detect.views`).
3. Triangulate the named corners (RANSAC over views), clean them, calibrate the
   marker attachment on the calibration take and solve the grasp take; track the
   held object (its patches' corners, ``handcap track-object --markers 'NAME:*'``) and
   the cube (``track-object --articulated cube2x2-patches``: its pose and moves).
4. Measure each stage against the truth: corners named per image and their
   pixel error, triangulated corners (mm), reprojection (px), calibration and
   solve marker residuals (MRE, mm), joint error (mm), the object's corners as
   its track places them (mm), the cube's moves and its pose and cubies (mm, degrees).

Writes into the output folder (rewritten on every run): ``calibration/``,
``take/`` and ``cube/``, each with ``cameras.toml``, ``images/CAM/FRAME.png``,
``image_truth.npz``, ``pattern.toml``, ``detections.npz`` (from the images), ``overlay/CAM/FRAME.jpg``
(the first camera's detections drawn over its frames, :mod:`handcap.detect.overlay`),
``triangulated.c3d``, ``cleaned.c3d``, ``truth.npz`` (the true hand motion) and, where an object is held,
``object_motion.npz`` (``cube/``: ``cube_motion.npz``, the cube's pose, layer angles and moves);
``attachment.npz``, ``motion.npz`` and ``summary.json``/``summary.txt`` beside them.
"""

from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from handcap.core.files import atomic_output, file_stamps, save_npz, written_since
from handcap.core.transforms import homogeneous
from handcap.detect.overlay import write_pictures
from handcap.detect.capture import detect_capture
from handcap.detect.networks import load_checker, load_corner_net, load_reader, load_refiner
from handcap.detect.pipeline import Detector
from handcap.detect.sources import frame_sources
from handcap.detect.motion import name_from_frames
from handcap.detect.seek import searched_frames, second_look
from handcap.detect.views import name_from_views
from handcap.io import write_hand_motion, write_markers, write_object_motion
from handcap.layouts import load_layout
from handcap.multiview import clean_markers, read_detections, triangulate_detections
from handcap.objects import load_articulated, track_rigid
from handcap.objects.cube_output import cube_errors, cube_motion
from handcap.objects.cube_track import smoothing_window, track_cube
from handcap.patterns.pattern import Pattern
from handcap.quality import plausibility as q
from handcap.solve import calibrate_attachment, solve_hand
from handcap.synth.config import SynthConfig
from handcap.synth.filming import film_take

#: The takes, one subject: 13 cameras at 4 Hz, 8 frames of calibration and 11 of the grasp (its shortest: 2.5 s);
#: 6 cameras at 15 Hz on the hand turning the patched 2x2x2 cube through two moves (its 24 textured patches make
#: these frames the slowest to render, about 0.6 s each).
IMAGE_DEMO_CONFIGS = {
    "calibration": SynthConfig(layout="dense-patches", motion="calibration", frames=8, rate=4.0, seed=8,
                               subject_seed=21, cameras=13, min_views=3, object="none"),
    "take": SynthConfig(layout="dense-patches", motion="grasp", frames=11, rate=4.0, seed=7, subject_seed=21,
                        cameras=13, min_views=3),
    "cube": SynthConfig(layout="dense-patches", motion="turn-cube", moves="R U'", rate=15.0, seed=5, subject_seed=21,
                        cameras=6, min_views=2),
}


def run_image_demo(out="demo-images", *, configs=None, progress: bool | None = None) -> dict:
    """Run the demo into ``out`` (see the module docstring); returns its summary.

    Parameters
    ----------
    out : str or Path
        Output folder; created if needed, files already there are written over.
    configs : dict, optional
        ``{"calibration": SynthConfig, "take": SynthConfig}`` (default :data:`IMAGE_DEMO_CONFIGS`).
    progress : bool, optional
        Progress bars (default: only on a terminal).

    Returns
    -------
    dict
        Figures per stage (keys name their unit: ``_mm``, ``_px``, ``_fraction``, ``_seconds``),
        ``warnings`` (list of str) and ``files`` (the paths written).
    """
    out = Path(out)
    before = file_stamps(out)
    configs = configs or IMAGE_DEMO_CONFIGS
    detector = None
    summary, warnings, cleaned, captures = {}, [], {}, {}
    for key, config in configs.items():
        folder = out / key
        folder.mkdir(parents=True, exist_ok=True)
        start = time.perf_counter()
        captures[key] = capture = film_take(config, folder, progress=progress)
        summary[f"{key}_render_seconds"] = round(time.perf_counter() - start, 1)
        pattern = Pattern.load(folder / "pattern.toml")
        if detector is None:
            detector = Detector(load_corner_net(int8=True), load_reader(), pattern, refiner=load_refiner(int8=True),
                                checker=load_checker())
        detector.pattern = pattern
        sources = frame_sources([folder / "images" / c.name for c in capture.rig])
        start = time.perf_counter()
        # synth renders grey levels linear in the light (handcap.synth.images): no camera's response to choose.
        run = detect_capture(detector, sources, pattern.corner_names(), config.rate, progress=progress,
                             response="linear")
        # The squares a camera could not read, named where its neighbouring frames and the other cameras place them
        # (handcap.detect.motion, handcap.detect.views).
        moved = name_from_frames(run.arrays, run.unread, pattern, progress=progress)
        naming = name_from_views(moved.arrays, moved.left, capture.rig, pattern, progress=progress)
        warnings += list(naming.warnings)
        # ... and a second look where the other cameras or the neighbouring frames place squares (handcap.detect.seek).
        sought = second_look(naming.arrays, pattern, detector.refiner,
                             searched_frames(detector, sources, run.responses), rig=capture.rig, progress=progress)
        seconds = time.perf_counter() - start
        save_npz(folder / "detections.npz", sought.arrays | {"pitch": np.array(pattern.pitch)})
        # To look at: the detections drawn over one camera's frames (handcap overlay draws any camera's).
        write_pictures(sought.arrays, sources[:1], folder / "overlay", progress=False)
        summary.update(_detection_figures(key, run.images, sought.arrays, folder / "image_truth.npz", seconds))
        summary[f"{key}_squares_named_from_frames"] = moved.squares
        summary[f"{key}_squares_named_from_views"] = naming.squares
        summary[f"{key}_squares_found_by_a_second_look"] = sought.squares
        triangulated = triangulate_detections(read_detections(folder / "detections.npz"), capture.rig,
                                              min_views=config.min_views, progress=progress)
        found = q.triangulation_warnings(triangulated.error_px, triangulated.views, threshold_px=5.0,
                                         used=triangulated.used)
        # The template names its corners OWNER:PATCH_rRcC; the layout names the hand's PATCH_rRcC (a held object's
        # keep their owner: cylinder:band_r0c0).
        markers = triangulated.to_markers()
        side = f"{config.side}:"
        markers = markers.renamed([n[len(side):] if n.startswith(side) else n for n in markers.names])
        # The printed squares as a ruler (as triangulate says it): synth's patches stretch with its hands.
        ruler, stretched = q.pitch_check(markers, pattern.pitch)
        summary[f"{key}_patch_square_mm"] = ruler.get("patch square (mm)")
        found += stretched
        write_markers(q.attach(markers, found), folder / "triangulated.c3d")
        layout = load_layout(config.layout)
        # Four frames a second: a finger moves too far between frames to interpolate over a gap, so only the
        # rigid fill (from patch-mates seen in the same frame) fills, over at most 1.5 s.
        cleaned[key], _ = clean_markers(markers, layout, max_linear_frames=0, max_spline_frames=0,
                                        max_rigid_frames=int(1.5 * config.rate))
        write_markers(cleaned[key], folder / "cleaned.c3d")
        warnings += found
        summary.update(_triangulation_figures(key, triangulated, folder / "image_truth.npz"))
        if "cube_cubie_rotation" in capture.truth:  # the cube's moves, as track-object --articulated finds them
            track = _track_turned_cube(markers, folder / "cube_motion.npz")
            summary.update({f"{key}_{k}": v for k, v in _cube_figures(track, capture).items()})
            warnings += list(track.warnings)
        elif capture.object_motion is not None:
            figures, said = _track_held_object(markers, capture.object_motion.name, folder / "object_motion.npz",
                                               folder / "image_truth.npz")
            summary.update({f"{key}_{k}": v for k, v in figures.items()})
            warnings += said
    # Calibrate the markers the images showed; say how many were never found.
    full = load_layout(configs["calibration"].layout)
    calib = cleaned["calibration"]
    seen = set(np.array(calib.names)[np.isfinite(calib.positions).all(axis=-1).any(axis=0)])
    layout = full.subset(seen)
    kept = layout.names
    summary["calibrated_markers"] = f"{len(kept)} of {len(full.names)}"
    if len(kept) < len(full.names):
        warnings.append(f"{len(full.names) - len(kept)} of the layout's {len(full.names)} corners were never "
                        "triangulated in the calibration take; the solve uses the other ones")
    calibrated = calibrate_attachment(cleaned["calibration"], layout)
    attachment = q.attach(calibrated.attachment, q.residual_warnings(calibrated.residuals,
                                                                     names=calibrated.attachment.marker_names,
                                                                     what="calibration MRE"))
    attachment.save(out / "attachment.npz")
    warnings += list(attachment.warnings)
    summary["calibration_mre_mm"] = round(1000 * calibrated.mre, 3)
    motion = solve_hand(cleaned["take"], calibrated.attachment, filter_cutoff=None, progress=progress)
    motion = q.attach(motion, q.motion_warnings(motion))
    write_hand_motion(motion, out / "motion.npz")
    warnings += list(motion.warnings)
    fit = motion.marker_fit - cleaned["take"].select(motion.marker_names).positions
    summary["solve_mre_mm"] = round(1000 * float(np.nanmean(np.linalg.norm(fit, axis=-1))), 3)
    truth = captures["take"].hand_motion
    summary["joint_error_mm"] = round(1000 * float(np.nanmean(np.linalg.norm(motion.joints - truth.joints, axis=-1))),
                                      3)
    summary["warnings"] = list(dict.fromkeys(warnings))
    with atomic_output(out / "summary.json", "w") as fh:
        json.dump(summary, fh, indent=2)
    with atomic_output(out / "summary.txt", "w") as fh:
        fh.write("\n".join(f"{k:34s} {v}" for k, v in summary.items()) + "\n")
    summary["files"] = written_since(out, before)
    return summary


def _detection_figures(key: str, images: int, a: dict, truth_path, seconds: float) -> dict:
    """Named corners of the detector against the image truth: share found, share misnamed, pixel error."""
    truth = np.load(truth_path)
    names = list(truth["marker_names"])
    visible = len(truth["frame"])  # one row per visible corner in each image
    every = truth["all_xy"]  # (T, C, N, 2), hidden corners included
    index = {n: k for k, n in enumerate(names)}
    detected = [str(a["marker_names"][m]) for m in a["marker"]]
    true_xy = np.array([every[f, c, index[n]] if n in index else (np.nan, np.nan)
                        for f, c, n in zip(a["frame"], a["camera"], detected)]).reshape(-1, 2)
    error = np.linalg.norm(a["xy"] - true_xy, axis=1)
    right = error <= 2.0
    return {
        f"{key}_images": images,
        f"{key}_detect_seconds_per_image": round(seconds / max(images, 1), 3),
        f"{key}_visible_corners": visible,
        f"{key}_named_corners": int(len(error)),
        f"{key}_named_right_of_visible_fraction": round(float(right.sum() / max(visible, 1)), 4),
        f"{key}_misnamed_fraction": round(float((~right).sum() / max(len(error), 1)), 4),
        f"{key}_corner_error_median_px": round(float(np.median(error[right])), 3) if right.any() else None,
        f"{key}_read_tags": int(len(a["block_text"])),
        f"{key}_visible_tags": int(len(truth["block_text"])),
    }


def _track_held_object(markers, name: str, out, truth_path) -> tuple[dict, list[str]]:
    """Track the held object from its triangulated patch corners (``NAME:FACE_rRcC``, as ``handcap track-object
    --markers 'NAME:*'``, its shape learnt from the take) into ``out``; the figures: its corners placed by the track
    (pose and learnt shape) against their true positions, mm, and the frames it holds a pose in."""
    names = [n for n in markers.names if n.startswith(f"{name}:")]
    shown = [n for n in names if np.isfinite(markers.select([n]).positions).all(axis=-1).any()]
    if len(shown) < 3:
        return {"object_corners_tracked": len(shown)}, [
            f"the held {name} showed {len(shown)} of its patch corners in the take: too few to track it"]
    track = track_rigid(markers, names, name=name)
    motion = q.attach(track.motion, q.object_warnings(track, threshold=0.005))
    write_object_motion(motion, out)
    truth = np.load(truth_path)
    index = {str(n): k for k, n in enumerate(truth["marker_names"])}
    true = truth["positions"][:, [index[n] for n in motion.marker_names]]  # (T, K, 3)
    placed = motion.transform_points(motion.canonical)  # (T, K, 3), NaN in frames without a pose
    error = 1000 * np.linalg.norm(placed - true, axis=-1)[np.isfinite(motion.translation).all(axis=1)]
    return {"object_corners_tracked": len(motion.marker_names),
            "object_posed_frames": f"{int(np.isfinite(motion.translation).all(axis=1).sum())} of {motion.n_frames}",
            "object_corner_error_median_mm": round(float(np.median(error)), 3) if error.size else None,
            "object_corner_error_max_mm": round(float(error.max()), 3) if error.size else None}, list(motion.warnings)


def _track_turned_cube(markers, out):
    """Track the 2x2x2 cube from its triangulated facelet corners as ``track-object --articulated cube2x2-patches``
    does (its corners never triangulated are missing throughout) into ``out``; the track."""
    cube = load_articulated("cube2x2-patches")
    track = track_cube(markers.positions_of(cube.marker_names), cube, window=smoothing_window(markers.rate),
                       rate=markers.rate)
    motion, extra = cube_motion(track, cube, markers.rate)
    write_object_motion(motion, out, extra)
    return track


def _cube_figures(track, capture) -> dict:
    """The cube's moves as tracked and as turned, and its pose and cubies against the truth (medians over the
    frames with a pose)."""
    motion = capture.object_motion
    pose = homogeneous(Rotation.from_rotvec(motion.rotation).as_matrix(), motion.translation)
    errors = cube_errors(track, pose, capture.truth["cube_cubie_rotation"])
    posed = np.isfinite(errors["rotation_deg"])
    return {"cube_moves": track.moves, "cube_moves_turned": str(capture.truth["cube_moves"]),
            "cube_posed_frames": f"{int(posed.sum())} of {len(posed)}",
            "cube_position_error_median_mm": round(float(np.median(errors["position_mm"][posed])), 3),
            "cube_rotation_error_median_deg": round(float(np.median(errors["rotation_deg"][posed])), 3),
            "cube_cubie_error_median_deg": round(float(np.median(errors["layer_deg"][posed])), 3)}


def _triangulation_figures(key: str, triangulated, truth_path) -> dict:
    """Triangulated corners against the true 3D corners (same names), and the reprojection error."""
    truth = np.load(truth_path)
    index = {n: k for k, n in enumerate(truth["marker_names"])}
    columns = [index.get(n, -1) for n in triangulated.names]
    true = np.where(np.array(columns)[None, :, None] >= 0, truth["positions"][:, columns], np.nan)
    error = np.linalg.norm(triangulated.positions - true, axis=-1) * 1000
    found = np.isfinite(error)
    return {
        f"{key}_triangulated_marker_frames": int(found.sum()),
        f"{key}_triangulation_median_mm": round(float(np.median(error[found])), 3) if found.any() else None,
        f"{key}_triangulation_p95_mm": round(float(np.percentile(error[found], 95)), 3) if found.any() else None,
        f"{key}_reprojection_median_px": round(float(np.nanmedian(triangulated.error_px)), 3)
        if np.isfinite(triangulated.error_px).any() else None,
    }
