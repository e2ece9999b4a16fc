"""Grasp refinement with an observed contact map (the paper's Stage 5, after ContactGrasp).

A contact map says, for every vertex of the object's mesh, whether the hand touched it (ContactDB
captures it with a thermal camera after the grasp). Given a grasp estimated from keypoints, the hand's
pose is refined so that it agrees with the map:

* **attraction**: every contacted object vertex is pulled to the nearest hand vertex;
* **repulsion**: an object vertex not contacted that the hand comes closer to than :data:`MARGIN` is
  pushed away;
* **penetration**: a hand vertex inside the object is pushed out (the object's signed distance to
  the plane of its nearest surface sample, :class:`ObjectField`);
* **staying put**: the pose may move only as far as the contacts ask (a weak pull to the estimate).

The 27 angles and the global pose are solved by ``scipy.optimize.least_squares`` (the hand's shape is
kept). Object and hand are in one frame, metres.

Contact map file (``.npz``): ``vertices (V, 3)`` metres and ``faces (F, 3)`` of the object's mesh in the
object's frame, ``contact (V,)`` between 0 and 1 (a vertex counts as contacted from 0.5), and optionally
``warnings``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import trimesh
from scipy.optimize import least_squares
from scipy.spatial import cKDTree

from handcap.core.errors import HandcapError
from handcap.core.files import load_npz, save_npz
from handcap.core.geometry import closest_points_on_mesh

#: Object vertices not contacted are pushed to at least this far from the hand, metres.
MARGIN = 0.002
#: Weights of the residuals (metres of residual per metre of distance), and of the pull to the estimate
#: (metres per radian, metres per metre). The angles' pull, 0.03 m per radian (10 degrees cost like 5 mm of
#: contact distance), was the middle of 0.01 / 0.03 / 0.1 tried on synthetic power and precision grasps
#: (angles 5 degrees off): at 0.01 the fingers bent wrongly to reach contacts (angle error 3.3 -> 4.5
#: degrees), at 0.1 the contacts were met less (1.31 against 1.20 mm).
ATTRACT, REPEL, PENETRATE, STAY_ANGLE, STAY_POSE = 1.0, 1.0, 3.0, 0.03, 0.3
#: Spacing of the samples of the object's surface its signed distance is measured to, metres.
SAMPLE_SPACING = 0.001


@dataclass(frozen=True)
class ContactMap:
    """An object's mesh and which of its vertices the hand touched.

    Attributes
    ----------
    vertices : ndarray (V, 3)
        Object frame, metres.
    faces : ndarray (F, 3) int
    contact : ndarray (V,)
        0..1; contacted from 0.5.
    """

    vertices: np.ndarray
    faces: np.ndarray
    contact: np.ndarray

    def __post_init__(self):
        v = np.asarray(self.vertices, dtype=np.float64)
        f = np.asarray(self.faces)
        c = np.asarray(self.contact, dtype=np.float64)
        if v.ndim != 2 or v.shape[1] != 3 or not np.isfinite(v).all():
            raise HandcapError(f"contact map: vertices must be finite (V, 3) metres, got {v.shape}")
        if f.ndim != 2 or f.shape[1] != 3 or f.dtype.kind not in "iu" or \
                (len(f) and (f.min() < 0 or f.max() >= len(v))):
            raise HandcapError("contact map: faces must be (F, 3) vertex indices")
        if c.shape != (len(v),) or not np.isfinite(c).all() or (c < 0).any() or (c > 1).any():
            raise HandcapError(f"contact map: contact must be {len(v)} values between 0 and 1, got {c.shape}")
        if len(v) and np.ptp(v, axis=0).max() > 2.0:
            raise HandcapError(f"contact map: the object is {np.ptp(v, axis=0).max():.3g} m across: are its vertices "
                               f"in metres?")
        object.__setattr__(self, "vertices", v)
        object.__setattr__(self, "faces", f.astype(np.int64))
        object.__setattr__(self, "contact", c)

    @property
    def contacted(self) -> np.ndarray:
        """(V,) bool."""
        return self.contact >= 0.5

    def save(self, path) -> None:
        """Write the ``.npz`` of the module docstring (atomically)."""
        save_npz(path, {"vertices": self.vertices, "faces": self.faces, "contact": self.contact})

    @classmethod
    def load(cls, path) -> "ContactMap":
        """Read a contact map ``.npz``."""
        data = load_npz(path, ("vertices", "faces", "contact"), what="contact map")
        return cls(data["vertices"], data["faces"], data["contact"])


class ObjectField:
    """An object's signed distance (negative inside) near its surface, metres.

    The surface is sampled about every :data:`SAMPLE_SPACING`; the sample nearest a point gives the side (its
    face normal), and the distance: to the sample's plane inside (exact on flat parts), to the sample itself
    outside (within about half the spacing, also beyond convex edges). Meant for points near the surface,
    those that matter here.

    Parameters
    ----------
    vertices, faces : ndarray
        A closed, outward-facing mesh, object frame, metres.
    spacing : float
        Metres between surface samples.
    """

    def __init__(self, vertices, faces, spacing: float = SAMPLE_SPACING):
        mesh = trimesh.Trimesh(vertices, faces, process=False)
        count = int(np.clip(mesh.area / spacing ** 2, 100, 400_000))
        points, face = trimesh.sample.sample_surface_even(mesh, count, seed=0)
        self.points, self.normals = points, mesh.face_normals[face]
        self.tree = cKDTree(points)

    def __call__(self, points, nearest=None) -> np.ndarray:
        """Signed distance (...,) of points (..., 3) in the object frame, metres (negative inside).

        ``nearest`` (N,) gives the index of each point's surface sample (:meth:`nearest`) instead of searching:
        for points moved too little to change it (the steps of a numerical derivative), broadcast over
        the leading axes of ``points`` (..., N, 3).
        """
        points = np.asarray(points, dtype=np.float64)
        idx = self.nearest(points) if nearest is None else nearest
        away = points - self.points[idx]
        euclid = np.linalg.norm(away, axis=-1)
        plane = np.einsum("...j,...j->...", away, self.normals[idx])
        # outside, beyond a convex edge the plane distance falls short: the distance to the sample is the one
        return np.where(plane > 0, euclid, plane)

    def nearest(self, points) -> np.ndarray:
        """Index (...,) of the surface sample nearest each point (..., 3), object frame."""
        return self.tree.query(np.asarray(points, dtype=np.float64))[1]


def refine_grasp(hand, betas, phi, orient, transl, contact_map: ContactMap, object_pose=None, *,
                 iterations: int = 30, field: ObjectField | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Refine one hand pose against an object's contact map.

    Parameters
    ----------
    hand : HandModel
    betas : ndarray (10,)
    phi : ndarray (27,)
        The estimated angles, radians.
    orient, transl : ndarray (3,)
        The estimated MANO global orientation (axis-angle) and translation, metres, in the world.
    contact_map : ContactMap
    object_pose : ndarray (4, 4), optional
        Object frame to world (default: identity).
    iterations : int
        Most evaluations of the least squares.
    field : ObjectField, optional
        The contact map's object field, where the caller has made it (it is slow to make).

    Returns
    -------
    phi, orient, transl : ndarrays (27,), (3,), (3,)
    """
    pose = np.eye(4) if object_pose is None else np.asarray(object_pose, dtype=np.float64)
    obj_world = contact_map.vertices @ pose[:3, :3].T + pose[:3, 3]
    field = ObjectField(contact_map.vertices, contact_map.faces) if field is None else field
    start = np.r_[np.asarray(orient, dtype=np.float64), np.asarray(transl, dtype=np.float64), phi]
    touched, free = obj_world[contact_map.contacted], obj_world[~contact_map.contacted]
    # only the uncontacted vertices the hand can reach matter (within 3 cm of its start)
    near_start = cKDTree(hand.forward(betas, start[:3], None, start[3:6], phi=start[6:]).vertices)
    free = free[np.isfinite(near_start.query(free, distance_upper_bound=0.03)[0])]
    world_to_object = np.linalg.inv(pose)
    scale = np.r_[[STAY_POSE * 0.05] * 3, [STAY_POSE] * 3, [STAY_ANGLE] * 27]

    def vertices(p):  # (..., 33) -> (..., V, 3)
        return hand.forward(betas, p[..., :3], None, p[..., 3:6], phi=p[..., 6:]).vertices

    def in_object(verts):
        return verts @ world_to_object[:3, :3].T + world_to_object[:3, 3]

    def pairs(verts):
        """Each contacted vertex's nearest hand vertex, the hand vertices within the margin of the others, and
        each hand vertex's nearest sample of the object's surface."""
        tree = cKDTree(verts)
        touch = tree.query(touched)[1] if len(touched) else np.zeros(0, int)
        near, close = tree.query(free, distance_upper_bound=MARGIN) if len(free) else (np.zeros(0), np.zeros(0, int))
        return touch, np.isfinite(near), np.minimum(close, len(verts) - 1), field.nearest(in_object(verts))

    def terms(verts, p, touch, active, close, surface):
        """The residuals of hand vertices ``verts`` (..., V, 3) with these nearest pairs, for parameters p (..., 33)."""
        d_touch = np.linalg.norm(verts[..., touch, :] - touched, axis=-1)
        repel = np.where(active, MARGIN - np.linalg.norm(verts[..., close, :] - free, axis=-1), 0.0)
        inside = field(in_object(verts), surface)
        stay = scale * (p - start)  # the pull to the estimate: 0.05 m of lever per radian of global turn
        return np.concatenate([ATTRACT * d_touch, REPEL * repel, PENETRATE * np.minimum(inside, 0.0), stay], axis=-1)

    last = {}  # the nearest pairs of the parameters last evaluated: the solver asks the Jacobian there next

    def residual(p):
        verts = vertices(p)
        last["p"], last["pairs"] = p.copy(), pairs(verts)
        return terms(verts, p, *last["pairs"])

    def jacobian(p):
        # Forward differences of all 33 parameters in one batched pass of the hand, each with the nearest
        # pairs of p (a step this small moves no vertex past another); the pull to the estimate is linear.
        step = 1e-5 * np.maximum(1.0, np.abs(p))
        shifted = p + np.diag(step)
        verts = vertices(np.vstack([p, shifted]))
        same = "p" in last and np.array_equal(last["p"], p)
        found = terms(verts, np.vstack([p, shifted]), *(last["pairs"] if same else pairs(verts[0])))
        return ((found[1:] - found[0]) / step[:, None]).T

    fit = least_squares(residual, start, jac=jacobian, max_nfev=iterations,
                        x_scale=np.r_[[0.05] * 3, [0.005] * 3, [0.05] * 27])
    return fit.x[6:], fit.x[:3], fit.x[3:6]


def contact_figures(hand_vertices, hand_faces, contact_map: ContactMap, signed_distance, object_pose=None) -> dict:
    """Penetration and contact distance of a posed hand against an object, against exact geometry.

    Parameters
    ----------
    hand_vertices : ndarray (V, 3)
        World, metres.
    hand_faces : ndarray (F, 3)
    contact_map : ContactMap
        Which object vertices are truly in contact.
    signed_distance : callable
        The object's exact signed distance (points in its frame, negative inside), metres.
    object_pose : ndarray (4, 4), optional
        Object frame to world.

    Returns
    -------
    dict
        ``penetration_mm`` (mean depth of the hand vertices inside the object, 0 for none), ``penetration_max_mm``,
        ``contact_mm`` and ``contact_std_mm`` (distance of each truly contacted object vertex to the hand's
        surface, mean and standard deviation).
    """
    pose = np.eye(4) if object_pose is None else np.asarray(object_pose, dtype=np.float64)
    inv = np.linalg.inv(pose)
    depth = -np.minimum(signed_distance(hand_vertices @ inv[:3, :3].T + inv[:3, 3]), 0.0)
    touched = (contact_map.vertices @ pose[:3, :3].T + pose[:3, 3])[contact_map.contacted]
    closest = closest_points_on_mesh(touched, hand_vertices, hand_faces)[0] if len(touched) else touched
    dist = np.linalg.norm(closest - touched, axis=1) if len(touched) else np.zeros(1)
    return {"penetration_mm": 1000 * float(depth.mean()), "penetration_max_mm": 1000 * float(depth.max()),
            "contact_mm": 1000 * float(dist.mean()), "contact_std_mm": 1000 * float(dist.std())}
