"""The paper's baselines and the registration, against independent computations."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from handcap.occlusion.baselines import ac_apply, ac_weights, ma_velocity
from handcap.objects.rigid import canonical_from_markers
from handcap.occlusion.register import apply_registration, fit_registration, undo_registration


def test_ac_weights_match_equation_8():
    rng = np.random.default_rng(0)
    known, hidden = rng.normal(size=(9, 3)), rng.normal(size=(2, 3))
    x = np.hstack([known, np.ones((9, 1))])
    y = np.hstack([hidden, np.ones((2, 1))])
    lam = 1e-8
    expected = y @ x.T @ np.linalg.inv(x @ x.T + lam * np.eye(9))  # eq. 8 as printed
    w = ac_weights(known, hidden, lam=lam)
    assert np.allclose(w, expected, atol=1e-6)
    assert np.allclose(w.sum(axis=1), 1.0, atol=1e-6)  # affine (eq. 4)
    assert np.allclose(ac_apply(w, known), hidden, atol=1e-6)  # exact on the frame it was fitted on


def test_ac_is_invariant_to_rigid_motion():
    rng = np.random.default_rng(1)
    frame = rng.normal(0, 0.05, (13, 3))
    w = ac_weights(frame[3:], frame[:3])
    rot, shift = Rotation.random(random_state=2).as_matrix(), np.array([0.3, -1.0, 2.0])
    moved = frame @ rot.T + shift
    assert np.allclose(ac_apply(w, moved[3:]), moved[:3], atol=1e-6)


def test_ma_velocity_is_mean_of_the_window():
    rate = 30.0  # window of 10 frames
    t = np.arange(15, dtype=float)
    track = np.stack([0.01 * t, -0.002 * t ** 2, np.zeros_like(t)], axis=1)[:, None, :]
    v = ma_velocity(track, rate)
    window = track[-11:, 0]
    assert np.allclose(v[0], (window[-1] - window[0]) / 10)
    track[-11:-7] = np.nan  # first sample of the window now 4 frames later
    v = ma_velocity(track, rate)
    assert np.allclose(v[0], (track[-1, 0] - track[-7, 0]) / 6)
    track[:-1] = np.nan
    assert np.allclose(ma_velocity(track, rate), 0.0)  # seen once: no velocity


def test_registration_recovers_a_rigid_motion():
    rng = np.random.default_rng(3)
    template = rng.normal(0, 0.05, (9, 3))
    rot, shift = Rotation.random(random_state=4).as_matrix(), np.array([0.1, 0.2, 1.0])
    world = template @ rot.T + shift
    visible = np.ones(9, bool)
    visible[[2, 5]] = False
    pose = fit_registration(world, visible, template, np.linspace(0.1, 1.0, 9))
    assert np.allclose(apply_registration(world, *pose), template, atol=1e-12)
    assert np.allclose(undo_registration(template, *pose), world, atol=1e-12)
    assert np.isclose(np.linalg.det(pose[0]), 1.0)
    few = np.zeros(9, bool)
    few[:2] = True
    assert np.isnan(fit_registration(world, few, template, np.ones(9))[0]).all()


def test_template_recovers_the_shape():
    rng = np.random.default_rng(5)
    shape = rng.normal(0, 0.04, (6, 3))
    frames = np.stack([shape @ Rotation.random(random_state=i).as_matrix().T + rng.normal(0, 1, 3)
                       for i in range(20)])
    frames[3, 2] = np.nan  # incomplete frames are skipped
    mean = canonical_from_markers(frames)
    d = lambda a: np.linalg.norm(a[:, None] - a[None], axis=-1)  # noqa: E731
    assert np.allclose(d(mean), d(shape), atol=1e-9)


@pytest.mark.parametrize("k", [1, 3])
def test_ac_weights_batch(k):
    rng = np.random.default_rng(k)
    known, hidden = rng.normal(size=(4, 10, 3)), rng.normal(size=(4, k, 3))
    batch = ac_weights(known, hidden)
    for i in range(4):
        assert np.allclose(batch[i], ac_weights(known[i], hidden[i]))
