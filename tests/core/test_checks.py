"""The boundary validators of handcap.core.checks: each returns the checked value or raises one line."""

import numpy as np
import pytest

from handcap.core import checks
from handcap.core.errors import HandcapError


@pytest.mark.parametrize("check, args, expected", [
    (checks.check_positive, (2, "x"), 2.0),
    (checks.check_rate, ("120",), 120.0),
    (checks.check_frames, (np.int64(3), "gap"), 3),
    (checks.check_odd_window, (9,), 9),
    (checks.check_cutoff, (5.0, 20.0, 2), 5.0),
])
def test_a_good_value_comes_back_converted(check, args, expected):
    out = check(*args)
    assert out == expected and type(out) is type(expected)


def test_arrays_come_back_as_float64_of_the_checked_shape():
    assert checks.check_positions([[[0, 0, 1]]]).dtype == np.float64
    vector = checks.check_vector([[1], [2], [3]], 3, "t")
    assert vector.shape == (3,) and not vector.flags.writeable
    assert checks.check_points(np.zeros((2, 5, 3))).shape == (2, 5, 3)
    assert checks.check_pixels([[1, 2]]).shape == (1, 2)


@pytest.mark.parametrize("check, args, message", [
    (checks.check_positive, (0, "radius"), "radius must be a positive finite number"),
    (checks.check_positive, ("a", "radius"), "radius must be a number"),
    (checks.check_rate, (float("nan"),), "rate (frames per second) must be a positive finite number"),
    (checks.check_frames, (2.5, "gap"), "gap must be a whole number of frames"),
    (checks.check_frames, (True, "gap"), "gap must be a whole number of frames"),
    (checks.check_frames, (-1, "gap"), "gap must be a whole number of frames"),
    (checks.check_odd_window, (8,), "window must be an odd number of frames, at least 7"),
    (checks.check_odd_window, (5,), "window must be an odd number of frames, at least 7"),
    (checks.check_cutoff, (10.0, 20.0, 2), "not below the Nyquist frequency 10 Hz"),
    (checks.check_cutoff, (5.0, 20.0, 9), "filter order must be an integer from 1 to 8"),
    (checks.check_cutoff, (None, 20.0, 2), "filter cutoff must be a positive frequency in Hz, got None"),
    (checks.check_cutoff, ("fast", 20.0, 2), "filter cutoff must be a positive frequency in Hz, got 'fast'"),
    (checks.check_positions, (np.zeros((4, 3)),), "positions must have shape (T, M, 3)"),
    (checks.check_vector, ([1, 2], 3, "t"), "t must have 3 values"),
    (checks.check_vector, ([1, np.inf, 2], 3, "t"), "t must be finite"),
    (checks.check_numbers, (["a"], "matrix"), "matrix must be numbers"),
    (checks.check_points, (np.zeros((3, 2)),), "points must have shape (..., 3) in metres"),
    (checks.check_pixels, (np.zeros(3),), "pixels must have shape (..., 2)"),
])
def test_a_bad_value_is_one_line(check, args, message):
    with pytest.raises(HandcapError) as caught:
        check(*args)
    assert message in str(caught.value) and "\n" not in str(caught.value)


def test_all_numbers_refuses_what_numpy_would_convert():
    assert checks.all_numbers([[1, 2.5], [0, -3]])
    assert not checks.all_numbers([1, True]) and not checks.all_numbers(["1"]) and not checks.all_numbers({"a": 1})
