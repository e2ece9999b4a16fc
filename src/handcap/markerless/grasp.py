"""Hand and object of a steady grasp from one video (the paper's Stages 1-5 after the keypoints).

The object is known by its mesh. Its pose is measured once, in one frame of the video (``frame``): given
(a 4 x 4 from another tool), or fitted by ICP to a point cloud of the object's surface in that frame's
camera (a depth camera's; :func:`object_pose_from_points`), started from the given pose when there is one
(the paper's ``T_adj``: the change of the object's pose while the participant settles the grasp). As the
hand holds the object still, the object is fixed in the hand's frame; the video's virtual cameras (one
camera-from-hand pose per frame, :mod:`~handcap.markerless.sfm`) then carry it to every frame:
``camera_T_object(t) = camera_T_hand(t) @ inv(camera_T_hand(frame)) @ camera_T_object(frame)``.

One camera cannot see the hand's size, and the hand's distance from the camera grows with it, while the
object's points are metric, and an error of the hand's size moves the carried object by that fraction of the
hand's travel. With a contact map the size is measured (unless ``scale`` is given): the hand, scaled about
the camera's centre, is put where the contacted object points touch it (:func:`scale_from_contact`), and
the video is solved again at that size. On 6 synthetic grasp videos this halved the object's error
(vertices 11.8 -> 5.2 mm on average, sizes measured 1.01-1.04 where the keypoints' offsets make the palm
look 1-4 % larger than the model's). Without a contact map the average adult's size is taken, with a
warning. The grasp is then refined against the map (:func:`~handcap.markerless.contact.refine_grasp`) and
the change is carried to every frame.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, replace

import numpy as np
import trimesh
from scipy.optimize import minimize_scalar
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation

from handcap.core.errors import HandcapError, HandcapWarning
from handcap.core.motion import HandMotion, ObjectMotion
from handcap.core.transforms import homogeneous
from handcap.hand import OpenHand
from handcap.markerless.capture import VideoCapture, capture_video, video_motion
from handcap.markerless.contact import ContactMap, ObjectField, refine_grasp
from handcap.markerless.joint_model import KeypointModel
from handcap.markerless.sfm import template_points
from handcap.quality.plausibility import attach

#: Points sampled on the mesh's surface for ICP.
ICP_SAMPLES = 20_000
#: After a first ICP, cloud points farther than this many times the median distance are dropped (the hand's
#: points, background) and ICP runs again.
ICP_OUTLIER = 3.0
#: Two ICP starts whose poses differ by more than this (degrees) and whose fits are within
#: :data:`AMBIGUOUS_COST` of each other mean the cloud does not fix the pose (a symmetric object).
AMBIGUOUS_DEG, AMBIGUOUS_COST = 10.0, 1.15
#: Without a start, each of the 24 turns is first fitted with this many of the cloud's points (drawn at random)
#: and only those whose fit costs at most :data:`ICP_RECHECK` times the best go on to the whole cloud.
ICP_COARSE, ICP_RECHECK = 500, 3.0
#: A cloud whose median distance to the fitted mesh is above this (metres) is not the object.
ICP_WARNING = 0.003
#: Scales searched for the hand (relative to the size assumed).
SCALE_RANGE = (0.6, 1.6)
#: Contacted object points farther than this from the hand count as this far in the scale's fit, metres.
SCALE_CAP = 0.02


def _model_poses(hand, betas, orient, transl) -> np.ndarray:
    """Camera-from-model poses (..., 4, 4) of MANO-style global parameters (the model turns about its root)."""
    j0 = KeypointModel(hand, betas).rest_joints[0]
    rot = Rotation.from_rotvec(np.reshape(orient, (-1, 3))).as_matrix().reshape(np.shape(orient)[:-1] + (3, 3))
    return homogeneous(rot, np.asarray(transl) + j0 - rot @ j0)


def _transform(pose, points) -> np.ndarray:
    return np.asarray(points) @ pose[:3, :3].T + pose[:3, 3]


def object_pose_from_points(vertices, faces, points, initial=None, *, seed: int = 0):
    """Pose of a known mesh fitted to a point cloud of its surface (ICP, trimesh's).

    Parameters
    ----------
    vertices : ndarray (V, 3)
        The object's mesh in its own frame, metres.
    faces : ndarray (F, 3)
    points : ndarray (N, 3)
        Points of the object's surface in the camera's frame, metres (a partial view is fine).
    initial : ndarray (4, 4), optional
        A start (object to camera). Without it, the 24 turns of a cube about the cloud's centre are tried.
    seed : int
        For the surface samples.

    Returns
    -------
    pose : ndarray (4, 4)
        Object frame to camera frame.
    distance : float
        Median distance of the inlier points to the posed surface, metres.
    warnings : list of str
    """
    points = np.asarray(points, dtype=np.float64)
    if points.ndim != 2 or points.shape[1] != 3 or len(points) < 10:
        raise HandcapError(f"object points must be (N, 3) with N >= 10, got {points.shape}")
    points = points[np.isfinite(points).all(axis=1)]
    if len(points) < 10:
        raise HandcapError("object points: fewer than 10 finite points")
    mesh = trimesh.Trimesh(vertices, faces, process=False)
    samples = trimesh.sample.sample_surface_even(mesh, ICP_SAMPLES, seed=seed)[0]
    tree = cKDTree(samples)
    if initial is not None:
        starts = [np.linalg.inv(np.asarray(initial, dtype=np.float64))]
    else:
        shift = np.eye(4)
        shift[:3, 3] = samples.mean(axis=0)
        to_centre = np.eye(4)
        to_centre[:3, 3] = -points.mean(axis=0)
        turns = Rotation.create_group("O").as_matrix()
        starts = []
        for turn in turns:
            m = np.eye(4)
            m[:3, :3] = turn
            starts.append(shift @ m @ to_centre)  # camera points to the object's frame
    if len(starts) > 1 and len(points) > 2 * ICP_COARSE:  # coarse to fine: the turns on a few points first
        few = points[np.random.default_rng(seed).choice(len(points), ICP_COARSE, replace=False)]
        coarse = sorted((_icp(few, samples, tree, start) for start in starts), key=lambda f: f[0])
        starts = [f[2] for f in coarse if f[0] <= ICP_RECHECK * coarse[0][0]]
    fits, turn = [], None
    for start in starts:  # best coarse fit first; once two poses fit equally well, the rest cannot say more
        fits = sorted(fits + [_icp(points, samples, tree, start)], key=lambda f: f[0])
        turn = _ambiguous(fits)
        if turn is not None:
            break
    cost, distance, matrix = fits[0]
    found = []
    if turn is not None:
        found.append(f"the object's points fit poses {turn:.0f} degrees apart equally well (a symmetric shape, "
                     f"or too few points): give the object's pose as a start")
    if distance > ICP_WARNING:
        found.append(f"the object's points lie {1000 * distance:.1f} mm from its fitted mesh (median): are they "
                     f"the object's, in metres?")
    return np.linalg.inv(matrix), distance, found


def _ambiguous(fits) -> float | None:
    """The turn (degrees) from the best of ``fits`` (sorted by cost) to another that fits about as well, or None."""
    cost, _, matrix = fits[0]
    for other_cost, _, other in fits[1:]:
        turn = np.rad2deg(Rotation.from_matrix(other[:3, :3] @ matrix[:3, :3].T).magnitude())
        if turn > AMBIGUOUS_DEG and other_cost <= AMBIGUOUS_COST * cost:
            return float(turn)
    return None


def _icp(points, samples, tree, start) -> tuple[float, float, np.ndarray]:
    """ICP of ``points`` onto ``samples`` (with their tree) from ``start``, again without the outliers of the first:
    the mean squared and the median distance of the points kept, and the matrix (points to samples)."""
    matrix = trimesh.registration.icp(points, samples, initial=start, threshold=1e-7, max_iterations=60)[0]
    d = tree.query(_transform(matrix, points))[0]
    keep = d <= max(ICP_OUTLIER * np.median(d), 1e-4)
    matrix = trimesh.registration.icp(points[keep], samples, initial=matrix, threshold=1e-8, max_iterations=60)[0]
    d = tree.query(_transform(matrix, points[keep]))[0]
    return float(np.mean(d ** 2)), float(np.median(d)), matrix


def hand_poses(motion: HandMotion, hand) -> np.ndarray:
    """Camera-from-hand-model poses (T, 4, 4) of a motion: a point ``x`` of the model at rest goes to ``R x + t``.

    Parameters
    ----------
    motion : HandMotion
    hand : HandModel
        The motion's model.
    """
    return _model_poses(hand, motion.betas, motion.global_orient, motion.transl)


def carry_object(poses, frame: int, object_pose) -> np.ndarray:
    """The object's pose in every frame, fixed in the hand's frame (T, 4, 4).

    Parameters
    ----------
    poses : ndarray (T, 4, 4)
        Camera-from-hand poses (the virtual cameras).
    frame : int
        The frame ``object_pose`` was measured in.
    object_pose : ndarray (4, 4)
        Object to camera in that frame.
    """
    hand_from_object = np.linalg.inv(poses[frame]) @ np.asarray(object_pose, dtype=np.float64)
    return poses @ hand_from_object


def scale_from_contact(hand_vertices, contact_map: ContactMap, object_pose, field: ObjectField | None = None) -> float:
    """How much larger the hand must be, scaled about the camera's centre, to touch the contacted object points.

    Parameters
    ----------
    hand_vertices : ndarray (V, 3)
        The hand's surface in the camera frame, metres, at the assumed size.
    contact_map : ContactMap
    object_pose : ndarray (4, 4)
        Object to camera.
    field : ObjectField, optional
        The contact map's object field, where the caller has made it.

    Returns
    -------
    float
        The factor, within :data:`SCALE_RANGE`.
    """
    touched = _transform(object_pose, contact_map.vertices[contact_map.contacted])
    if not len(touched):
        raise HandcapError("the contact map has no contacted vertex: the hand's size cannot be measured from it")
    field = ObjectField(contact_map.vertices, contact_map.faces) if field is None else field
    inverse = np.linalg.inv(object_pose)
    hand_vertices = np.asarray(hand_vertices, dtype=np.float64)

    def cost(s):
        verts = s * hand_vertices
        d = np.minimum(cKDTree(verts).query(touched)[0], SCALE_CAP)
        inside = np.minimum(field(_transform(inverse, verts)), 0.0)
        return float(np.mean(d ** 2) + np.mean(inside ** 2) * len(verts) / len(touched))

    grid = np.linspace(*SCALE_RANGE, 41)
    best = grid[int(np.argmin([cost(s) for s in grid]))]
    step = grid[1] - grid[0]
    fit = minimize_scalar(cost, bounds=(max(best - step, SCALE_RANGE[0]), min(best + step, SCALE_RANGE[1])),
                          method="bounded", options={"xatol": 1e-4})
    return float(fit.x)


@dataclass(frozen=True)
class GraspCapture:
    """What :func:`capture_grasp` found.

    Attributes
    ----------
    video : VideoCapture
        The hand (its motion refined when a contact map was given).
    object_motion : ObjectMotion
        The object in the camera's frame, every frame.
    scale : float
        The hand's size relative to an average adult's that was used (given, measured or assumed).
    before : HandMotion
        The hand before the refinement with the contact map (the same as ``video.motion`` without one).
    figures : dict
        ``icp_mm`` (median distance of the object's points to its fitted surface, or NaN), and with a
        contact map ``contact_mm`` / ``penetration_mm`` before and after refinement (mean distance of the
        contacted object vertices to the hand's vertices; depth of the deepest hand vertex inside the object,
        as ``handcap metrics`` measures it).
    """

    video: VideoCapture
    object_motion: ObjectMotion
    scale: float
    before: HandMotion
    figures: dict

    def summary(self) -> str:
        """One line of figures."""
        f = self.figures
        parts = [f"hand size {self.scale:.3f}"]
        if np.isfinite(f["icp_mm"]):
            parts.append(f"object points {f['icp_mm']:.2f} mm from its surface")
        if "contact_mm" in f:
            parts.append(f"contact {f['contact_mm'][0]:.1f} -> {f['contact_mm'][1]:.1f} mm, penetration "
                         f"{f['penetration_mm'][0]:.2f} -> {f['penetration_mm'][1]:.2f} mm")
        return ", ".join(parts)


def _contact_figures(hand, motion, frame, contact_map, field, object_pose):
    verts = hand.forward(motion.betas, motion.global_orient[frame], motion.hand_pose[frame],
                         motion.transl[frame]).vertices
    touched = _transform(object_pose, contact_map.vertices[contact_map.contacted])
    d = cKDTree(verts).query(touched)[0] if len(touched) else np.zeros(1)
    depth = -np.minimum(field(_transform(np.linalg.inv(object_pose), verts)), 0.0)
    return verts, 1000 * float(d.mean()), 1000 * float(depth.max())


def capture_grasp(pixels, camera, vertices, faces, *, object_pose=None, object_points=None, frame: int = 0,
                  contact_map: ContactMap | None = None, scale: float | None = None, side: str = "right",
                  hand=None, method: str = "joint", rate: float = 30.0, name: str = "object") -> GraspCapture:
    """Hand and object of a steady grasp from one camera's keypoints, the object's mesh and its pose in one frame.

    Parameters
    ----------
    pixels : ndarray (T, 21, 2)
        Keypoints (see :func:`~handcap.markerless.capture.capture_video`).
    camera : Camera
    vertices, faces : ndarray
        The object's mesh in its frame, metres.
    object_pose : ndarray (4, 4), optional
        Object to camera in ``frame``: the pose, or the start of ICP when ``object_points`` are given.
    object_points : ndarray (N, 3), optional
        The object's surface in ``frame``'s camera, metres.
    frame : int
        The frame the object was measured in.
    contact_map : ContactMap, optional
        Which of the object's vertices the hand touched (its vertices are the object's mesh): measures the
        hand's size (unless ``scale`` is given) and refines the grasp.
    scale : float, optional
        The hand's size relative to an average adult's (default: measured with a contact map, else 1).
    side, hand, method, rate
        As :func:`~handcap.markerless.capture.capture_video`.
    name : str
        The object's name in its motion.

    Returns
    -------
    GraspCapture

    Raises
    ------
    HandcapError
        Neither a pose nor points for the object, or a frame out of range or with too few keypoints.
    """
    pixels = np.asarray(pixels, dtype=np.float64)
    if not 0 <= frame < len(pixels):
        raise HandcapError(f"object frame {frame} is outside the video's {len(pixels)} frames")
    if object_pose is None and object_points is None:
        raise HandcapError("the object needs its pose or points of its surface in one frame")
    if object_pose is not None:
        object_pose = np.asarray(object_pose, dtype=np.float64)
        if object_pose.shape != (4, 4) or not np.isfinite(object_pose).all() or \
                not np.allclose(object_pose[:3, :3] @ object_pose[:3, :3].T, np.eye(3), atol=1e-4):
            raise HandcapError("the object's pose must be a 4 x 4 rigid transform (a rotation and metres)")
    hand = OpenHand(side) if hand is None else hand
    found, icp = [], float("nan")
    if object_points is not None:
        object_pose, distance, notes = object_pose_from_points(vertices, faces, object_points, object_pose)
        found += notes
        icp = 1000 * distance
    video = capture_video(pixels, camera, hand=hand, method=method, rate=rate, scale=scale or 1.0)
    if not video.structure.placed[frame]:
        raise HandcapError(f"frame {frame}, where the object was measured, has too few keypoints to place the hand")
    used = scale or 1.0
    figures = {"icp_mm": icp}
    field = None if contact_map is None else ObjectField(contact_map.vertices, contact_map.faces)
    if contact_map is not None and scale is None:
        for _ in range(2):  # the size feeds the solve non-linearly: once more from the first measure
            verts = hand.forward(video.motion.betas, video.motion.global_orient[frame], video.motion.hand_pose[frame],
                                 video.motion.transl[frame]).vertices
            factor = scale_from_contact(verts, contact_map, object_pose, field)
            if abs(factor - 1.0) < 0.005:
                break
            used = float(np.clip(used * factor, 0.5, 2.0))
            video = capture_video(pixels, camera, hand=hand, method=method, rate=rate, scale=used)
        if abs(used - 1.0) > 0.25:
            found.append(f"the hand's size measured against the object's contacts is {used:.2f} times an average "
                         f"adult's: check the object's units and pose")
    elif scale is None:
        found.append("the hand's size is assumed average (no contact map to measure it against the object): the "
                     "object's place in the frames depends on it; give the hand's scale if known")
    poses = hand_poses(video.motion, hand)
    motion = video.motion
    if contact_map is not None:
        _, c0, p0 = _contact_figures(hand, motion, frame, contact_map, field, object_pose)
        phi, orient, transl = refine_grasp(hand, motion.betas, motion.phi[frame], motion.global_orient[frame],
                                           motion.transl[frame], contact_map, object_pose, field=field)
        refined = _model_poses(hand, motion.betas, orient, transl)
        moved = poses @ (np.linalg.inv(poses[frame]) @ refined)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", HandcapWarning)
            offsets = video.structure.points - template_points(hand, motion.betas, motion.phi[frame])
            new = video_motion(hand, motion.betas, phi, Rotation.from_matrix(moved[:, :3, :3]).as_rotvec(),
                               moved[:, :3, 3], motion.rate, offsets)
        motion = replace(new, warnings=motion.warnings)
        _, c1, p1 = _contact_figures(hand, motion, frame, contact_map, field, object_pose)
        figures.update(contact_mm=(c0, c1), penetration_mm=(p0, p1))
    carried = carry_object(poses, frame, object_pose)
    obj = ObjectMotion(Rotation.from_matrix(carried[:, :3, :3]).as_rotvec(), carried[:, :3, 3], motion.rate, name)
    motion = attach(motion, found)
    obj = obj.with_warnings(*found) if found else obj
    return GraspCapture(replace(video, motion=motion), obj, used, video.motion, figures)
