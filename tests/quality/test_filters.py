import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from handcap import HandcapError
from handcap.core.motion import HandMotion, ObjectMotion
from handcap.quality import lowpass, smooth_hand_motion, smooth_object_motion, smooth_rotations


def test_butterworth_passes_slow_and_stops_fast_motion_without_lag():
    rate = 100.0
    t = np.arange(400) / rate
    slow, fast = np.sin(2 * np.pi * 1.0 * t), 0.3 * np.sin(2 * np.pi * 25.0 * t)
    out = lowpass(slow + fast, rate, cutoff=5.0, order=2)
    core = slice(50, 350)
    np.testing.assert_allclose(out[core], slow[core], atol=0.02)  # zero phase: no delay
    assert np.abs(lowpass(fast, rate, 5.0)[core]).max() < 0.02


def test_cutoff_must_stay_below_nyquist_and_order_sane():
    with pytest.raises(HandcapError, match="Nyquist"):
        lowpass(np.zeros(100), 20.0, cutoff=10.0)
    with pytest.raises(HandcapError, match="order"):
        lowpass(np.zeros(100), 20.0, cutoff=5.0, order=0)


def test_nan_runs_are_kept_and_filtered_apart():
    x = np.sin(np.arange(200) / 10.0)
    x[90:100] = np.nan
    out = lowpass(x, 100.0, 5.0)
    assert np.isnan(out[90:100]).all() and np.isfinite(out[:90]).all()


def test_rotations_through_180_degrees_do_not_flip():
    rate = 50.0
    angles = np.linspace(0, 4 * np.pi, 300)  # two full turns about z: the axis-angle wraps twice
    rotvecs = Rotation.from_euler("z", angles[:, None]).as_rotvec()
    smooth = smooth_rotations(rotvecs, rate, cutoff=5.0)
    err = (Rotation.from_rotvec(smooth).inv() * Rotation.from_rotvec(rotvecs)).magnitude()
    assert err.max() < 1e-3


def test_smoothing_keeps_the_warnings_of_the_motion():
    # A smoothed implausible fit is still one: the warnings stored with the motion stay with it.
    t = np.arange(60) / 50.0
    phi = 0.2 * np.sin(2 * np.pi * t)[:, None] * np.ones(27)
    motion = HandMotion(np.zeros(10), np.zeros((60, 3)), np.zeros((60, 45)), np.zeros((60, 3)), 50.0, phi=phi,
                        warnings=("solve MRE of 1 marker(s) above 5 mm",))
    smoothed = smooth_hand_motion(motion, cutoff=5.0)
    assert smoothed.warnings == motion.warnings
    assert np.abs(smoothed.phi - phi).max() < 0.05  # and it is smoothed, not the same motion
    obj = ObjectMotion(np.zeros((60, 3)), np.c_[t, t, t], 50.0, warnings=("residual 9 mm",))
    assert smooth_object_motion(obj, cutoff=5.0).warnings == ("residual 9 mm",)

