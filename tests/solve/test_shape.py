import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from handcap import HandcapError
from handcap.hand import OpenHand
from handcap.solve import betas_from_measurements, betas_from_scan, hand_measurements


def test_measurements_of_the_average_hand():
    m = hand_measurements(OpenHand())
    assert m["hand_length"] == pytest.approx(0.1825, abs=0.001)
    assert 0.075 < m["hand_breadth"] < 0.09
    assert m["middle_length"] > m["index_length"] > m["pinky_length"]


def test_measured_lengths_are_reproduced():
    hand = OpenHand()
    truth = np.random.default_rng(3).normal(size=10) * 0.8
    lengths = hand_measurements(hand, truth)
    betas = betas_from_measurements(hand, **lengths)
    got = hand_measurements(hand, betas)
    for name, value in lengths.items():
        assert got[name] == pytest.approx(value, rel=0.005), name
    # One measurement only: matched with the smallest change of shape, mostly overall size.
    size = betas_from_measurements(hand, hand_length=0.195)
    assert hand_measurements(hand, size)["hand_length"] == pytest.approx(0.195, rel=0.002)
    assert np.argmax(size) == 0 and np.linalg.norm(size) < 1.3
    assert np.allclose(size[[4, 5, 6, 7, 8, 9]], 0, atol=0.01)  # thickness, thumb, ring... untouched


def test_scan_gives_the_subjects_lengths():
    hand = OpenHand()
    rng = np.random.default_rng(0)
    truth = rng.normal(size=10) * 0.8
    surface = hand.forward(truth, phi=rng.normal(0, 0.05, 27)).vertices
    rot = Rotation.random(random_state=1).as_matrix()
    tri = (surface @ rot.T + [0.3, 0.1, 1.0])[hand.faces]
    samples = np.einsum("fsk,fki->fsi", rng.dirichlet([1, 1, 1], size=(len(tri), 2)), tri).reshape(-1, 3)
    samples += rng.normal(0, 0.0005, samples.shape)
    betas, chamfer = betas_from_scan(hand, samples, iterations=12)
    assert chamfer < 0.0015
    want, got = hand_measurements(hand, truth), hand_measurements(hand, betas)
    for name in ("hand_length", "palm_length", "hand_breadth"):
        assert got[name] == pytest.approx(want[name], rel=0.03), name


def test_bad_inputs():
    hand = OpenHand()
    with pytest.raises(HandcapError, match="unknown measurement"):
        betas_from_measurements(hand, wrist_size=0.05)
    with pytest.raises(HandcapError, match="not a hand length in metres"):
        betas_from_measurements(hand, hand_length=190)
    with pytest.raises(HandcapError, match="at least one"):
        betas_from_measurements(hand)
    with pytest.raises(HandcapError, match="at least 100 points"):
        betas_from_scan(hand, np.zeros((10, 3)))
