"""``handcap demo``: the end-to-end job on built-in data.

1. Synthesize a DexterCap-style session (dense checkerboard patches, twelve
   cameras at 20 Hz): a calibration take (open hand, slowly turned) and a take
   of a power grasp of a cylinder, same subject (shape, marker placement).
2. Triangulate both takes from the 2D detections of the twelve cameras (2 % of
   them with a wrong marker id; RANSAC over views), then clean them (largest
   cluster per patch, spikes, rigid and short gap filling).
3. Calibrate the marker attachment on the cleaned calibration take.
4. Solve the cleaned grasp take, low-pass it at 5 Hz (DexterCap Appendix D).
5. Measure it against the ground truth: MRE, joint error, MSNR, jerk,
   penetration of the cylinder, diversity and coherence.

Writes the capture folder, ``attachment.npz``, ``motion.npz``,
``metrics.json``/``metrics.txt``, ``summary.json``/``summary.txt`` and a
picture ``hand.png`` (the truth and, beside it, the solved hand) into the
output folder; the summary's ``files`` lists every file written.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from handcap.core.files import atomic_output
from handcap.hand import OpenHand
from handcap.io import write_hand_motion, write_markers, write_object_motion
from handcap.layouts import load_layout
from handcap.multiview import clean_markers, read_detections, triangulate_detections, write_quality
from handcap.quality import plausibility as q
from handcap.report import metrics_table, motion_metrics
from handcap.solve import calibrate_attachment, solve_hand
from handcap.synth.objects import make_object
from handcap.synth.render import View, render, save_png
from handcap.synth.scene import SynthConfig, synthesize, write_capture

DEMO_CONFIG = SynthConfig(layout="dense-patches", motion="grasp", frames=120, rate=20.0, seed=7, min_views=3,
                          subject_seed=21, noise_mm=0.5, outlier_rate=0.02)
CALIBRATION_CONFIG = SynthConfig(layout="dense-patches", motion="calibration", frames=100, rate=20.0, seed=8,
                                 min_views=3, subject_seed=21, noise_mm=0.5, outlier_rate=0.02)


def summarize(capture) -> dict:
    """Frames, markers, visibility and gap statistics of a synthetic capture."""
    markers = capture.markers
    names = list(capture.truth["names"])
    labeled = markers.select(names)
    visible = capture.truth["visible"]
    n_hand = len(capture.hand_motion.marker_names)
    gaps = labeled.gap_summary()
    per_camera = capture.truth["camera_visible"].mean(axis=(0, 2))
    return {
        "frames": markers.n_frames,
        "rate_hz": markers.rate,
        "duration_s": round(markers.duration, 3),
        "layout": capture.config.layout,
        "motion": capture.config.motion,
        "object": capture.config.object_kind or "none",
        "hand_markers": n_hand,
        "object_markers": len(names) - n_hand,
        "ghost_trajectories": markers.n_markers - len(names),
        "cameras": len(capture.rig),
        "min_views": capture.config.min_views,
        "reconstructed_fraction": round(float(visible.mean()), 4),
        "hand_reconstructed_fraction": round(float(visible[:, :n_hand].mean()), 4),
        "seen_per_camera_fraction": [round(float(v), 4) for v in per_camera],
        "missing_fraction": round(gaps["missing_fraction"], 4),
        "gaps": gaps["gaps"],
        "mean_gap_frames": round(gaps["mean_gap_frames"], 2),
        "max_gap_frames": gaps["max_gap_frames"],
        "mean_segment_frames": round(gaps["mean_segment_frames"], 2),
        "label_swaps": int(len(capture.truth["swaps"])),
        "detections_2d": int(len(capture.detections["frame"])),
    }


def picture(capture, motion=None, frame: int | None = None) -> np.ndarray:
    """RGB image of the truth and, beside it, the solved hand, in the same frame from the same view.

    Left, "truth": the synthetic hand and object with the true marker positions (green: reconstructed,
    red: lost). Right, "solved" (when ``motion`` is given): the hand of the solved motion with its
    fitted markers (blue) and the object, titled with that frame's mean joint error against the truth.

    Parameters
    ----------
    capture : SynthCapture
    motion : HandMotion, optional
        The solved motion of the same take (OpenHand).
    frame : int, optional
        Default: the middle of the grasp (or of the take).

    Returns
    -------
    image : ndarray of uint8, shape (720, 960, 3), or (720, 1920, 3) with ``motion``
    """
    import cv2
    from scipy.spatial.transform import Rotation

    truth_motion = capture.hand_motion
    holding = capture.object_motion.state["holding"] if capture.object_motion is not None else None
    if frame is None:
        frame = int(np.flatnonzero(holding)[len(np.flatnonzero(holding)) // 2]) if holding is not None \
            and holding.any() else truth_motion.n_frames // 2
    hand = OpenHand(truth_motion.side)
    out = hand.forward(truth_motion.betas, truth_motion.global_orient[frame], truth_motion.hand_pose[frame],
                       truth_motion.transl[frame])
    objects = []
    if capture.object_motion is not None:
        obj = make_object(capture.config.object_kind, seed=capture.config.seed)
        rot = Rotation.from_rotvec(capture.object_motion.rotation[frame]).as_matrix()
        objects.append((obj.vertices @ rot.T + capture.object_motion.translation[frame], obj.faces, (110, 150, 220)))
    truth = capture.truth["positions"][frame]
    seen = capture.truth["visible"][frame]
    centre = out.vertices.mean(axis=0)
    # Look from the camera that sees the most markers in this frame.
    camera = capture.rig[int(np.argmax(capture.truth["camera_visible"][frame].sum(axis=1)))]
    eye = centre + (camera.center - centre) / np.linalg.norm(camera.center - centre) * 0.42
    view = View.looking_at(centre, eye, up=(0.0, 0.0, 1.0), size=(960, 720), fov_deg=36)
    points = [(truth[seen], (40, 200, 60), 3), (truth[~seen], (230, 40, 40), 3)]
    panels = [(render(view, [(out.vertices, hand.faces, (232, 190, 160))] + objects, points), "truth")]
    if motion is not None:
        solved = OpenHand(motion.side).forward(motion.betas, motion.global_orient[frame], motion.hand_pose[frame],
                                               motion.transl[frame])
        title = "solved"
        if motion.joints is not None and truth_motion.joints is not None:
            error = np.linalg.norm(motion.joints[frame] - truth_motion.joints[frame], axis=-1).mean()
            title += f", joint error {1000 * error:.1f} mm"
        fitted = [(motion.marker_fit[frame], (50, 110, 230), 3)] if motion.marker_fit is not None else []
        panels.append((render(view, [(solved.vertices, hand.faces, (200, 200, 215))] + objects, fitted), title))
    images = []
    for image, title in panels:
        image = np.ascontiguousarray(image)
        cv2.putText(image, f"{title} (frame {frame})", (20, 40), cv2.FONT_HERSHEY_SIMPLEX, 1.0, (20, 20, 20), 2,
                    cv2.LINE_AA)
        images.append(image)
    return np.concatenate(images, axis=1)


def run_demo(out="demo-output", *, progress: bool | None = None) -> dict:
    """Run the demo into ``out`` (see the module docstring); returns the summary with the metrics.

    Parameters
    ----------
    out : str or Path
        Output folder; created if needed, files already there are written over.
    progress : bool, optional
        Show progress bars (default: only on a terminal).

    Returns
    -------
    dict
        The capture summary (:func:`summarize`) and the stage results; each key names its unit
        (``_mm`` millimetres, ``_px`` pixels, ``_seconds`` seconds, ``_fraction`` a share from 0 to 1).
        Also ``warnings`` (list of str), ``metrics`` (the metrics table as text) and ``files``
        (the paths written, :func:`written_since`).
    """
    import time

    out = Path(out)
    before = file_stamps(out)
    calibration = synthesize(CALIBRATION_CONFIG, progress=progress)
    capture = synthesize(DEMO_CONFIG, progress=progress)
    paths = write_capture(capture, out)
    write_capture(calibration, out / "calibration")
    summary = summarize(capture)
    warnings = []  # every stage's plausibility warnings, stored in its file and listed in the summary

    layout = load_layout(DEMO_CONFIG.layout)
    cleaned = {}
    for key, take, folder in (("calibration", calibration, out / "calibration"), ("take", capture, out)):
        start = time.perf_counter()
        triangulated = triangulate_detections(read_detections(folder / "detections.npz"), take.rig,
                                              progress=progress)
        seconds = time.perf_counter() - start
        found = q.triangulation_warnings(triangulated.error_px, triangulated.views, threshold_px=5.0,
                                         used=triangulated.used)
        write_markers(q.attach(triangulated.to_markers(), found), folder / "triangulated.c3d")
        write_quality(triangulated, folder / "triangulated.c3d")
        cleaned[key], report = clean_markers(triangulated.to_markers(), layout)
        cleaned[key] = q.attach(cleaned[key], q.marker_warnings(cleaned[key], hand=layout.names))
        write_markers(cleaned[key], folder / "cleaned.c3d")
        warnings += found + list(cleaned[key].warnings)
        if key == "take":
            truth = take.truth["positions"]
            error = np.linalg.norm(triangulated.positions - truth, axis=-1) * 1000
            clean_error = np.linalg.norm(cleaned[key].positions - truth, axis=-1) * 1000
            summary.update({
                "triangulated_fraction": round(float(np.isfinite(error).mean()), 4),
                "triangulation_median_mm": round(float(np.nanmedian(error)), 3),
                "triangulation_p95_mm": round(float(np.nanpercentile(error, 95)), 3),
                "reprojection_error_px": round(float(np.nanmean(triangulated.error_px)), 3),
                "wrong_ids_rejected": round(float((~triangulated.used[take.detections["wrong_id"]]).mean()), 4),
                "triangulation_marker_frames_per_s": round(error.size / seconds),
                "cleaned_fraction": round(float(np.isfinite(clean_error).mean()), 4),
                "cleaned_p95_mm": round(float(np.nanpercentile(clean_error, 95)), 3),
                "cleaning": report.counts(),
            })

    start = time.perf_counter()
    calibrated = calibrate_attachment(cleaned["calibration"], layout)
    found = q.residual_warnings(calibrated.residuals, names=calibrated.attachment.marker_names,
                                what="calibration MRE") + q.shape_warnings(calibrated.attachment.betas)
    attachment = q.attach(calibrated.attachment, found)
    attachment.save(out / "attachment.npz")
    warnings += list(attachment.warnings)
    summary["calibration_seconds"] = round(time.perf_counter() - start, 2)
    summary["calibration_mre_mm"] = round(1000 * calibrated.mre, 3)
    start = time.perf_counter()
    motion = solve_hand(cleaned["take"], calibrated.attachment, filter_cutoff=5.0, progress=progress)
    seconds = time.perf_counter() - start
    summary["solve_frames_per_second"] = round(motion.n_frames / seconds, 1)
    motion = q.attach(motion, q.motion_warnings(motion))
    write_hand_motion(motion, out / "motion.npz")
    warnings += list(motion.warnings)

    mesh_path = out / "object.ply"
    obj = make_object(DEMO_CONFIG.object_kind, seed=DEMO_CONFIG.seed)
    import trimesh
    with atomic_output(mesh_path) as fh:
        fh.write(trimesh.Trimesh(obj.vertices, obj.faces, process=False).export(file_type="ply"))
    write_object_motion(capture.object_motion, out / "object.npz")
    metrics = motion_metrics(out / "motion.npz", truth=paths["truth.npz"], markers=out / "cleaned.c3d",
                             obj=out / "object.npz", object_mesh=mesh_path)
    with atomic_output(out / "metrics.json", "w") as fh:
        json.dump(metrics, fh, indent=2)
    table = metrics_table(metrics)
    with atomic_output(out / "metrics.txt", "w") as fh:
        fh.write(table + "\n")

    summary["warnings"] = list(dict.fromkeys(warnings))
    text = "\n".join(f"{k:28s} {v}" for k, v in summary.items() if k != "seen_per_camera_fraction")
    with atomic_output(out / "summary.json", "w") as fh:
        json.dump(summary, fh, indent=2)
    with atomic_output(out / "summary.txt", "w") as fh:
        fh.write(text + "\n")
    save_png(out / "hand.png", picture(capture, motion))
    summary["metrics"] = table
    summary["files"] = written_since(out, before)
    return summary


def file_stamps(folder) -> dict:
    """Path -> (inode, modification time in ns) of every file under ``folder`` (empty if it does not exist)."""
    folder = Path(folder)
    if not folder.is_dir():
        return {}
    return {p: (p.stat().st_ino, p.stat().st_mtime_ns) for p in folder.rglob("*") if p.is_file()}


def written_since(folder, before: dict) -> list[str]:
    """Files under ``folder`` that are new or rewritten since ``before`` (:func:`file_stamps`), sorted.

    Every handcap write renames a new file into place, so a rewritten file has a new inode or time.

    Parameters
    ----------
    folder : str or Path
        Folder searched recursively.
    before : dict
        Earlier :func:`file_stamps` of the same folder.

    Returns
    -------
    list of str
        Paths, sorted.
    """
    return sorted(str(p) for p, stamp in file_stamps(folder).items() if before.get(p) != stamp)
