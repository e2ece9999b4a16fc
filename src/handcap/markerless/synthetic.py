"""Synthetic hand keypoints with exact truth: what a 2D detector would give, and what it gets wrong.

The truth is the hand model itself: a generated motion (:func:`handcap.synth.motions.make_motion`) posed on an
OpenHand of random shape, its 21 joints taken as the keypoints (:mod:`~handcap.markerless.keypoints`). The
views add what real detectors do to them, each at a rate the caller sets: pixel noise, keypoints not
given, wrong keypoints (a detector's typical confusion: the position of another keypoint of the same hand),
and left/right labels swapped for a whole hand in a camera and frame.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import trimesh
from scipy.spatial.transform import Rotation

from handcap.core.camera import Camera
from handcap.core.errors import HandcapError
from handcap.core.geometry import closest_points_on_mesh
from handcap.core.transforms import homogeneous
from handcap.hand import OpenHand
from handcap.markerless.contact import ContactMap
from handcap.markerless.keypoints import hand_names, keypoints_from_joints
from handcap.multiview.detections import Detections
from handcap.synth.grasps import grasp_configuration
from handcap.synth.motions import make_motion, natural_pose
from handcap.synth.objects import make_object


@dataclass(frozen=True)
class SyntheticHand:
    """One generated hand and its truth.

    Attributes
    ----------
    side : str
    betas : ndarray (10,)
    phi : ndarray (T, 27)
        Anatomical angles, radians.
    global_orient, transl : ndarray (T, 3)
        Axis-angle and metres.
    keypoints : ndarray (T, 21, 3)
        The true keypoints, metres, keypoint order.
    """

    side: str
    betas: np.ndarray
    phi: np.ndarray
    global_orient: np.ndarray
    transl: np.ndarray
    keypoints: np.ndarray


def synthetic_hand(n_frames: int, rate: float, rng, *, side: str = "right", motion: str = "random",
                   offset=(0.0, 0.0, 0.0), shape_sd: float = 1.0) -> SyntheticHand:
    """A hand moving as ``motion``, of a random shape, and its true keypoints.

    Parameters
    ----------
    n_frames : int
    rate : float
        Frames per second.
    rng : numpy.random.Generator
    side : {"right", "left"}
    motion : str
        One of :data:`handcap.synth.motions.MOTIONS` without an object.
    offset : (3,) float
        Added to the hand's translation, metres (to set two hands apart).
    shape_sd : float
        Standard deviation of the shape values.

    Returns
    -------
    SyntheticHand
    """
    hand = OpenHand(side)
    betas = np.clip(rng.normal(0.0, shape_sd, 10), -2.5, 2.5)
    m = make_motion(motion, hand, n_frames, rate, rng)
    transl = m.transl + np.asarray(offset, dtype=np.float64)
    joints = hand.forward(betas, m.global_orient, None, transl, phi=m.phi, vertices=False).joints
    return SyntheticHand(side, betas, m.phi, m.global_orient, transl, keypoints_from_joints(joints))


def view_keypoints(rig, hands: dict, *, rate: float = 30.0, noise_px: float = 1.0, missing: float = 0.0,
                   wrong: float = 0.0, swap: float = 0.0, rng=None) -> tuple[Detections, np.ndarray]:
    """What a 2D keypoint detector gives in every camera of ``rig`` for the hands' true keypoints.

    Parameters
    ----------
    rig : CameraRig
    hands : dict of str to ndarray (T, 21, 3)
        True keypoints of each hand, metres, by label (``"left"``, ``"right"``).
    rate : float
        Frames per second.
    noise_px : float
        Standard deviation of the Gaussian pixel noise.
    missing : float
        Share of keypoints not given.
    wrong : float
        Share of keypoints given at the place of another keypoint of the same hand (plus noise).
    swap : float
        Share of camera-frames whose hand labels are exchanged (with one label, it changes to the other of
        ``left``/``right``).
    rng : numpy.random.Generator, optional

    Returns
    -------
    detections : Detections
        Marker names ``LABEL:keypoint``; keypoints outside an image are not given.
    true_hand : ndarray (N,) str
        The label of the hand each row really belongs to.
    """
    rng = np.random.default_rng(0) if rng is None else rng
    labels = sorted(hands)
    if not labels:
        raise HandcapError("give at least one hand")
    other = {"left": "right", "right": "left"}
    names = sorted({lab for lab in labels} | ({other.get(labels[0], labels[0])} if len(labels) == 1 else set()))
    n_frames = len(next(iter(hands.values())))
    n_cams = len(rig)
    flips = rng.random((n_frames, n_cams)) < swap
    frame, camera, marker, xy, truth = [], [], [], [], []
    for label in labels:
        points = np.asarray(hands[label], dtype=np.float64)
        pixels, depth = rig.project(points.reshape(-1, 3))
        pixels = pixels.reshape(n_cams, n_frames, 21, 2) + rng.normal(0.0, noise_px, (n_cams, n_frames, 21, 2))
        bad = rng.random((n_cams, n_frames, 21)) < wrong
        source = (np.arange(21) + rng.integers(1, 21, (n_cams, n_frames, 21))) % 21
        moved = np.take_along_axis(pixels, source[..., None], axis=2)
        pixels = np.where(bad[..., None], moved, pixels)
        seen = rig.in_image(pixels.reshape(n_cams, -1, 2)).reshape(n_cams, n_frames, 21)
        seen &= depth.reshape(n_cams, n_frames, 21) > 0
        seen &= rng.random(seen.shape) >= missing
        c, t, k = np.nonzero(seen)
        given = np.where(flips[t, c], np.array([other.get(label, label)]), np.array([label]))
        if len(labels) > 1:  # two hands: a flip exchanges the two labels
            given = np.where(flips[t, c], [lab for lab in labels if lab != label][0], label)
        marker.append(np.array([names.index(g) for g in given]) * 21 + k)
        frame.append(t)
        camera.append(c)
        xy.append(pixels[c, t, k])
        truth.append(np.full(len(t), label))
    marker_names = tuple(n for name in names for n in hand_names(name))
    detections = Detections(rig.names, marker_names, np.concatenate(frame), np.concatenate(camera),
                            np.concatenate(marker), np.concatenate(xy), np.ones(sum(len(f) for f in frame)), rate,
                            n_frames, source="synthetic keypoints")
    return detections, np.concatenate(truth)


@dataclass(frozen=True)
class GraspVideo:
    """A synthetic single-camera video of a steady grasp presented to the camera, and its truth.

    Attributes
    ----------
    camera : Camera
        The video camera (its frame is the world).
    pixels : ndarray (T, 21, 2)
        Detected keypoints in the distorted image, NaN where not given.
    points : ndarray (21, 3)
        True keypoints in the hand's own frame (OpenHand at ``phi``, no global pose, plus each keypoint's
        offset), metres.
    phi : ndarray (27,)
        The held pose, radians.
    betas : ndarray (10,)
    rotation, translation : ndarray (T, 3)
        Camera-from-hand pose of every frame (axis-angle, metres): ``x_cam = R x_hand + t``.
    wrong : ndarray (T, 21) bool
        Keypoints given at a wrong place.
    """

    camera: object
    pixels: np.ndarray
    points: np.ndarray
    phi: np.ndarray
    betas: np.ndarray
    rotation: np.ndarray
    translation: np.ndarray
    wrong: np.ndarray


def grasp_video(n_frames: int = 200, rng=None, *, noise_px: float = 3.0, missing: float = 0.1,
                wrong: float = 0.02, side: str = "right", size=(1280, 720), focal_px: float = 1000.0,
                distance: float = 0.5, offset_mm: float = 2.0, phi=None, betas=None) -> GraspVideo:
    """A hand holding one pose, turned in front of a camera as a participant presents a grasp (the paper's video).

    The hand's back faces the camera at the start; over the take it turns up to 80 degrees about the
    vertical and 45 degrees about the horizontal image axis (smooth random sweeps) and drifts a few
    centimetres, ``distance`` metres from the camera. The keypoints are the model's joints moved by a
    constant random offset (``offset_mm`` per axis: where an annotator marks a joint is not its centre of
    rotation), so no model reproduces them exactly. In the images they get Gaussian pixel noise,
    ``missing`` of them are not given, ``wrong`` are given at the place of another keypoint of the hand
    (plus 10 px).

    Parameters
    ----------
    n_frames : int
    rng : numpy.random.Generator, optional
    noise_px, missing, wrong : float
    side : {"right", "left"}
    offset_mm : float
        Standard deviation of each keypoint's constant offset from its joint, per axis, millimetres.
    size : (int, int)
        Image width and height, pixels.
    focal_px : float
    distance : float
        Metres from the camera to the hand's centre.
    phi : ndarray (27,), optional
        The held pose, radians (default: a random natural pose).
    betas : ndarray (10,), optional
        The hand's shape (default: random).

    Returns
    -------
    GraspVideo
    """
    rng = np.random.default_rng(0) if rng is None else rng
    hand = OpenHand(side)
    drawn_betas, drawn_phi = np.clip(rng.normal(0.0, 1.0, 10), -2.5, 2.5), natural_pose(rng)
    betas = drawn_betas if betas is None else np.asarray(betas, dtype=np.float64)
    phi = drawn_phi if phi is None else np.asarray(phi, dtype=np.float64)
    joints = hand.forward(betas, np.zeros(3), None, np.zeros(3), phi=phi, vertices=False).joints
    points = keypoints_from_joints(joints) + rng.normal(0.0, offset_mm / 1000.0, (21, 3))
    w, h = size
    camera = Camera("video", (w, h), [[focal_px, 0, w / 2 + rng.normal(0, 5)], [0, focal_px, h / 2 + rng.normal(0, 5)],
                                      [0, 0, 1]], distortions=[rng.normal(0, 0.05), rng.normal(0, 0.02), 0, 0, 0])
    # Model axes (x distal, y dorsal) to the camera's: fingers up the image, the back towards the camera.
    base = Rotation.from_matrix(np.column_stack([[0.0, -1.0, 0.0], [0.0, 0.0, -1.0], [1.0, 0.0, 0.0]]))
    t = np.linspace(0.0, 1.0, n_frames)

    def sweep(amplitude_deg):
        phase, freq = rng.uniform(0, 2 * np.pi), rng.uniform(0.7, 1.5)
        return np.deg2rad(amplitude_deg) * np.sin(2 * np.pi * freq * t + phase)

    turn = Rotation.from_euler("y", sweep(80.0)[:, None]) * Rotation.from_euler("x", sweep(45.0)[:, None]) * base
    centre = points.mean(axis=0)
    drift = np.stack([sweep(0.0) + 0.03 * np.sin(3 * t + rng.uniform(0, 6)), 0.02 * np.sin(4 * t + rng.uniform(0, 6)),
                      np.full(n_frames, distance) + 0.04 * np.sin(2 * t + rng.uniform(0, 6))], axis=1)
    translation = drift - turn.apply(centre)
    cam_points = np.einsum("tij,kj->tki", turn.as_matrix(), points) + translation[:, None]
    pixels, _ = camera.project(cam_points.reshape(-1, 3))
    pixels = pixels.reshape(n_frames, 21, 2) + rng.normal(0.0, noise_px, (n_frames, 21, 2))
    bad = rng.random((n_frames, 21)) < wrong
    other = (np.arange(21) + rng.integers(1, 21, (n_frames, 21))) % 21
    moved = np.take_along_axis(pixels, other[..., None], axis=1) + rng.normal(0, 10.0, (n_frames, 21, 2))
    pixels = np.where(bad[..., None], moved, pixels)
    pixels[rng.random((n_frames, 21)) < missing] = np.nan
    return GraspVideo(camera, pixels, points, phi, betas, turn.as_rotvec(), translation, bad)


def synthetic_grasp(kind: str = "precision", object_name: str = "cuboid", *, max_edge: float = 0.006,
                    touch: float = 0.002):
    """A grasp of a synthetic object by the average right hand, and its exact contact map.

    Parameters
    ----------
    kind : {"power", "precision"}
        As :func:`handcap.synth.grasps.grasp_configuration` (fingers closed until they touch).
    object_name : str
        ``cuboid``, ``cylinder`` or ``sphere`` (:func:`handcap.synth.objects.make_object`).
    max_edge : float
        The object's mesh is subdivided to edges of at most this, metres (the contact map's resolution).
    touch : float
        Object vertices within this of the hand's surface are in contact, metres.

    Returns
    -------
    hand : OpenHand
    obj : SynthObject
        With its exact signed distance.
    object_pose : ndarray (4, 4)
        Object frame to the hand model's frame (the world here).
    phi : ndarray (27,)
        The grasping pose (global pose zero).
    contact_map : ContactMap
    """
    hand = OpenHand()
    obj = make_object(object_name, seed=0)
    object_pose, _, phi = grasp_configuration(hand, obj, kind)
    vertices, faces = trimesh.remesh.subdivide_to_size(obj.vertices, obj.faces, max_edge=max_edge)
    skin = hand.forward(np.zeros(10), np.zeros(3), None, np.zeros(3), phi=phi).vertices
    world = vertices @ object_pose[:3, :3].T + object_pose[:3, 3]
    distance = np.linalg.norm(closest_points_on_mesh(world, skin, hand.faces)[0] - world, axis=1)
    return hand, obj, object_pose, phi, ContactMap(vertices, faces, (distance < touch).astype(float))


@dataclass(frozen=True)
class GraspVideoTruth:
    """A video of a steady grasp of a known object, with the object's truth (:func:`grasp_object_video`).

    Attributes
    ----------
    video : GraspVideo
        The hand (average shape, the grasping pose) and its keypoints.
    hand : OpenHand
    obj : SynthObject
        Mesh in its frame, metres, with its exact signed distance.
    object_poses : ndarray (T, 4, 4)
        Object to camera in every frame.
    contact_map : ContactMap
        The exact contacts (the object's mesh subdivided).
    points : ndarray (N, 3)
        The object's surface as a depth camera at the video camera would see it in frame 0 (the sides facing
        the camera, not behind the hand), metres, with noise.
    """

    video: GraspVideo
    hand: object
    obj: object
    object_poses: np.ndarray
    contact_map: ContactMap
    points: np.ndarray


def grasp_object_video(kind: str = "precision", object_name: str = "cuboid", n_frames: int = 200, rng=None, *,
                       points: int = 3000, point_noise: float = 0.0005, **video) -> GraspVideoTruth:
    """A hand holding an object in a grasp, turned in front of a camera (:func:`grasp_video` with
    :func:`synthetic_grasp`'s hand, pose and object), and a depth view of the object in the first frame.

    Parameters
    ----------
    kind, object_name : str
        As :func:`synthetic_grasp`.
    n_frames : int
    rng : numpy.random.Generator, optional
    points : int
        Surface samples of the object before those hidden are removed.
    point_noise : float
        Standard deviation of the depth points' noise per axis, metres.
    **video
        More arguments of :func:`grasp_video` (noise, missing and wrong keypoints, ...).

    Returns
    -------
    GraspVideoTruth
    """
    rng = np.random.default_rng(0) if rng is None else rng
    hand, obj, object_pose, phi, contact_map = synthetic_grasp(kind, object_name)
    clip = grasp_video(n_frames, rng, phi=phi, betas=np.zeros(10), side=hand.side, **video)
    poses = homogeneous(Rotation.from_rotvec(clip.rotation).as_matrix(), clip.translation)
    object_poses = poses @ object_pose
    mesh = trimesh.Trimesh(obj.vertices, obj.faces, process=False)
    surface, face = trimesh.sample.sample_surface(mesh, points, seed=int(rng.integers(1 << 31)))
    cam = surface @ object_poses[0, :3, :3].T + object_poses[0, :3, 3]
    normals = mesh.face_normals[face] @ object_poses[0, :3, :3].T
    facing = np.einsum("ij,ij->i", normals, cam) < 0
    skin_cam = hand.forward(np.zeros(10), np.zeros(3), None, np.zeros(3), phi=phi).vertices @ poses[0, :3, :3].T \
        + poses[0, :3, 3]
    hidden = trimesh.Trimesh(skin_cam, hand.faces, process=False).ray.intersects_any(
        cam, -cam / np.linalg.norm(cam, axis=1, keepdims=True))
    seen = cam[facing & ~hidden] + rng.normal(0.0, point_noise, (int((facing & ~hidden).sum()), 3))
    return GraspVideoTruth(clip, hand, obj, object_poses, contact_map, seen)
