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
picture ``hand.png`` into the output folder.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

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


def picture(capture, frame: int | None = None) -> np.ndarray:
    """RGB image of the hand, the object and the markers (green: reconstructed, red: lost)."""
    from scipy.spatial.transform import Rotation

    from handcap.hand import OpenHand
    from handcap.synth.objects import make_object
    from handcap.synth.render import View, render

    motion = capture.hand_motion
    holding = capture.object_motion.state["holding"] if capture.object_motion is not None else None
    if frame is None:
        frame = int(np.flatnonzero(holding)[len(np.flatnonzero(holding)) // 2]) if holding is not None \
            and holding.any() else motion.n_frames // 2
    hand = OpenHand(motion.side)
    out = hand.forward(motion.betas, motion.global_orient[frame], motion.hand_pose[frame], motion.transl[frame])
    meshes = [(out.vertices, hand.faces, (232, 190, 160))]
    if capture.object_motion is not None:
        obj = make_object(capture.config.object_kind, seed=capture.config.seed)
        rot = Rotation.from_rotvec(capture.object_motion.rotation[frame]).as_matrix()
        meshes.append((obj.vertices @ rot.T + capture.object_motion.translation[frame], obj.faces, (110, 150, 220)))
    truth = capture.truth["positions"][frame]
    seen = capture.truth["visible"][frame]
    centre = out.vertices.mean(axis=0)
    # Look from the camera that sees the most markers in this frame.
    camera = capture.rig[int(np.argmax(capture.truth["camera_visible"][frame].sum(axis=1)))]
    eye = centre + (camera.center - centre) / np.linalg.norm(camera.center - centre) * 0.42
    view = View.looking_at(centre, eye, up=(0.0, 0.0, 1.0), size=(960, 720), fov_deg=36)
    points = [(truth[seen], (40, 200, 60), 3), (truth[~seen], (230, 40, 40), 3)]
    return render(view, meshes, points)


def run_demo(out="demo-output", *, progress: bool | None = None) -> dict:
    """Run the demo into ``out`` (see the module docstring); returns the summary with the metrics."""
    import time

    from handcap.io import write_hand_motion, write_markers
    from handcap.io._files import atomic_output
    from handcap.layouts import load_layout
    from handcap.multiview import clean_markers, read_detections, triangulate_detections, write_quality
    from handcap.quality.report import metrics_table, motion_metrics
    from handcap.solve import calibrate_attachment, solve_hand
    from handcap.synth.objects import make_object
    from handcap.synth.render import save_png

    out = Path(out)
    calibration = synthesize(CALIBRATION_CONFIG, progress=progress)
    capture = synthesize(DEMO_CONFIG, progress=progress)
    paths = write_capture(capture, out)
    write_capture(calibration, out / "calibration")
    summary = summarize(capture)

    layout = load_layout(DEMO_CONFIG.layout)
    cleaned = {}
    for key, take, folder in (("calibration", calibration, out / "calibration"), ("take", capture, out)):
        start = time.perf_counter()
        triangulated = triangulate_detections(read_detections(folder / "detections.npz"), take.rig,
                                              progress=progress)
        seconds = time.perf_counter() - start
        write_markers(triangulated.to_markers(), folder / "triangulated.c3d")
        write_quality(triangulated, folder / "triangulated.c3d")
        cleaned[key], report = clean_markers(triangulated.to_markers(), layout)
        write_markers(cleaned[key], folder / "cleaned.c3d")
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
                "cleaning": report.summary(),
            })

    start = time.perf_counter()
    calibrated = calibrate_attachment(cleaned["calibration"], layout)
    calibrated.attachment.save(out / "attachment.npz")
    summary["calibration_seconds"] = round(time.perf_counter() - start, 2)
    summary["calibration_mre_mm"] = round(1000 * calibrated.mre, 3)
    start = time.perf_counter()
    motion = solve_hand(cleaned["take"], calibrated.attachment, filter_cutoff=5.0, progress=progress)
    seconds = time.perf_counter() - start
    summary["solve_frames_per_second"] = round(motion.n_frames / seconds, 1)
    write_hand_motion(motion, out / "motion.npz")

    mesh_path = out / "object.ply"
    obj = make_object(DEMO_CONFIG.object_kind, seed=DEMO_CONFIG.seed)
    import trimesh
    with atomic_output(mesh_path) as fh:
        fh.write(trimesh.Trimesh(obj.vertices, obj.faces, process=False).export(file_type="ply"))
    from handcap.io import write_object_motion
    write_object_motion(capture.object_motion, out / "object.npz")
    metrics = motion_metrics(out / "motion.npz", truth=paths["truth.npz"], markers=out / "cleaned.c3d",
                             obj=out / "object.npz", object_mesh=mesh_path)
    with atomic_output(out / "metrics.json", "w") as fh:
        json.dump(metrics, fh, indent=2)
    table = metrics_table(metrics)
    with atomic_output(out / "metrics.txt", "w") as fh:
        fh.write(table + "\n")

    text = "\n".join(f"{k:28s} {v}" for k, v in summary.items() if k != "seen_per_camera_fraction")
    with atomic_output(out / "summary.json", "w") as fh:
        json.dump(summary, fh, indent=2)
    with atomic_output(out / "summary.txt", "w") as fh:
        fh.write(text + "\n")
    save_png(out / "hand.png", picture(capture))
    summary["metrics"] = table
    summary["files"] = sorted(str(p) for p in list(paths.values()) + [out / "triangulated.c3d", out / "cleaned.c3d",
                                                                      out / "attachment.npz", out / "motion.npz",
                                                                      out / "metrics.json", out / "hand.png"])
    return summary
