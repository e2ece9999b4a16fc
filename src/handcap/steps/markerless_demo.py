"""``handcap demo --markerless``: a grasp captured from one video's keypoints, with its truth.

1. Synthesize a video of a steady precision grasp of a box (the hand held still, turned in front of one
   camera, :func:`handcap.markerless.synthetic.grasp_object_video`): the keypoints a detector would give
   (3 px noise, 10 % missing, 2 % wrong, each keypoint 2 mm off its joint), the box's mesh, its contact
   map, a depth camera's view of it in the first frame and a start for its pose 5 degrees and 5 mm off
   (as a turntable scan would give before the grasp settles).
2. Run ``handcap markerless`` on those files, as a user would: structure from motion, the hand fitted
   (eq. 2), the box's pose by ICP carried to every frame by the virtual cameras, the grasp refined with
   the contact map.
3. Measure it against the truth: keypoints after a similarity alignment (mm), joint angles (degrees),
   the box's pose (mm of its surface), and the hand against the true box before and after the
   refinement (contact distance, deepest penetration).

Writes into the output folder (rewritten on every run): ``keypoints.npz``, ``camera.toml``, ``box.ply``,
``contact.npz``, ``box_points.npz``, ``box_pose_start.txt`` (the inputs), ``motion.npz`` and
``motion-object.npz`` (the results), ``truth.npz``, ``summary.json`` and ``summary.txt``; with the
command line that repeats step 2.
"""

from __future__ import annotations

import json
import warnings
from pathlib import Path

import numpy as np
import trimesh
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation

from handcap.core.camera_rig import CameraRig
from handcap.core.errors import HandcapWarning
from handcap.core.files import atomic_output, file_stamps, save_npz, written_since
from handcap.core.transforms import homogeneous
from handcap.io import read_hand_motion, read_object_motion, write_rig
from handcap.markerless.contact import contact_figures
from handcap.markerless.keypoints import hand_names
from handcap.markerless.synthetic import grasp_object_video
from handcap.multiview.detections import Detections, write_detections
from handcap.steps.markerless import markerless

FRAMES, SEED = 150, 1


def _pa_error(a, b) -> float:
    """Mean distance of points a to b after the best similarity (no mirror), metres."""
    a0, b0 = a - a.mean(0), b - b.mean(0)
    u, s, vt = np.linalg.svd(b0.T @ a0)
    d = np.diag([1.0, 1.0, np.sign(np.linalg.det(u @ vt))])
    scale = (s * np.diag(d)).sum() / (a0 ** 2).sum()
    return float(np.linalg.norm(scale * a0 @ (u @ d @ vt).T - b0, axis=1).mean())


def run_markerless_demo(out="demo-markerless", *, frames: int = FRAMES, seed: int = SEED) -> dict:
    """Run the demo into ``out`` (see the module docstring); returns its summary.

    It sits among the steps because it runs one (``markerless``) on the files it writes, as a user would.

    Parameters
    ----------
    out : str or Path
        The folder to write into (created; files of the same names are replaced).
    frames : int
        Frames of the video.
    seed : int
        Seeds the synthetic grasp.

    Returns
    -------
    dict
        The figures (see the module docstring), ``command``, ``warnings`` and ``files`` (those written).
    """
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    before_files = file_stamps(out)
    rng = np.random.default_rng(seed)
    g = grasp_object_video("precision", "cuboid", frames, rng, noise_px=3.0, missing=0.1, wrong=0.02)
    video, cm = g.video, g.contact_map
    t, k = np.nonzero(np.isfinite(video.pixels[..., 0]))
    write_detections(Detections(("video",), hand_names("right"), t, np.zeros_like(t), k, video.pixels[t, k],
                                np.ones(len(t)), 30.0, frames, "demo keypoints"), out / "keypoints.npz")
    write_rig(CameraRig([video.camera]), out / "camera.toml")
    with atomic_output(out / "box.ply", mode=None) as tmp:
        trimesh.Trimesh(cm.vertices, cm.faces, process=False).export(tmp, file_type="ply")
    cm.save(out / "contact.npz")
    save_npz(out / "box_points.npz", {"points": g.points})
    start = g.object_poses[0].copy()
    axis = rng.normal(size=3)
    start[:3, :3] = Rotation.from_rotvec(axis / np.linalg.norm(axis) * np.deg2rad(5.0)).as_matrix() @ start[:3, :3]
    start[:3, 3] += rng.normal(0.0, 0.005 / np.sqrt(3), 3)
    with atomic_output(out / "box_pose_start.txt", mode="w") as f:
        np.savetxt(f, start, header="object to camera in frame 0 (metres): a start, 5 degrees and 5 mm off")
    save_npz(out / "truth.npz", {"keypoints": video.points, "phi": video.phi, "object_poses": g.object_poses,
                                 "hand_rotation": video.rotation, "hand_translation": video.translation})
    command = (f"handcap markerless {out}/keypoints.npz --intrinsics {out}/camera.toml --object {out}/box.ply "
               f"--object-points {out}/box_points.npz --object-pose {out}/box_pose_start.txt "
               f"--contact {out}/contact.npz --out {out}/motion.npz")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", HandcapWarning)
        step = markerless(out / "keypoints.npz", out / "motion.npz", intrinsics=str(out / "camera.toml"),
                          obj=out / "box.ply", object_pose=out / "box_pose_start.txt",
                          object_points=out / "box_points.npz", contact=out / "contact.npz")
    result = step.result
    motion, obj = read_hand_motion(out / "motion.npz"), read_object_motion(out / "motion-object.npz")
    est = homogeneous(Rotation.from_rotvec(obj.rotation).as_matrix(), obj.translation)
    surface = [cKDTree(cm.vertices @ g.object_poses[f, :3, :3].T + g.object_poses[f, :3, 3]).query(
        cm.vertices @ est[f, :3, :3].T + est[f, :3, 3])[0].mean() for f in range(frames)]

    def against_truth(m):
        v = g.hand.forward(m.betas, m.global_orient[0], m.hand_pose[0], m.transl[0]).vertices
        return contact_figures((v - est[0, :3, 3]) @ est[0, :3, :3], g.hand.faces, cm, g.obj.signed_distance)

    before, after = against_truth(result.before), against_truth(motion)
    summary = {
        "frames": frames,
        "keypoint_error_pa_mm": round(1000 * _pa_error(result.video.structure.points, video.points), 2),
        "joint_angle_error_deg": round(float(np.degrees(np.abs(motion.phi[0] - video.phi)).mean()), 2),
        "reprojection_median_px": round(float(np.nanmedian(result.video.structure.residual_px)), 2),
        "object_points_to_surface_mm": round(float(result.figures["icp_mm"]), 2),
        "object_surface_error_mm": round(1000 * float(np.mean(surface)), 2),
        "contact_distance_mm_before_after": [round(before["contact_mm"], 2), round(after["contact_mm"], 2)],
        "deepest_penetration_mm_before_after": [round(before["penetration_max_mm"], 2),
                                                round(after["penetration_max_mm"], 2)],
        "command": command,
        "warnings": sorted({str(w.message) for w in caught}),
    }
    text = "\n".join(f"{key:38s} {value}" for key, value in summary.items() if key != "warnings")
    with atomic_output(out / "summary.txt", mode="w") as f:
        f.write(text + "\n")
    with atomic_output(out / "summary.json", mode="w") as f:
        json.dump(summary, f, indent=1)
    summary["files"] = written_since(out, before_files)
    return summary
