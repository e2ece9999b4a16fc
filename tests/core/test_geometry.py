import re

import numpy as np
import pytest
import trimesh

from handcap import HandcapError
from handcap.core.geometry import (
    closest_points_on_mesh,
    closest_points_on_triangles,
    segments_cross_triangles,
    self_intersections,
    signed_distance,
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


def test_signed_distance_to_a_box_is_exact_and_positive_inside():
    # A box's signed distance in closed form: inside, the depth to the nearest face; outside, the distance to the box.
    half = np.array([0.03, 0.02, 0.01])
    box = trimesh.creation.box(extents=2 * half)
    rng = np.random.default_rng(4)
    points = rng.uniform(-2 * half, 2 * half, size=(2000, 3))
    excess = np.abs(points) - half
    truth = np.where((excess < 0).all(axis=1), -excess.max(axis=1), -np.linalg.norm(np.maximum(excess, 0), axis=1))
    np.testing.assert_allclose(signed_distance(points, box.vertices, box.faces), truth, atol=1e-12)
    # The faces wound inwards (a negative volume): the inside is still inside.
    np.testing.assert_allclose(signed_distance(points, box.vertices, box.faces[:, ::-1]), truth, atol=1e-12)
    # A missing point gives NaN, and a mesh without faces leaves every point outside.
    points[3] = np.nan
    out = signed_distance(points, box.vertices, box.faces)
    assert np.isnan(out[3]) and np.isfinite(np.delete(out, 3)).all()
    assert (signed_distance(points[:2], box.vertices, np.zeros((0, 3), int)) == -np.inf).all()


@pytest.mark.parametrize("vertices, faces, said", [
    (np.zeros((4, 3)), [[0, 1, 2], [0, 1, 4]], "index vertices 0 to 4, but it has 4"),
    (np.zeros((4, 3)), [[0, 1, 2], [0, -1, 3]], "index vertices -1 to 3"),
    (np.array([[0, 0, 0], [1, 0, 0], [0, np.nan, 0], [0, 0, 1.0]]), [[0, 1, 2]], "1 of the mesh's 4 vertices"),
    (np.zeros((4, 2)), [[0, 1, 2]], "(V, 3) coordinates"),
    (np.zeros((4, 3)), [[0.0, 1.0, 2.0]], "(F, 3) vertex indices"),
])
def test_a_damaged_mesh_is_an_error_not_a_crash(vertices, faces, said):
    # libigl reads wherever a bad index points (the Python process died with a segmentation fault).
    with pytest.raises(HandcapError, match=re.escape(said)):
        signed_distance(np.zeros((2, 3)), vertices, np.asarray(faces))


def test_signed_distance_keeps_its_side_through_a_small_hole():
    # A sphere missing one small triangle: its inside is still inside (the winding number), and the distances are
    # those to the nearest of what is left of its triangles, each measured (trimesh's closest points are off by up
    # to 0.14 mm here).
    sphere = trimesh.creation.icosphere(subdivisions=3, radius=0.05)
    faces = np.delete(np.asarray(sphere.faces), 7, axis=0)
    rng = np.random.default_rng(5)
    points = rng.uniform(-0.07, 0.07, size=(500, 3))
    radius = np.linalg.norm(points, axis=1)
    points = points[np.abs(radius - 0.05) > 0.003]  # clear of the polyhedron's faces, to know the side
    got = signed_distance(points, sphere.vertices, faces)
    every, tri = np.repeat(points, len(faces), axis=0), np.tile(sphere.vertices[faces], (len(points), 1, 1))
    dist = np.linalg.norm(closest_points_on_triangles(every, tri)[0] - every, axis=1).reshape(len(points), -1)
    np.testing.assert_allclose(np.abs(got), dist.min(axis=1), atol=1e-12)
    assert ((got > 0) == (np.linalg.norm(points, axis=1) < 0.05)).all()


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
