"""Synthetic fingers keep apart: neighbouring fingers' bones never pass through each other."""

import numpy as np

from handcap.hand import load_hand_model
from handcap.synth.clearance import FINGER_CLEARANCE, finger_clearance, segment_distance
from handcap.synth.motions import make_motion, natural_pose


def test_segment_distance_against_dense_sampling():
    # Independent computation: the least distance over 2001 x 2001 points of the two segments.
    rng = np.random.default_rng(0)
    s = np.linspace(0.0, 1.0, 2001)[:, None]
    for _ in range(20):
        p0, p1, q0, q1 = rng.normal(size=(4, 3))
        a, b = p0 + s * (p1 - p0), q0 + s * (q1 - q0)
        dense = np.sqrt(((a[:, None] - b[None]) ** 2).sum(-1)).min()
        assert abs(segment_distance(p0, p1, q0, q1) - dense) < 2e-3
    # parallel segments, and a segment that is a point
    assert np.isclose(segment_distance(np.zeros(3), np.array([1.0, 0, 0]), np.array([0.5, 1, 0]),
                                       np.array([2.0, 1, 0])), 1.0)
    assert np.isclose(segment_distance(np.zeros(3), np.zeros(3), np.array([1.0, 1, 0]), np.array([1.0, -1, 0])), 1.0)


def test_random_motion_keeps_the_fingers_apart():
    hand = load_hand_model()
    rng = np.random.default_rng(3)
    # The key poses drawn on their own put two fingers closer than a finger is thick in about a third of draws.
    keys = np.array([natural_pose(rng) for _ in range(300)])
    alone = finger_clearance(hand.forward(phi=keys, vertices=False).joints)
    assert (alone < FINGER_CLEARANCE).mean() > 0.15 and alone.min() < 0.005
    for seed in range(3):
        motion = make_motion("random", hand, 600, 100.0, np.random.default_rng(seed))
        clearance = finger_clearance(hand.forward(phi=motion.phi, vertices=False).joints)
        assert clearance.min() > 0.8 * FINGER_CLEARANCE and (clearance < FINGER_CLEARANCE).mean() < 0.02
