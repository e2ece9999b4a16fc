"""Grasp refinement with a contact map, against synthetic grasps whose contact and penetration are exact."""

import numpy as np
import pytest

from handcap import HandcapError
from handcap.markerless.contact import ContactMap, ObjectField, contact_figures, refine_grasp
from handcap.markerless.synthetic import synthetic_grasp


@pytest.fixture(scope="module")
def grasp():
    return synthetic_grasp("precision", "cuboid", max_edge=0.008)


def test_object_field_is_the_signed_distance(grasp):
    _, obj, _, _, contact_map = grasp
    field = ObjectField(contact_map.vertices, contact_map.faces)
    rng = np.random.default_rng(0)
    points = rng.uniform(-1.3, 1.3, (2000, 3)) * obj.size  # inside and around the box
    exact = obj.signed_distance(points)
    near = np.abs(exact) < 0.005
    err = np.abs(field(points[near]) - exact[near])
    assert np.percentile(err, 99) < 0.8e-3 and err.max() < 2e-3  # sampled at 1 mm; off at sharp edges
    assert (np.sign(field(points[np.abs(exact) > 0.001])) == np.sign(exact[np.abs(exact) > 0.001])).mean() > 0.99
    # with each point's surface sample given (points moved a little, batched), the same distances
    idx = field.nearest(points)
    moved = points + rng.normal(0, 1e-7, points.shape)
    given = field(np.stack([points, moved]), idx)
    assert given.shape == (2, len(points))
    np.testing.assert_array_equal(given[0], field(points))
    assert (given[1] == field(moved)).mean() > 0.99 and np.abs(given[1] - field(moved)).max() < 1e-3


def test_refinement_lowers_penetration_and_contact_distance(grasp):
    hand, obj, pose, phi, contact_map = grasp
    assert contact_map.contacted.sum() > 20
    rng = np.random.default_rng(1)
    p0, r0, t0 = phi + np.deg2rad(rng.normal(0, 5, 27)), np.deg2rad(rng.normal(0, 2, 3)), rng.normal(0, 0.003, 3)
    betas = np.zeros(10)
    before = contact_figures(hand.forward(betas, r0, None, t0, phi=p0).vertices, hand.faces, contact_map,
                             obj.signed_distance, pose)
    p1, r1, t1 = refine_grasp(hand, betas, p0, r0, t0, contact_map, pose, iterations=15)
    after = contact_figures(hand.forward(betas, r1, None, t1, phi=p1).vertices, hand.faces, contact_map,
                            obj.signed_distance, pose)
    assert after["penetration_mm"] < 0.5 * before["penetration_mm"]
    assert after["penetration_max_mm"] < before["penetration_max_mm"]
    assert after["contact_mm"] < 0.6 * before["contact_mm"]
    assert np.degrees(np.abs(p1 - phi)).mean() < np.degrees(np.abs(p0 - phi)).mean() + 1.0


def test_contact_map_file_and_bad_maps(grasp, tmp_path):
    contact_map = grasp[4]
    contact_map.save(tmp_path / "c.npz")
    back = ContactMap.load(tmp_path / "c.npz")
    np.testing.assert_array_equal(back.contact, contact_map.contact)
    with pytest.raises(HandcapError, match="between 0 and 1"):
        ContactMap(contact_map.vertices, contact_map.faces, contact_map.contact * 2)
    with pytest.raises(HandcapError, match="metres"):
        ContactMap(contact_map.vertices * 1000, contact_map.faces, contact_map.contact)
    with pytest.raises(HandcapError, match="faces"):
        ContactMap(contact_map.vertices, contact_map.faces + len(contact_map.vertices), contact_map.contact)
