"""``handcap demo``: the end-to-end job on built-in data, as a session.

1. Synthesize a DexterCap-style session (dense checkerboard patches, twelve
   cameras at 20 Hz): a calibration take (open hand, slowly turned) and a take
   of a power grasp of a cylinder, same subject (shape, marker placement), with
   the 2D detections of the twelve cameras (2 % of them with a wrong marker id).
2. Write ``session.toml`` naming both takes (kind ``detections``) and run it
   with :func:`handcap.session.process`, the runner of ``handcap process``:
   triangulate (RANSAC over views), clean (largest cluster per patch, spikes,
   rigid and short gap filling), calibrate the marker attachment on the
   calibration take, solve the grasp take and low-pass it at 5 Hz (DexterCap
   Appendix D), measure it (MRE, joint error, MSNR, jerk, penetration of the
   cylinder, diversity and coherence) and write each take's report page.
3. Measure the stages against the ground truth and draw the truth beside the
   solve.

Writes ``calibration/`` and ``take/`` (the synthetic inputs; ``take/`` also the
object's motion and mesh), ``session.toml``, ``results/<take>/`` (each stage's
output and manifest: run the demo again and finished stages are skipped),
``summary.json``/``summary.txt`` and the picture ``hand.png`` into the output
folder; the summary's ``files`` lists every file written.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from handcap.core.files import atomic_output, check_output_folder, file_stamps, written_since
from handcap.hand import OpenHand
from handcap.io import read_hand_motion, read_markers, write_object_motion
from handcap.report import metrics_table
from handcap.session import load_session, process
from handcap.session.runner import summary as session_table
from handcap.solve.motion import observed_markers
from handcap.steps.step import Step
from handcap.synth.objects import make_object
from handcap.synth.render import View, render, save_png
from handcap.synth.scene import SynthConfig, synthesize, write_capture

SESSION = """# handcap demo: two synthetic takes of 2D detections (twelve cameras), run by handcap process.
[session]
name = "demo"
results = "results"

[stages.triangulate]
min_views = {min_views}

[stages.calibrate]
layout = "{layout}"

[stages.solve]
filter_cutoff = 5.0          # Hz (DexterCap Appendix D)

[[takes]]
name = "calibration"
kind = "detections"
detections = "calibration/detections.npz"
cameras = "calibration/cameras.toml"
truth = "calibration/truth.npz"

[[takes]]
name = "take"
kind = "detections"
detections = "take/detections.npz"
cameras = "take/cameras.toml"
calibration_take = "calibration"
truth = "take/truth.npz"
object = "take/object.npz"
object_mesh = "take/object.ply"
"""

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
        Also ``warnings`` (list of str), ``metrics`` (the metrics table as text), ``stages`` (the runner's
        table) and ``files`` (the paths written, :func:`~handcap.core.files.written_since`).
    """
    import trimesh

    out = Path(out)
    before = file_stamps(out)
    calibration = synthesize(CALIBRATION_CONFIG, progress=progress)
    capture = synthesize(DEMO_CONFIG, progress=progress)
    write_capture(calibration, out / "calibration")
    write_capture(capture, out / "take")
    obj = make_object(DEMO_CONFIG.object_kind, seed=DEMO_CONFIG.seed)
    with atomic_output(out / "take" / "object.ply") as fh:
        fh.write(trimesh.Trimesh(obj.vertices, obj.faces, process=False).export(file_type="ply"))
    write_object_motion(capture.object_motion, out / "take" / "object.npz")
    with atomic_output(out / "session.toml", "w") as fh:
        fh.write(SESSION.format(layout=DEMO_CONFIG.layout, min_views=DEMO_CONFIG.min_views))
    session = load_session(out / "session.toml")
    runs = process(session, workers=1)
    summary = summarize(capture)
    summary.update(_stage_figures(capture, session.results / "take", runs))
    motion = read_hand_motion(session.results / "take" / "motion.npz")
    metrics = json.loads((session.results / "take" / "metrics.json").read_text())
    table = metrics_table(metrics)
    summary["warnings"] = list(dict.fromkeys(w for r in runs for w in r.warnings))
    text = "\n".join(f"{k:28s} {v}" for k, v in summary.items() if k != "seen_per_camera_fraction")
    with atomic_output(out / "summary.json", "w") as fh:
        json.dump(summary, fh, indent=2)
    with atomic_output(out / "summary.txt", "w") as fh:
        fh.write(text + "\n")
    save_png(out / "hand.png", picture(capture, motion))
    summary["stages"] = session_table(runs)
    summary["metrics"] = table
    summary["files"] = written_since(out, before)
    return summary


def _stage_figures(capture, folder: Path, runs) -> dict:
    """The take's triangulated and cleaned markers against the truth, and each stage's speed and figures."""
    names = list(capture.truth["names"])
    truth = capture.truth["positions"]
    triangulated, _ = observed_markers(read_markers(folder / "triangulated.c3d"), names)
    cleaned, _ = observed_markers(read_markers(folder / "cleaned.c3d"), names)
    error = np.linalg.norm(triangulated - truth, axis=-1) * 1000
    clean_error = np.linalg.norm(cleaned - truth, axis=-1) * 1000
    quality = np.load(folder / "triangulated.triangulation.npz")
    manifests = {stage: json.loads((folder.parent / take / f"{stage}.manifest.json").read_text())
                 for take, stage in (("take", "triangulate"), ("calibration", "calibrate"), ("take", "solve"))}
    figures = {
        "triangulated_fraction": round(float(np.isfinite(error).mean()), 4),
        "triangulation_median_mm": round(float(np.nanmedian(error)), 3),
        "triangulation_p95_mm": round(float(np.nanpercentile(error, 95)), 3),
        "reprojection_error_px": round(float(np.nanmean(quality["error_px"])), 3),
        "wrong_ids_rejected": round(float((~quality["used"][capture.detections["wrong_id"]]).mean()), 4),
        "cleaned_fraction": round(float(np.isfinite(clean_error).mean()), 4),
        "cleaned_p95_mm": round(float(np.nanpercentile(clean_error, 95)), 3),
        "calibration_mre_mm": manifests["calibrate"]["figures"].get("mre_mm"),
        "calibration_seconds": manifests["calibrate"]["seconds"],
        "solve_seconds": manifests["solve"]["seconds"],
        "triangulation_seconds": manifests["triangulate"]["seconds"],
    }
    figures["stages_run"] = sum(r.status == "done" for r in runs)
    figures["stages_up_to_date"] = sum(r.status == "skipped" for r in runs)
    return figures


def demo(out="demo-output") -> Step:
    """Run :func:`run_demo` into ``out`` (rewritten on every run) and summarise it.

    Parameters
    ----------
    out : str or Path
    """
    check_output_folder(out, force=True)  # demo-output/ is rewritten on every run
    summary = run_demo(out)
    lines = [f"{key:28s} {value}" for key, value in summary.items()
             if key not in ("files", "seen_per_camera_fraction", "metrics", "warnings", "stages")]
    warnings = tuple(summary["warnings"])
    files = [Path(f) for f in summary["files"]]
    lines += ["\nthe session's stages (handcap process " + f"{out}/session.toml):", summary["stages"],
              "\nsolved motion against the ground truth:", summary["metrics"],
              f"\nwrote {len(files)} files to {out}/ (picture of the truth beside the solve: {out}/hand.png; "
              f"the take's report: {out}/results/take/report.html); "
              + (f"{len(warnings)} warning(s), see below" if warnings else "no warnings")]
    lines += [f"  {path.relative_to(out) if path.is_relative_to(out) else path}" for path in files]
    return Step(tuple(lines), warnings, tuple(map(str, files)), summary)
