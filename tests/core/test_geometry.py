import numpy as np
import trimesh

from handcap.core.geometry import (
    closest_points_on_mesh,
    closest_points_on_triangles,
    segments_cross_triangles,
    self_intersections,
)


def test_closest_points_against_trimesh():
    rng = np.random.default_rng(0)
    mesh = trimesh.creation.icosphere(subdivisions=3, radius=0.05)
    mesh.vertices *= [1.0, 0.6, 1.4]
    points = rng.normal(scale=0.05, size=(300, 3))
    closest, face, bary = closest_points_on_mesh(points, mesh.vertices, mesh.faces, candidates=64)
    ref, dist, _ = trimesh.proximity.closest_point(mesh, points)
    np.testing.assert_allclose(np.linalg.norm(closest - points, axis=1), dist, atol=1e-12)
    np.testing.assert_allclose(np.einsum("nk,nki->ni", bary, mesh.vertices[mesh.faces[face]]), closest, atol=1e-14)
    assert (bary >= -1e-12).all()
    np.testing.assert_allclose(bary.sum(1), 1.0)


def test_closest_point_regions_of_one_triangle():
    tri = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0]])
    pts = np.array([[0.2, 0.2, 1.0], [-1, -1, 0], [2, -0.5, 0], [0.5, -1, 0], [1, 1, 0], [-1, 0.5, 3]])
    closest, _ = closest_points_on_triangles(pts, np.repeat(tri[None], len(pts), 0))
    np.testing.assert_allclose(closest, [[0.2, 0.2, 0], [0, 0, 0], [1, 0, 0], [0.5, 0, 0], [0.5, 0.5, 0], [0, 0.5, 0]])


def test_segment_triangle_crossing():
    tri = np.array([[[0.0, 0, 0], [1, 0, 0], [0, 1, 0]]] * 3)
    starts = np.array([[0.2, 0.2, -1], [0.2, 0.2, 0.5], [2, 2, -1]])
    ends = np.array([[0.2, 0.2, 1], [0.2, 0.2, 2], [2, 2, 1]])
    np.testing.assert_array_equal(segments_cross_triangles(starts, ends, tri), [True, False, False])


def test_self_intersections_found_only_where_made():
    sphere = trimesh.creation.icosphere(subdivisions=2)
    assert len(self_intersections(sphere.vertices, sphere.faces)) == 0
    vertices = sphere.vertices.copy()
    vertices[0] = -vertices[0] * 1.5  # push one vertex through the far side
    assert len(self_intersections(vertices, sphere.faces)) > 0
