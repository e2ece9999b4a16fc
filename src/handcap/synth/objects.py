"""Objects the synthetic hand manipulates: meshes, signed distances, markers.

Each object lives in its own frame (metres, origin at its centre) and carries
a handful of markers on its surface, as an object tracked by a capture system
would (at least four, never all coplanar). :func:`random_blobs` makes the
occluders of rendered images (a sleeve, the other hand, a tool).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import trimesh

from handcap.core.errors import HandcapError

OBJECTS = ("cuboid", "cylinder", "sphere", "cube2x2")


@dataclass(frozen=True, eq=False)
class SynthObject:
    """A rigid object.

    Attributes
    ----------
    name : str
    kind : str
        One of :data:`OBJECTS`.
    size : ndarray (3,)
        Box half-extents; for a cylinder (radius, radius, half-height), for a
        sphere (radius,)*3. Metres.
    vertices, faces : ndarrays (V, 3), (F, 3)
        Closed surface in the object frame.
    marker_positions : ndarray (K, 3)
        Marker centres in the object frame (on the surface plus the radius).
    marker_normals : ndarray (K, 3)
    marker_radius : float
    """

    name: str
    kind: str
    size: np.ndarray
    vertices: np.ndarray
    faces: np.ndarray
    marker_positions: np.ndarray
    marker_normals: np.ndarray
    marker_radius: float = 0.004

    @property
    def marker_names(self) -> tuple[str, ...]:
        """Marker names ``<name>_0``, ``<name>_1``, ... (K,), in the order of ``marker_positions``."""
        return tuple(f"{self.name}_{i}" for i in range(len(self.marker_positions)))

    def signed_distance(self, points) -> np.ndarray:
        """Signed distance (metres, negative inside) of object-frame points (..., 3)."""
        p = np.asarray(points, dtype=np.float64)
        if self.kind == "sphere":
            return np.linalg.norm(p, axis=-1) - self.size[0]
        if self.kind == "cylinder":  # axis along z
            radial = np.linalg.norm(p[..., :2], axis=-1) - self.size[0]
            axial = np.abs(p[..., 2]) - self.size[2]
            outside = np.hypot(np.maximum(radial, 0), np.maximum(axial, 0))
            return outside + np.minimum(np.maximum(radial, axial), 0)
        q = np.abs(p) - self.size  # box (cuboid and the 2x2x2 cube's outline)
        return np.linalg.norm(np.maximum(q, 0), axis=-1) + np.minimum(q.max(axis=-1), 0)


def _box_markers(half, radius, rng):
    """Two markers on each of the six faces at random spots away from the edges."""
    points, normals = [], []
    for axis in range(3):
        for sign in (-1.0, 1.0):
            for _ in range(2):
                p = rng.uniform(-0.6, 0.6, 3) * half
                p[axis] = sign * (half[axis] + radius)
                n = np.zeros(3)
                n[axis] = sign
                points.append(p)
                normals.append(n)
    return np.array(points), np.array(normals)


def make_object(kind: str, *, seed: int = 0, scale: float = 1.0) -> SynthObject:
    """One of the standard objects.

    ``cuboid`` 5 x 7 x 12 cm, ``cylinder`` 7 cm across and 12 cm long (a
    drinking glass), ``sphere`` 6 cm across (a ball), ``cube2x2`` a 5.6 cm
    2x2x2 puzzle cube made of eight 2.8 cm cubies.

    Parameters
    ----------
    kind : str
        One of :data:`OBJECTS`; also the object's name.
    seed : int
        Seeds where the markers go (12 on a box, 10 on the cylinder, 8 on the sphere).
    scale : float
        Size factor, 0.2 to 5 (the markers' 4 mm radius is not scaled).

    Returns
    -------
    SynthObject
        Mesh and markers in the object frame, metres.

    Raises
    ------
    HandcapError
        An unknown kind or a scale out of range.
    """
    if kind not in OBJECTS:
        raise HandcapError(f"unknown object {kind!r}; choose one of {', '.join(OBJECTS)}")
    if not 0.2 <= scale <= 5:
        raise HandcapError(f"object scale must be between 0.2 and 5, got {scale}")
    rng = np.random.default_rng(seed)
    radius = 0.004
    if kind == "cuboid":
        half = np.array([0.025, 0.035, 0.06]) * scale
        mesh = trimesh.creation.box(extents=2 * half)
        markers, normals = _box_markers(half, radius, rng)
    elif kind == "cube2x2":
        half = np.full(3, 0.028) * scale
        move = trimesh.transformations.translation_matrix
        cubies = [trimesh.creation.box(extents=np.full(3, 0.0275 * scale), transform=move(np.array(c) * 0.014 * scale))
                  for c in np.array(np.meshgrid([-1, 1], [-1, 1], [-1, 1])).reshape(3, -1).T]
        mesh = trimesh.util.concatenate(cubies)
        markers, normals = _box_markers(half, radius, rng)
    elif kind == "cylinder":
        r, h = 0.035 * scale, 0.06 * scale
        half = np.array([r, r, h])
        mesh = trimesh.creation.cylinder(radius=r, height=2 * h, sections=48)
        angles = rng.uniform(0, 2 * np.pi, 8)
        heights = rng.uniform(-0.8, 0.8, 8) * h
        normals = np.c_[np.cos(angles), np.sin(angles), np.zeros(8)]
        markers = normals * (r + radius) + np.c_[np.zeros((8, 2)), heights]
        markers = np.vstack([markers, [[0, 0, h + radius], [0.5 * r, 0, -h - radius]]])
        normals = np.vstack([normals, [[0, 0, 1.0], [0, 0, -1.0]]])
    else:
        r = 0.03 * scale
        half = np.full(3, r)
        mesh = trimesh.creation.icosphere(subdivisions=3, radius=r)
        normals = rng.normal(size=(8, 3))
        normals /= np.linalg.norm(normals, axis=1, keepdims=True)
        markers = normals * (r + radius)
    return SynthObject(kind, kind, half, np.asarray(mesh.vertices, dtype=np.float64),
                       np.asarray(mesh.faces, dtype=np.int64), markers, normals, radius)


def random_blobs(vertices, rng, count: int, towards=None) -> list:
    """``count`` ellipsoids 1-3 cm across near the hand: occluders (a sleeve, the other hand, a tool).

    Parameters
    ----------
    vertices : ndarray (V, 3)
        The hand mesh, metres.
    rng : numpy.random.Generator
    count : int
    towards : ndarray (3,), optional
        A unit direction (to a camera) to move the blobs along, 3-12 cm off the skin; default: any
        direction, 1-6 cm off.

    Returns
    -------
    list of (ndarray (V, 3), ndarray (F, 3))
    """
    sphere = trimesh.creation.icosphere(subdivisions=2)
    vertices = np.asarray(vertices, dtype=np.float64)
    extent = np.ptp(vertices, axis=0).max() / 2
    blobs = []
    for _ in range(count):
        spot = vertices[rng.integers(len(vertices))] + rng.normal(0, 0.3 * extent, 3)
        if towards is None:
            way = rng.normal(size=3)
            where = spot + way / np.linalg.norm(way) * rng.uniform(0.01, 0.06)
        else:
            where = spot + np.asarray(towards) * rng.uniform(0.03, 0.12)
        radii = rng.uniform(0.01, 0.03, 3)
        blobs.append((np.asarray(sphere.vertices) * radii + where, np.asarray(sphere.faces)))
    return blobs
