"""Synthetic captures with ground truth: the yardstick of every other stage.

:func:`synthesize` moves the OpenHand (and an object) through a motion, sticks
markers on the skin as a layout says, films them with a rig of cameras,
decides visibility by ray casting against the hand and the object, and adds
what real systems add: 3D jitter, 2D pixel noise, dropouts, ghost markers
near real ones and label swaps. :func:`write_capture` writes the folder::

    markers.c3d, markers.npz   labeled markers as a capture system gives them
                               (layout and object markers, then ghosts as
                               unlabeled trajectories named *0, *1, ...)
    points.npz                 the same points per frame, unlabeled and shuffled
    detections.npz             2D detections per camera (File contract)
    cameras.toml               the rig (anipose style)
    truth.npz                  hand motion (HandMotion keys: hand markers in
                               marker_names / marker_fit), joints; every label
                               (names) with its noise-free position (positions,
                               normals), visibility (visible (T, M), camera_visible
                               (T, C, M)), faults (dropped, swaps, ghosts), the
                               marker attachment and the object motion; with the
                               2x2x2 cube turned (motion turn-cube) also its
                               cube_cubie_rotation (T, 8, 3, 3), cube_layer_angle
                               (T, 6), cube_move_frames (K, 2), cube_moves and
                               cube_riding (the finger on each move's layer)
    scene.toml                 every setting, to make the folder again

Everything is deterministic for a seed: same settings, same bytes. The settings
(:class:`~handcap.synth.config.SynthConfig`) and ``scene.toml`` are in :mod:`handcap.synth.config`.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import tomli_w
from scipy.spatial.transform import Rotation
from tqdm import tqdm

from handcap.core.errors import HandcapError
from handcap.core.files import atomic_output, save_npz
from handcap.core.geometry import closest_points_on_mesh
from handcap.core.markers import MarkerSequence
from handcap.core.motion import HandMotion, ObjectMotion
from handcap.core.points import PointCloudSequence
from handcap.hand import OpenHand
from handcap.hand.attachment import MarkerAttachment
from handcap.io import write_c3d, write_markers_npz, write_points_npz
from handcap.io.npz import write_hand_motion
from handcap.layouts import MARKER_GAP, LayoutMarker, MarkerLayout, load_layout
from handcap.objects.articulated import load_articulated
from handcap.objects.cube import format_moves, random_moves
from handcap.synth.cameras import cage_rig
from handcap.synth.cube import CUBE_MOTION, turning_motion
from handcap.synth.config import DEFAULT_OBJECT, SynthConfig, config_from_scene, scene_table
from handcap.synth.faults import burst_dropouts, ghost_markers, swap_labels
from handcap.synth.motions import WORK_CENTRE, make_motion
from handcap.synth.objects import make_object
from handcap.synth.visibility import take_visibility

# The settings and their scene.toml live in handcap.synth.config; named here too, where they were first.
__all__ = ["DEFAULT_OBJECT", "SynthCapture", "SynthConfig", "config_from_scene", "misplaced", "scene_table",
           "synthesize", "write_capture"]

#: Frames whose visibility is tested together (memory: about 0.2 MB per frame of the hand's mesh).
VISIBILITY_FRAMES = 64


@dataclass(frozen=True, eq=False)
class SynthCapture:
    """A synthetic capture in memory (see the module docstring for the files)."""

    config: SynthConfig
    markers: MarkerSequence
    points: PointCloudSequence
    detections: dict
    rig: object
    hand_motion: HandMotion
    object_motion: ObjectMotion | None
    truth: dict = field(repr=False)

    def summary(self) -> str:
        """One line: frames, hand markers, trajectories and the share of marker-frames reconstructed."""
        m = self.markers
        return (f"{m.n_frames} frames, {len(self.hand_motion.marker_names)} hand markers, {m.n_markers} trajectories, "
                f"{100 * self.truth['visible'].mean():.1f}% reconstructed")

    @property
    def attachment(self) -> MarkerAttachment:
        """Where the hand markers really sit (the ground truth a calibration should find)."""
        t = self.truth
        return MarkerAttachment(self.hand_motion.marker_names, t["attachment_triangles"],
                                t["attachment_barycentric"], t["attachment_offset"], self.hand_motion.betas,
                                self.hand_motion.model, self.hand_motion.side)

    def labeled_points(self, names=None, *, radius: float = 0.003) -> MarkerSequence:
        """The true labels of the unlabeled points: each marker's point in every frame, NaN where it was
        not reconstructed (hidden, dropped, or no point within ``radius`` metres of its true place).

        A labeler's output on :attr:`points` is scored against this (``handcap.labeling.score_labels``).

        Parameters
        ----------
        names : sequence of str, optional
            The markers (default: the hand's layout markers).
        radius : float
            Metres; the reconstruction noise is well below it.
        """
        names = list(self.hand_motion.marker_names if names is None else names)
        all_names = [str(n) for n in self.truth["names"]]
        index = [all_names.index(n) for n in names]
        true = self.truth["positions"][:, index]
        seen = self.truth["visible"][:, index] & ~self.truth["dropped"][:, index]
        out = np.full(true.shape, np.nan)
        rows = np.arange(len(names))
        for t, pts in enumerate(self.points.frames):
            if len(pts):
                d = np.linalg.norm(true[t][:, None] - pts[None], axis=-1)
                j = np.argmin(d, axis=1)
                ok = seen[t] & (d[rows, j] < radius)
                out[t, ok] = pts[j[ok]]
        return MarkerSequence(out, tuple(names), self.markers.rate)


def misplaced(layout, hand, sigma: float, rng):
    """The layout with its markers stuck on a little off their nominal spots (see ``placement_mm``).

    Shifts happen on the flat template and every marker is put back on the
    skin of its own segment (closest point), so it stays where a marker can be.
    A patch (in a patch layout) moves as one piece and also turns about the
    skin normal, by a normal angle of 3 degrees per millimetre of ``sigma``.
    Sphere markers keep :data:`~handcap.layouts.MARKER_GAP` between their surfaces (or their
    nominal distance, where the layout puts them closer): one that would come
    nearer a marker already stuck on, or the nominal spot of one still to
    come, is moved half as far, then a quarter..., then not at all.

    Parameters
    ----------
    layout : MarkerLayout
        On ``hand``'s side, with a position (metres) for every hand marker.
    hand : HandModel
        Its average shape (``betas = 0``) is the template.
    sigma : float
        Standard deviation of the shift along the skin, metres (per tangential axis); 0 or less
        returns ``layout`` unchanged.
    rng : numpy.random.Generator

    Returns
    -------
    MarkerLayout
        Same markers, hand marker positions moved (metres); object markers unchanged.
    """
    if sigma <= 0:
        return layout
    template = hand.forward().vertices
    positions = layout.positions()
    gap = 2 * layout.marker_radius + MARKER_GAP
    moved = positions.copy()
    groups = {}
    for i, m in enumerate(layout.markers):
        if not m.on_object:
            groups.setdefault(m.patch if (m.patch and layout.marker_kind == "patch") else m.name, []).append(i)
    for members in groups.values():
        pts = positions[members]
        centre = pts.mean(axis=0)
        seg_faces = hand.segment_faces(layout.markers[members[0]].segment)
        _, face, _ = closest_points_on_mesh(centre[None], template, hand.faces[seg_faces])
        tri = template[hand.faces[seg_faces[face[0]]]]
        normal = np.cross(tri[1] - tri[0], tri[2] - tri[0])
        normal /= np.linalg.norm(normal)
        shift = rng.normal(0, sigma, 3)
        shift -= normal * (shift @ normal)
        angle = rng.normal(0, np.deg2rad(3.0) * sigma * 1000) if len(members) > 1 else 0.0
        turn = Rotation.from_rotvec(angle * normal).as_matrix()
        moved[members] = (pts - centre) @ turn.T + centre + shift
    markers, placed = [], []
    for i, m in enumerate(layout.markers):
        if m.on_object:
            markers.append(m)
            continue
        seg_faces = hand.segment_faces(m.segment)
        # A sphere that would touch one already stuck on, or the nominal spot of one still to come, goes nearer
        # its own nominal spot (which always keeps clear of both).
        others = [] if layout.marker_kind == "patch" else placed + [
            (j, positions[j]) for j in range(i + 1, len(positions)) if not layout.markers[j].on_object]
        for k in range(5):
            spot = positions[i] + (moved[i] - positions[i]) * (0.5 ** k if k < 4 else 0.0)
            point = closest_points_on_mesh(spot[None], template, hand.faces[seg_faces])[0][0]
            if all(np.linalg.norm(point - q) >= min(gap, np.linalg.norm(positions[i] - positions[j]))
                   for j, q in others):
                break
        placed.append((i, point))
        markers.append(LayoutMarker(m.name, m.segment, point, m.patch))
    return MarkerLayout(layout.name, layout.side, tuple(markers), layout.rigid, layout.marker_radius,
                        layout.marker_kind, layout.description)


def synthesize(config: SynthConfig, *, progress: bool | None = None) -> SynthCapture:
    """Make a synthetic capture.

    Parameters
    ----------
    config : SynthConfig
    progress : bool, optional
        Show a progress bar (default: only on a terminal).
    """
    seeds = np.random.SeedSequence(config.seed).spawn(6)
    _, rng_motion, rng_noise, rng_faults, rng_detect, rng_shuffle = (np.random.default_rng(s) for s in seeds)
    # The subject (hand shape, where the markers are stuck) can be shared between takes.
    subject = np.random.SeedSequence(config.seed if config.subject_seed is None else config.subject_seed).spawn(2)
    rng_shape, rng_place = (np.random.default_rng(s) for s in subject)
    hand = OpenHand(config.side)
    layout = load_layout(config.layout, side=config.side)
    betas = np.asarray(config.betas if config.betas is not None else rng_shape.normal(0, 0.5, 10), dtype=np.float64)
    attachment = MarkerAttachment.from_layout(misplaced(layout, hand, config.placement_mm / 1000, rng_place),
                                              hand, betas)
    kind = config.object_kind
    turning = cube = None
    if config.motion == CUBE_MOTION:  # the hand turns the cube's layers: an articulated object
        moves = config.moves if config.moves is not None else format_moves(random_moves(10, rng_motion))
        turning, cube, obj = turning_motion(hand, moves, config.rate, rng_motion), load_articulated("cube2x2"), None
    else:
        obj = make_object(kind, seed=config.seed) if kind else None

    # 1. Motion and the hand surface in every frame.
    motion = turning.motion if turning else make_motion(config.motion, hand, config.frames, config.rate,
                                                        rng_motion, obj, betas=betas)
    hand_pose = hand.hand_pose_from_phi(motion.phi)
    out = hand.forward(betas, motion.global_orient, hand_pose, motion.transl)
    vertices, joints = out.vertices, out.joints
    hand_markers = attachment.positions(vertices, hand.faces)
    hand_normals = attachment.normals(vertices, hand.faces)

    # 2. Object markers and triangles.
    names = list(attachment.marker_names)
    truth_markers, normals = hand_markers, hand_normals
    object_motion = None
    if turning is not None:
        obj_markers, obj_normals = turning.markers(cube)
        truth_markers = np.concatenate([hand_markers, obj_markers], axis=1)
        normals = np.concatenate([hand_normals, obj_normals], axis=1)
        names += list(cube.marker_names)
        object_motion = ObjectMotion(motion.object_rotation, motion.object_translation, config.rate, cube.name,
                                     cube.marker_names, cube.markers, {"holding": motion.holding.astype(np.int8)})
    elif obj is not None:
        rot = Rotation.from_rotvec(motion.object_rotation).as_matrix()
        obj_markers = np.einsum("tij,kj->tki", rot, obj.marker_positions) + motion.object_translation[:, None]
        obj_normals = np.einsum("tij,kj->tki", rot, obj.marker_normals)
        truth_markers = np.concatenate([hand_markers, obj_markers], axis=1)
        normals = np.concatenate([hand_normals, obj_normals], axis=1)
        names += list(obj.marker_names)
        object_motion = ObjectMotion(motion.object_rotation, motion.object_translation, config.rate, obj.name,
                                     obj.marker_names, obj.marker_positions,
                                     {"holding": motion.holding.astype(np.int8)})

    # 3. Cameras and visibility (ray casting against hand and object).
    rig = cage_rig(config.cameras, target=tuple(WORK_CENTRE), seed=config.seed)
    angle = config.max_view_angle_deg
    if angle is None and layout.marker_kind == "patch":
        angle = 75.0
    n_hand = len(attachment)
    max_angle = None if angle is None else np.deg2rad(angle)
    n_frames, n_markers = truth_markers.shape[:2]
    seen_by = np.zeros((n_frames, len(rig), n_markers), bool)
    faces = hand.faces if obj is None else np.concatenate([hand.faces, obj.faces + vertices.shape[1]])
    if turning is not None:
        faces = np.concatenate([hand.faces, turning.surface(0)[1] + vertices.shape[1]])
    # tqdm: disable=None hides the bar when not on a terminal.
    hidden = None if progress is None else not progress
    with tqdm(total=n_frames, desc="visibility", unit="frame", disable=hidden, leave=False) as bar:
        for start in range(0, n_frames, VISIBILITY_FRAMES):
            t = np.arange(start, min(start + VISIBILITY_FRAMES, n_frames))
            surface = vertices[t]
            if obj is not None:
                turned = Rotation.from_rotvec(motion.object_rotation[t]).as_matrix()
                moved = obj.vertices @ turned.transpose(0, 2, 1) + motion.object_translation[t, None]
                surface = np.concatenate([surface, moved], axis=1)
            elif turning is not None:
                surface = np.concatenate([surface, np.stack([turning.surface(f)[0] for f in t])], axis=1)
            if max_angle is None:
                seen_by[t] = take_visibility(truth_markers[t], rig, surface, faces)
            else:  # printed patches are on the hand; object markers stay spheres
                seen_by[t, :, :n_hand] = take_visibility(truth_markers[t, :n_hand], rig, surface, faces,
                                                         normals=normals[t, :n_hand], max_view_angle=max_angle)
                seen_by[t, :, n_hand:] = take_visibility(truth_markers[t, n_hand:], rig, surface, faces)
            bar.update(len(t))
    reconstructed = seen_by.sum(axis=1) >= config.min_views

    # 4. What the capture system reports: jitter, dropouts, swaps, ghosts.
    observed = truth_markers + rng_noise.normal(0, config.noise_mm / 1000, truth_markers.shape)
    dropped = burst_dropouts(rng_faults, (n_frames, n_markers), config.dropout)
    observed[~reconstructed | dropped] = np.nan
    observed, swaps = swap_labels(rng_faults, observed, config.swap_rate / config.rate)
    ghosts, ghost_events = ghost_markers(rng_faults, observed, config.ghost_rate / config.rate)
    ghost_names = [f"*{i}" for i in range(ghosts.shape[1])]
    markers = MarkerSequence(np.concatenate([observed, ghosts], axis=1), names + ghost_names, config.rate)
    padded = markers.positions.copy()
    for t in range(n_frames):
        padded[t] = padded[t, rng_shuffle.permutation(padded.shape[1])]
    points = PointCloudSequence.from_padded(padded, config.rate)

    # 5. 2D detections in every camera that sees a marker.
    detections = _detections(rig, truth_markers, seen_by, names, config, rng_detect)

    hand_motion = HandMotion(betas, motion.global_orient, hand_pose, motion.transl, config.rate, config.side,
                             motion.phi, hand.name, joints, tuple(names[:n_hand]), hand_markers)
    truth = {
        "names": np.array(names), "positions": truth_markers, "normals": normals,
        "visible": reconstructed, "camera_visible": seen_by, "dropped": dropped,
        "swaps": np.array(swaps, dtype=np.int64).reshape(-1, 4),
        "ghosts": np.array(ghost_events, dtype=np.int64).reshape(-1, 3),
        "attachment_triangles": attachment.triangles, "attachment_barycentric": attachment.barycentric,
        "attachment_offset": attachment.offset,
    }
    if turning is not None:
        truth.update({"cube_cubie_rotation": turning.cubie_rotation, "cube_layer_angle": turning.layer_angle,
                      "cube_move_frames": turning.move_frames, "cube_moves": np.array(format_moves(turning.moves)),
                      "cube_riding": np.array(turning.riding)})
    return SynthCapture(config, markers, points, detections, rig, hand_motion, object_motion, truth)


def _detections(rig, truth_markers, seen_by, names, config, rng) -> dict:
    frames, cams, marks, xys = [], [], [], []
    for c, camera in enumerate(rig):
        t_idx, m_idx = np.nonzero(seen_by[:, c, :])
        pixels, _ = camera.project(truth_markers[t_idx, m_idx])
        frames.append(t_idx)
        cams.append(np.full(len(t_idx), c))
        marks.append(m_idx)
        xys.append(pixels)
    frame, camera_idx, marker, xy = (np.concatenate(a) for a in (frames, cams, marks, xys))
    xy = xy + rng.normal(0, config.pixel_noise, xy.shape)
    wrong = rng.random(len(marker)) < config.outlier_rate
    if wrong.any() and len(names) > 1:
        shift = rng.integers(1, len(names), wrong.sum())
        marker = marker.copy()
        marker[wrong] = (marker[wrong] + shift) % len(names)
    score = rng.uniform(0.7, 1.0, len(marker))
    order = np.lexsort((marker, camera_idx, frame))
    return {"camera_names": np.array(rig.names), "marker_names": np.array(names), "frame": frame[order],
            "camera": camera_idx[order], "marker": marker[order], "xy": xy[order], "score": score[order],
            "rate": np.array(config.rate), "wrong_id": wrong[order]}


def write_capture(capture: SynthCapture, folder) -> dict:
    """Write a capture folder (see the module docstring); returns the paths written.

    Files are written atomically; other files in the folder are left alone.

    Parameters
    ----------
    capture : SynthCapture
        Markers, points and truth in metres, detections in pixels.
    folder : str or Path
        Created (with its parents) if missing.

    Returns
    -------
    dict of str to Path
        ``markers.c3d``, ``markers.npz``, ``points.npz``, ``detections.npz``, ``cameras.toml``,
        ``truth.npz`` and ``scene.toml``, each by its file name.

    Raises
    ------
    HandcapError
        ``folder`` exists and is not a folder, or a file cannot be written.
    """
    folder = Path(folder)
    if folder.exists() and not folder.is_dir():
        raise HandcapError(f"{folder} exists and is not a folder")
    folder.mkdir(parents=True, exist_ok=True)
    paths = {name: folder / name for name in ("markers.c3d", "markers.npz", "points.npz", "detections.npz",
                                              "cameras.toml", "truth.npz", "scene.toml")}
    write_c3d(capture.markers, paths["markers.c3d"])
    write_markers_npz(capture.markers, paths["markers.npz"])
    write_points_npz(capture.points, paths["points.npz"])
    save_npz(paths["detections.npz"], capture.detections)
    capture.rig.save(paths["cameras.toml"])
    # truth.npz: the HandMotion keys (readable with read_hand_motion) plus the rest of the truth.
    write_hand_motion(capture.hand_motion, paths["truth.npz"])
    with np.load(paths["truth.npz"]) as data:
        arrays = {k: data[k] for k in data.files}
    arrays.update(capture.truth)
    if capture.object_motion is not None:
        om = capture.object_motion
        arrays.update({"object_name": np.array(om.name), "object_rotation": om.rotation,
                       "object_translation": om.translation, "object_marker_names": np.array(om.marker_names),
                       "object_canonical": om.canonical, "object_holding": om.state["holding"]})
    save_npz(paths["truth.npz"], arrays)
    with atomic_output(paths["scene.toml"]) as fh:
        fh.write(tomli_w.dumps(scene_table(capture.config)).encode())
    return paths
