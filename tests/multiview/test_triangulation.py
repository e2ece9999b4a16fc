"""Triangulation against known synthetic points: exact without noise, robust to wrong detections."""

import numpy as np
import pytest

from handcap import HandcapError
from handcap.multiview import triangulate_linear, triangulate_ransac
from handcap.multiview.triangulation import project
from handcap.synth.cameras import cage_rig


@pytest.fixture(scope="module")
def scene():
    rig = cage_rig(12, seed=0)
    rng = np.random.default_rng(0)
    points = np.array([0.0, 0.0, 1.0]) + rng.uniform(-0.15, 0.15, (500, 3))
    return rig.projections, points, rng


def test_linear_is_exact_without_noise(scene):
    projections, points, _ = scene
    pixels = project(points, projections)
    pixels[3:, :100] = np.nan  # those points seen by 3 cameras only
    assert np.allclose(triangulate_linear(pixels, projections), points, atol=1e-9)
    pixels[1:, :5] = np.nan  # one view: nothing to triangulate
    assert np.isnan(triangulate_linear(pixels, projections)[:5]).all()


def test_ransac_rejects_wrong_detections(scene):
    projections, points, rng = scene
    pixels = project(points, projections) + rng.normal(0, 0.5, (12, 500, 2))
    pixels[rng.random((12, 500)) < 0.2] = np.nan  # occlusion
    wrong = (rng.random((12, 500)) < 0.02) & ~np.isnan(pixels[..., 0])
    pixels[wrong] += rng.uniform(30, 300, (wrong.sum(), 2)) * rng.choice([-1, 1], (wrong.sum(), 2))
    result = triangulate_ransac(pixels, projections, min_views=3, threshold_px=5.0)
    error = np.linalg.norm(result.points - points, axis=1)
    ok = ~np.isnan(error)
    assert ok.mean() > 0.95
    assert np.median(error[ok]) < 0.0005 and np.percentile(error[ok], 95) < 0.0015
    assert (~result.inliers[wrong]).mean() >= 0.99  # injected outliers rejected
    assert np.nanmean(result.error) < 0.7
    plain = np.linalg.norm(triangulate_linear(pixels, projections) - points, axis=1)
    hit = wrong.any(axis=0) & ok
    assert np.nanmedian(plain[hit]) > 10 * np.median(error[hit])  # without RANSAC the outliers hurt


def test_bad_input(scene):
    projections, points, _ = scene
    with pytest.raises(HandcapError, match="pixels must have shape"):
        triangulate_linear(np.zeros((11, 5, 2)), projections)
    with pytest.raises(HandcapError, match="projections"):
        triangulate_linear(np.zeros((12, 5, 2)), projections[:, :, :3])
    with pytest.raises(HandcapError, match="min_views"):
        triangulate_ransac(np.zeros((12, 5, 2)), projections, min_views=1)
