"""Metrics of a solved take from its files, as a table (``handcap metrics``)."""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from handcap.core.errors import HandcapError
from handcap.core.files import existing_file, load_npz
from handcap.core.geometry import check_mesh, signed_distance
from handcap.core.rotations import matrix_from_axis_angle
from handcap.hand import OpenHand
from handcap.hand.attachment import MarkerAttachment
from handcap.io import read_hand_motion, read_markers, read_mesh, read_object_motion
from handcap.objects.cube import cube_signed_distance
from handcap.quality import metrics as q
from handcap.solve.leave_one_out import leave_one_marker_out
from handcap.solve.motion import observed_markers

#: Pose clusters of the diversity and coherence figures (the paper's k-means); a take of no more frames has neither.
CLUSTERS = 5


def motion_metrics(motion_path, *, truth=None, markers=None, obj=None, object_mesh=None, attachment=None,
                   leave_one_out: bool = False, hand=None) -> dict:
    """Every metric that the given files allow, as plain numbers (millimetres, m/s^3, dB).

    Parameters
    ----------
    motion_path : path
        Hand motion ``.npz`` (from ``handcap solve``).
    truth : path, optional
        ``truth.npz`` of a synthetic capture (or any hand motion with joints):
        joint position error.
    markers : path, optional
        The labeled markers the motion was solved from: MRE against them.
    obj, object_mesh : paths, optional
        Object motion ``.npz`` and the object's mesh in its own frame: penetration. A 2x2x2 cube's track
        (``track-object --articulated cube2x2``) needs no mesh: the penetration is into its cubies where
        they are, and its moves, MSNR and jerk are added (``cube_*``).
    attachment : path, optional
        Needed with ``leave_one_out`` (re-solves the take once per marker).
    hand : HandModel, optional
        The model the motion was solved with (for the mesh and ``leave_one_out``);
        OpenHand of the motion's side by default, which only an ``openhand`` motion accepts.
    """
    motion = read_hand_motion(motion_path)
    if motion.joints is None:
        raise HandcapError(f"{motion_path}: has no joints; solve it with handcap solve")
    if object_mesh is not None:
        existing_file(object_mesh)  # before any work: a missing mesh is one line, not a traceback at the end
    out = {"frames": motion.n_frames, "rate_hz": motion.rate}
    if motion.marker_residuals is not None:
        s = q.Stat.of(motion.marker_residuals)
        out["mre_mm"] = [1000 * s.mean, 1000 * s.std]
    if markers is not None:
        observed, _ = observed_markers(read_markers(markers), list(motion.marker_names))
        s = q.marker_reconstruction_error(motion.marker_fit, observed)
        out["mre_mm"] = [1000 * s.mean, 1000 * s.std]
    if truth is not None:
        true = read_hand_motion(truth)
        if true.joints is None or true.n_frames != motion.n_frames:
            raise HandcapError(f"{truth}: needs joints for the same {motion.n_frames} frames")
        s = q.joint_position_error(motion.joints, true.joints)
        out["joint_error_mm"] = [1000 * s.mean, 1000 * s.std]
        per_joint = np.linalg.norm(motion.joints - true.joints, axis=-1).mean(axis=0)
        out["joint_error_per_joint_mm"] = [round(1000 * float(v), 3) for v in per_joint]
    if motion.n_frames >= 4:  # else too short a take for a third difference: smoothness left out, as diversity
        out["msnr_db"] = q.msnr(motion.joints)
        s = q.jerk(motion.joints, motion.rate)
        out["jerk_m_s3"] = [s.mean, s.std]
    object_motion = read_object_motion(obj) if obj is not None else None
    if object_motion is not None and object_motion.n_frames != motion.n_frames:
        raise HandcapError(f"{obj}: the object moves for {object_motion.n_frames} frames, the hand motion "
                           f"{motion_path} for {motion.n_frames}; give the object motion of the same take")
    features = q.pose_features(motion.joints, None if object_motion is None else object_motion.translation)
    if np.isfinite(features).all(axis=1).sum() > CLUSTERS:  # else too short a take for k-means: left out
        out["diversity"], out["coherence"] = q.diversity_coherence(features, k=CLUSTERS)
    if obj is not None:
        cube = _cube_figures(obj, object_motion)
        out.update(cube)
        if truth is not None and not cube:
            out.update(_object_error(object_motion, truth))
        if cube and object_mesh is None:  # the cube's own geometry: its cubies where they are
            hand = _hand_for(motion, hand)
            verts = hand.forward(motion.betas, motion.global_orient, motion.hand_pose, motion.transl).vertices
            pose = np.tile(np.eye(4), (object_motion.n_frames, 1, 1))
            pose[:, :3, :3] = Rotation.from_rotvec(np.nan_to_num(object_motion.rotation)).as_matrix()
            pose[:, :3, 3] = object_motion.translation
            depth = -cube_signed_distance(verts, pose, load_npz(obj)["cubie_rotation"]).min(axis=1)
            s = q.Stat.of(depth[depth > 0])
            out["penetration_mm"] = [1000 * s.mean, 1000 * s.std, s.count]
    if object_motion is not None and object_mesh is not None:
        mesh = read_mesh(object_mesh)
        if len(getattr(mesh, "faces", ())) == 0:
            raise HandcapError(f"{object_mesh}: holds no mesh faces; give the object's surface mesh")
        try:
            check_mesh(mesh.vertices, mesh.faces)
        except HandcapError as err:
            raise HandcapError(f"{object_mesh}: {err}") from None
        out["warnings"] = _mesh_unit_warnings(object_motion, mesh, object_mesh)
        out["warnings"] += _mesh_frame_warnings(object_motion, mesh, object_mesh)
        hand = _hand_for(motion, hand)
        verts = hand.forward(motion.betas, motion.global_orient, motion.hand_pose, motion.transl).vertices
        # The hand in the object's frame, so the object's mesh is one for all frames (see q.penetration);
        # NaN in the frames where the object was lost, which are then left out as before.
        turn = matrix_from_axis_angle(object_motion.rotation)
        local = np.einsum("tji,tvj->tvi", turn, verts - object_motion.translation[:, None])
        s = q.penetration(local, np.asarray(mesh.vertices), np.asarray(mesh.faces))
        out["penetration_mm"] = [1000 * s.mean, 1000 * s.std, s.count]
    if leave_one_out:
        if attachment is None or markers is None:
            raise HandcapError("--leave-one-out needs --markers and --attachment")
        loo = leave_one_marker_out(read_markers(markers), MarkerAttachment.load(attachment), _hand_for(motion, hand))
        out["leave_one_out_mm"] = {k: 1000 * v.mean for k, v in loo.items()}
    return out


def _cube_figures(path, object_motion) -> dict:
    """A 2x2x2 cube's moves and the smoothness of its markers' motion (relative to its centre, so that the
    layers' turns count and the hand's carrying does not), when ``path`` is a cube track
    (``track-object --articulated cube2x2``); else nothing."""
    data = load_npz(path)
    if "cubie_rotation" not in data or "cubie_of_marker" not in data:
        return {}
    rotation = data["cubie_rotation"]
    cubie = data["cubie_of_marker"].astype(int)
    if rotation.shape != (object_motion.n_frames, 8, 3, 3) or cubie.shape != (len(object_motion.canonical),):
        raise HandcapError(f"{path}: its cubie_rotation or cubie_of_marker does not match its frames and markers")
    turned = Rotation.from_rotvec(np.nan_to_num(object_motion.rotation)).as_matrix()
    local = np.einsum("tmij,mj->tmi", rotation[:, cubie], object_motion.canonical)  # cube frame, per frame
    centre = object_motion.translation[:, None]
    world = np.einsum("tij,tmj->tmi", turned, local) + centre
    world = np.concatenate([centre, world], axis=1)[np.isfinite(object_motion.translation).all(axis=1)]
    if len(world) < 4:
        return {"cube_moves": str(data.get("moves", ""))}
    s = q.jerk(world[:, 1:], object_motion.rate)
    return {"cube_moves": str(data.get("moves", "")), "cube_msnr_db": q.msnr(world),
            "cube_jerk_m_s3": [s.mean, s.std]}


#: Furthest an object's marker may lie from the surface of its mesh (metres): markers sit on it (a sphere on its
#: base, a printed corner), so further means the motion's object frame is not the mesh's.
MESH_MARKER_LIMIT = 0.015


#: Units a mesh file may be in (metres per file unit), tried when its size is far from its markers' spread.
MESH_UNITS = {"m": 1.0, "cm": 0.01, "mm": 0.001}


def _mesh_unit_warnings(object_motion, mesh, path) -> list[str]:
    """Scale ``mesh`` (in place) to metres when its file is plainly in centimetres or millimetres, as CAD exports
    often are: its size more than 20 times off its markers' spread, and within 5 times of it once converted. The
    markers sit on the object, so the two sizes agree in the right unit."""
    spread = float(np.ptp(np.asarray(object_motion.canonical, dtype=np.float64), axis=0).max(initial=0.0))
    size = float(np.max(mesh.extents)) if len(mesh.vertices) else 0.0
    if spread <= 0 or size <= 0 or abs(np.log(size / spread)) <= np.log(20):
        return []
    unit = min(MESH_UNITS, key=lambda u: abs(np.log(size * MESH_UNITS[u] / spread)))
    if unit == "m" or abs(np.log(size * MESH_UNITS[unit] / spread)) > np.log(5):
        return []
    mesh.vertices = np.asarray(mesh.vertices, dtype=np.float64) * MESH_UNITS[unit]
    return [f"{path}: read in {unit} (it spans {size:g} units, its object's markers {1000 * spread:.0f} mm): "
            f"converted to metres; save meshes in metres"]


def _mesh_frame_warnings(object_motion, mesh, path) -> list[str]:
    """A warning when the object's markers (its ``canonical``, in the motion's object frame) do not lie on the
    mesh's surface: penetration into a mesh in another frame means nothing. ``track-object`` learns the frame from
    the take (centred on its markers) unless ``--canonical`` gives the markers in the mesh's frame."""
    canonical = np.asarray(object_motion.canonical, dtype=np.float64)
    distance = np.abs(signed_distance(canonical, np.asarray(mesh.vertices), np.asarray(mesh.faces)))
    distance = distance[np.isfinite(distance)]
    if not len(distance) or distance.max() <= MESH_MARKER_LIMIT:
        return []
    return [f"object {object_motion.name!r}: its markers lie up to {1000 * distance.max():.0f} mm (median "
            f"{1000 * np.median(distance):.0f} mm) from the surface of {path} (plausible: <= "
            f"{1000 * MESH_MARKER_LIMIT:.0f} mm, markers sit on it); the motion's object frame is likely not the "
            f"mesh's, and its penetration means little: track-object learns the frame from the take unless "
            f"--canonical gives the markers in the mesh's frame"]


def _object_error(object_motion, truth) -> dict:
    """Where the tracked object puts its markers against where a synthetic take's truth has them (the truth's
    ``object_*`` keys, :func:`handcap.synth.scene.write_capture`), mm, mean and spread over the frames with a pose
    in both of each frame's mean over the markers, and those frames: the
    object's frame may differ (a track learns its shape from the take), its markers' places do not. Nothing when
    the truth holds no object or none of the tracked markers."""
    data = load_npz(truth)
    keys = ("object_marker_names", "object_canonical", "object_rotation", "object_translation")
    if not all(k in data for k in keys):
        return {}
    index = {str(n): k for k, n in enumerate(np.asarray(data["object_marker_names"]).reshape(-1))}
    shared = [(k, index[n]) for k, n in enumerate(object_motion.marker_names) if n in index]
    rotation, translation = np.asarray(data["object_rotation"], float), np.asarray(data["object_translation"], float)
    if not shared or rotation.shape != (object_motion.n_frames, 3):
        return {}
    ours, theirs = (np.array(c) for c in zip(*shared))
    true = (np.einsum("tij,mj->tmi", matrix_from_axis_angle(rotation), np.asarray(data["object_canonical"])[theirs])
            + translation[:, None])
    error = np.linalg.norm(object_motion.transform_points(object_motion.canonical[ours]) - true, axis=-1)
    s = q.Stat.of(error[np.isfinite(error).all(axis=1)].mean(axis=1))  # per frame
    return {"object_error_mm": [1000 * s.mean, 1000 * s.std, s.count]} if s.count else {}


def _hand_for(motion, hand):
    """``hand``, or the OpenHand when the motion was solved with it."""
    if hand is not None:
        return hand
    if motion.model != "openhand":
        raise HandcapError(f"the motion was solved with the {motion.model} hand model: give --hand-model "
                           f"{motion.model} (and --mano-dir DIR or HANDCAP_MANO_DIR)")
    return OpenHand(motion.side)


#: The published figures a take's quality is shown against (``../shared/papers``): DexterCap's section 5 and Table 2
#: (its own captures and, as it measured them, GRAB and ARCTIC, both Vicon). Keys as :func:`motion_metrics`'s; each
#: value is (DexterCap, GRAB, ARCTIC), text.
PAPER_COLUMNS = ("DexterCap", "GRAB (Vicon)", "ARCTIC (Vicon)")
PAPER_FIGURES = {
    "mre_mm": ("0.77 ± 0.28 calibration, 2.06 ± 1.09 manipulation", "", ""),
    "msnr_db": ("9.31 ± 0.22", "7.29 ± 1.51", "7.82 ± 0.40"),
    "jerk_m_s3": ("0.76 ± 0.18", "3.68 ± 1.74", "0.91 ± 0.01"),
    "diversity": ("0.97", "0.91", "0.90"),
    "coherence": ("0.68", "0.70", "0.81"),
    "penetration_mm": ("3.8 ± 3.1", "", ""),
}
#: Said under the comparison: the published figures come from other takes, rates and filters.
PAPER_NOTE = ("Published figures are for the papers' own takes (their frame rates, filters and motions), "
              "so they place this take, not grade it: MSNR and jerk depend on the frame rate and the low-pass, "
              "diversity and coherence on how varied the take is.")


def paper_rows(metrics: dict) -> list[tuple[str, ...]]:
    """Rows (metric, this take, DexterCap, GRAB, ARCTIC) for the figures of ``metrics`` the papers report.

    Parameters
    ----------
    metrics : dict
        As :func:`motion_metrics` returns.
    """
    rows = []
    for key, published in PAPER_FIGURES.items():
        if key in metrics:
            label, text = _row(key, metrics[key])
            rows.append((label, text, *published))
    return rows


_LABELS = {"mre_mm": "MRE (mm)", "joint_error_mm": "joint error (mm)", "msnr_db": "MSNR (dB)",
           "jerk_m_s3": "jerk (m/s^3)", "diversity": "diversity", "coherence": "coherence",
           "penetration_mm": "penetration (mm)", "object_error_mm": "object error (mm)", "frames": "frames",
           "rate_hz": "rate (Hz)",
           "cube_msnr_db": "cube MSNR (dB)", "cube_jerk_m_s3": "cube jerk (m/s^3)", "cube_moves": "cube moves"}


def _row(key: str, value) -> tuple[str, str]:
    if isinstance(value, list):
        text = f"{value[0]:.3f} ± {value[1]:.3f}" + (f"  ({value[2]} frames)" if len(value) > 2 else "")
    elif isinstance(value, float):
        text = f"{value:.3f}"
    else:
        text = str(value)
    return _LABELS[key], text


def metrics_table(metrics: dict) -> str:
    """A human-readable table of :func:`motion_metrics`."""
    lines = []
    for key in _LABELS:
        if key in metrics:
            label, text = _row(key, metrics[key])
            lines.append(f"{label:22s} {text}")
    for name, value in metrics.get("leave_one_out_mm", {}).items():
        lines.append(f"{'leave-one-out ' + name:22s} {value:.2f} mm")
    return "\n".join(lines)
