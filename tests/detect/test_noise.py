"""Sensor noise: its estimate against known noise, and noisy frames denoised before the search."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
from scipy.spatial import cKDTree

from handcap.detect.networks import load_checker, load_corner_net, load_reader, load_refiner
from handcap.detect.noise import NOISE_LEARNED, noise_sigma
from handcap.detect.pipeline import Detector
from handcap.patterns.session import session_pattern
from handcap.synth.images import ImageStyle

PATTERN = session_pattern(("right",), (), alphabet="0123456789ACEFHPUY")  # the scenes fixture's tags


def _noisy(image, sigma, seed=0):
    return np.clip(image + np.random.default_rng(seed).normal(0.0, sigma, image.shape), 0, 255).astype(np.uint8)


def test_the_estimate_finds_known_noise_and_not_printed_edges():
    flat = np.full((300, 400), 120.0)
    for sigma in (2.0, 6.0, 15.0):
        assert abs(noise_sigma(_noisy(flat, sigma)) - sigma) < 0.05 * sigma
    board = (np.kron(np.indices((15, 20)).sum(axis=0) % 2, np.ones((20, 20))) * 180 + 30).astype(np.uint8)
    assert noise_sigma(board) < 0.5  # sharp edges everywhere, no noise
    assert abs(noise_sigma(_noisy(board, 8.0)) - 8.0) < 0.8
    assert noise_sigma(np.zeros((2, 2), np.uint8)) == 0.0 and noise_sigma(np.zeros((9, 9, 3), np.uint8)) == 0.0


def test_the_most_noise_learned_is_the_renders():
    # The renders' noise at full white: read noise at its most and shot noise (sigma = factor * sqrt(level)).
    style = ImageStyle()
    most = np.hypot(style.read_noise[1], style.shot_noise * np.sqrt(255.0))
    assert NOISE_LEARNED - 0.5 <= most <= NOISE_LEARNED + 0.1


def test_noisy_frames_are_denoised_first_and_clean_ones_left(scenes):
    networks = dict(corner_net=load_corner_net(int8=True), reader=load_reader(), refiner=load_refiner(int8=True),
                    checker=load_checker(), pattern=PATTERN, pyramid=False)
    on, off = Detector(**networks), Detector(**networks, denoise=False)
    for scene in scenes:  # clean renders: under the noise learned, searched as they are
        assert noise_sigma(scene.image) < NOISE_LEARNED
        one, two = on.image(scene.image), off.image(scene.image)
        np.testing.assert_array_equal(one.corners, two.corners)
        np.testing.assert_array_equal(one.block_text, two.block_text)
    found = {True: 0, False: 0}
    for k, scene in enumerate(scenes):
        noisy = replace(scene, image=_noisy(scene.image, 12.0, seed=k))
        for detector in (on, off):
            got = detector.image(noisy.image)
            assert got.noise > 10.0
            if len(got.corners):
                found[detector.denoise] += int((cKDTree(got.corners).query(scene.corners)[0] <= 2.0).sum())
    # Measured when this was written: 612 against 477 true corners found in these three scenes.
    assert found[True] > 1.15 * found[False] > 0
