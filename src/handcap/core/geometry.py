"""Geometry on triangle meshes: closest points, signed distances, ray and triangle intersection tests.

Vectorised numpy over points and triangles; meshes are ``vertices (V, 3)``
and ``faces (F, 3)`` int arrays. Signed distances are libigl's (an AABB tree in C++).
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from handcap.core.errors import HandcapError


def closest_points_on_triangles(points, triangles):
    """Closest point of each triangle to each matching point.

    Parameters
    ----------
    points : ndarray (N, 3)
    triangles : ndarray (N, 3, 3)
        Triangle n's corners, matched with point n.

    Returns
    -------
    closest : ndarray (N, 3)
    barycentric : ndarray (N, 3)
        Weights of the three corners; non-negative, summing to one.

    References
    ----------
    Ericson C. (2004) Real-Time Collision Detection, section 5.1.5.
    """
    p = np.asarray(points, dtype=np.float64)
    tri = np.asarray(triangles, dtype=np.float64)
    a, b, c = tri[:, 0], tri[:, 1], tri[:, 2]
    ab, ac, ap = b - a, c - a, p - a
    d1, d2 = (ab * ap).sum(1), (ac * ap).sum(1)
    bp = p - b
    d3, d4 = (ab * bp).sum(1), (ac * bp).sum(1)
    cp = p - c
    d5, d6 = (ab * cp).sum(1), (ac * cp).sum(1)
    va = d3 * d6 - d5 * d4
    vb = d5 * d2 - d1 * d6
    vc = d1 * d4 - d3 * d2
    with np.errstate(divide="ignore", invalid="ignore"):
        denom = va + vb + vc
        v_in, w_in = vb / denom, vc / denom
        t_ab = d1 / (d1 - d3)
        t_ac = d2 / (d2 - d6)
        t_bc = (d4 - d3) / ((d4 - d3) + (d5 - d6))
    bary = np.stack([1 - v_in - w_in, v_in, w_in], axis=1)
    # Region tests in Ericson's order; later assignments take priority as written there.
    regions = [
        ((vc <= 0) & (d1 >= 0) & (d3 <= 0), np.stack([1 - t_ab, t_ab, 0 * t_ab], 1)),  # edge AB
        ((vb <= 0) & (d2 >= 0) & (d6 <= 0), np.stack([1 - t_ac, 0 * t_ac, t_ac], 1)),  # edge AC
        ((va <= 0) & ((d4 - d3) >= 0) & ((d5 - d6) >= 0), np.stack([0 * t_bc, 1 - t_bc, t_bc], 1)),  # BC
        ((d6 >= 0) & (d5 <= d6), np.tile([0.0, 0.0, 1.0], (len(p), 1))),  # vertex C
        ((d3 >= 0) & (d4 <= d3), np.tile([0.0, 1.0, 0.0], (len(p), 1))),  # vertex B
        ((d1 <= 0) & (d2 <= 0), np.tile([1.0, 0.0, 0.0], (len(p), 1))),  # vertex A
    ]
    for mask, value in regions:
        bary[mask] = value[mask]
    bary = np.nan_to_num(bary, nan=1.0 / 3.0)
    closest = np.einsum("nk,nki->ni", bary, tri)
    return closest, bary


def closest_points_on_mesh(points, vertices, faces, candidates: int = 16):
    """Closest surface point of a triangle mesh to each point.

    Parameters
    ----------
    points : ndarray (N, 3)
    vertices : ndarray (V, 3)
    faces : ndarray (F, 3)
    candidates : int
        Triangles tried per point: those whose centroids are nearest. Exact for
        meshes with even triangle sizes (such as hand meshes) when the point is
        close to the surface; raise it for far points or uneven meshes.

    Returns
    -------
    closest : ndarray (N, 3)
    face : ndarray (N,) int
    barycentric : ndarray (N, 3)
    """
    points = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    tri = np.asarray(vertices, dtype=np.float64)[np.asarray(faces)]
    k = min(candidates, len(tri))
    _, idx = cKDTree(tri.mean(axis=1)).query(points, k=k)
    idx = idx.reshape(len(points), k)
    closest, bary = closest_points_on_triangles(np.repeat(points, k, axis=0), tri[idx.ravel()])
    dist = np.linalg.norm(closest - np.repeat(points, k, axis=0), axis=1).reshape(len(points), k)
    best = dist.argmin(axis=1)
    rows = np.arange(len(points)) * k + best
    return closest[rows], idx[np.arange(len(points)), best], bary[rows]


def check_mesh(vertices, faces) -> tuple[np.ndarray, np.ndarray]:
    """A triangle mesh as contiguous float64 vertices and int64 faces, checked.

    Parameters
    ----------
    vertices : array_like (V, 3)
    faces : array_like (F, 3) int

    Returns
    -------
    vertices : ndarray (V, 3) float64
    faces : ndarray (F, 3) int64

    Raises
    ------
    HandcapError
        Vertices that are not finite (V, 3) coordinates, or faces that are not (F, 3) indices of them.
    """
    vertices = np.ascontiguousarray(vertices, dtype=np.float64)
    faces = np.asarray(faces)
    if faces.size == 0:
        faces = np.zeros((0, 3), np.int64)
    if vertices.ndim != 2 or vertices.shape[1] != 3:
        raise HandcapError(f"a mesh's vertices must be (V, 3) coordinates, got shape {vertices.shape}")
    if not np.isfinite(vertices).all():
        raise HandcapError(f"{int((~np.isfinite(vertices)).any(axis=1).sum())} of the mesh's {len(vertices)} "
                           "vertices are NaN or infinite")
    if faces.ndim != 2 or faces.shape[1] != 3 or not np.issubdtype(faces.dtype, np.integer):
        raise HandcapError(f"a mesh's faces must be (F, 3) vertex indices, got {faces.dtype} of shape {faces.shape}")
    if len(faces) and (faces.min() < 0 or faces.max() >= len(vertices)):
        raise HandcapError(f"the mesh's faces index vertices {faces.min()} to {faces.max()}, but it has "
                           f"{len(vertices)} (0 to {len(vertices) - 1})")
    return vertices, np.ascontiguousarray(faces, dtype=np.int64)


def signed_distance(points, vertices, faces) -> np.ndarray:
    """Signed distance of each point to a closed triangle mesh, positive inside (trimesh's sign).

    The distance is exact (libigl's closest points on an AABB tree); the side is the generalised winding number's,
    which stays right for a mesh with small holes. A mesh whose faces are wound inwards (a negative volume) is
    turned the right way round first, so that its inside is still inside.

    Parameters
    ----------
    points : ndarray (N, 3)
        In the mesh's frame and unit (metres); NaN for missing.
    vertices : ndarray (V, 3)
    faces : ndarray (F, 3) int

    Returns
    -------
    ndarray (N,)
        Same unit as the points; NaN for a missing point, ``-inf`` for every point when the mesh has no faces.

    Raises
    ------
    HandcapError
        Vertices that are not finite (V, 3) coordinates, or faces that are not (F, 3) indices of them.

    References
    ----------
    Jacobson A., Kavan L., Sorkine-Hornung O. (2013) Robust inside-outside segmentation using generalized winding
    numbers. ACM Transactions on Graphics 32(4).
    """
    import igl  # noqa: PLC0415 (a compiled library: loaded where a mesh is measured)

    points = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 3)
    vertices, faces = check_mesh(vertices, faces)  # libigl reads where a bad index points: a crash, not an error
    if len(faces) == 0:
        return np.where(np.isfinite(points).all(axis=1), -np.inf, np.nan)
    a, b, c = (vertices[faces[:, k]] for k in range(3))
    if np.einsum("ij,ij->", a, np.cross(b, c)) < 0:  # six times the signed volume: wound inwards
        faces = np.ascontiguousarray(faces[:, ::-1])
    out = np.full(len(points), np.nan)
    seen = np.isfinite(points).all(axis=1)
    if seen.any():
        query = np.ascontiguousarray(points[seen])
        side, _, closest, _ = igl.signed_distance(query, vertices, faces,
                                                  sign_type=igl.SIGNED_DISTANCE_TYPE_WINDING_NUMBER)
        # The winding number's side only, and the distance to the closest point: libigl scales its distance by
        # 1 - 2 w, which is not +-1 where the mesh is open (w fractional).
        out[seen] = np.where(side < 0, 1.0, -1.0) * np.linalg.norm(query - closest, axis=1)  # its side: < 0 inside
    return out


def segments_cross_triangles(starts, ends, triangles, eps: float = 1e-12) -> np.ndarray:
    """Whether each segment crosses its matching triangle (Moller-Trumbore).

    Parameters
    ----------
    starts, ends : ndarray (N, 3)
    triangles : ndarray (N, 3, 3)

    Returns
    -------
    hit : ndarray (N,) bool
        True where the open segment meets the triangle's interior or edges.
    """
    # Components as columns (N,) each: NumPy is slow on reductions over axes of length 3.
    e1, e2 = (triangles[:, 1] - triangles[:, 0]).T, (triangles[:, 2] - triangles[:, 0]).T
    d, tvec = (ends - starts).T, (starts - triangles[:, 0]).T

    def cross(x, y):
        return x[1] * y[2] - x[2] * y[1], x[2] * y[0] - x[0] * y[2], x[0] * y[1] - x[1] * y[0]

    def dot(x, y):
        return x[0] * y[0] + x[1] * y[1] + x[2] * y[2]

    pvec = cross(d, e2)
    det = dot(e1, pvec)
    ok = np.abs(det) > eps
    inv = np.where(ok, 1.0 / np.where(ok, det, 1.0), 0.0)
    u = dot(tvec, pvec) * inv
    qvec = cross(tvec, e1)
    v = dot(d, qvec) * inv
    t = dot(e2, qvec) * inv
    return ok & (u >= 0) & (v >= 0) & (u + v <= 1) & (t > 0) & (t < 1)


def self_intersections(vertices, faces) -> np.ndarray:
    """Pairs of triangles of one mesh that cross each other.

    Triangles sharing a vertex are not compared (they always touch). Two
    triangles cross when an edge of one passes through the other; exactly
    coplanar overlaps are not reported.

    Parameters
    ----------
    vertices : array_like of shape (V, 3)
        Vertex positions, metres (any length unit works: the test is scale-free).
    faces : array_like of shape (F, 3) int
        Vertex indices of each triangle.

    Returns
    -------
    pairs : ndarray (P, 2) int
        Face indices, first < second.
    """
    vertices = np.asarray(vertices, dtype=np.float64)
    faces = np.asarray(faces)
    tri = vertices[faces]
    centroid = tri.mean(axis=1)
    radius = np.linalg.norm(tri - centroid[:, None], axis=2).max()
    pairs = cKDTree(centroid).query_pairs(2 * radius, output_type="ndarray")
    if len(pairs) == 0:
        return np.zeros((0, 2), int)
    shared = (faces[pairs[:, 0]][:, :, None] == faces[pairs[:, 1]][:, None, :]).any(axis=(1, 2))
    pairs = pairs[~shared]
    hit = np.zeros(len(pairs), bool)
    for first, second in ((0, 1), (1, 0)):
        ta, tb = tri[pairs[:, first]], tri[pairs[:, second]]
        for i, j in ((0, 1), (1, 2), (2, 0)):
            hit |= segments_cross_triangles(ta[:, i], ta[:, j], tb)
    return np.sort(pairs[hit], axis=1)
