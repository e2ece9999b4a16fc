"""Validators for the boundary: every public function checks what it is given with these.

Each takes the value and a name for the message, and returns the checked value
(converted: a float, an int, a float64 array), or raises
:class:`~handcap.core.errors.HandcapError` with one line that names the value,
what it must be, and what it was. Inside handcap, values that passed a check
are trusted.
"""

from __future__ import annotations

import numpy as np

from handcap.core.errors import HandcapError


def check_positions(positions, what: str = "positions") -> np.ndarray:
    """``positions`` as a float64 array of shape (T, M, 3) (metres, NaN for missing).

    Parameters
    ----------
    positions : array_like of shape (T, M, 3)
        Marker positions, metres, NaN where missing.
    what : str
        Name of the value for the error message.

    Returns
    -------
    positions : ndarray of shape (T, M, 3)
        Float64 (a copy only where the input was not float64 already).

    Raises
    ------
    HandcapError
        The array is not three-dimensional with 3 in its last axis.
    """
    positions = np.asarray(positions, dtype=np.float64)
    if positions.ndim != 3 or positions.shape[2] != 3:
        raise HandcapError(f"{what} must have shape (T, M, 3), got {positions.shape}")
    return positions


def check_positive(value, what: str) -> float:
    """``value`` as a float, finite and above zero.

    Parameters
    ----------
    value : float
        Any unit; the caller's.
    what : str
        Name of the value for the error message.

    Returns
    -------
    float

    Raises
    ------
    HandcapError
        Not a number, not finite, or not above zero.
    """
    try:
        number = float(value)
    except (TypeError, ValueError):
        raise HandcapError(f"{what} must be a number, got {value!r}") from None
    if not np.isfinite(number) or number <= 0:
        raise HandcapError(f"{what} must be a positive finite number, got {value!r}")
    return number


def check_rate(rate) -> float:
    """A frame rate in Hz, as a float: finite and positive."""
    return check_positive(rate, "rate (frames per second)")


def check_frames(value, what: str) -> int:
    """A number of frames (a whole number, 0 or more) as an int; a bool or 2.5 is refused.

    Parameters
    ----------
    value : int
        Frames.
    what : str
        Name of the value for the error message.

    Returns
    -------
    int
        Frames.

    Raises
    ------
    HandcapError
        A bool, a non-integer or a negative number.
    """
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 0:
        raise HandcapError(f"{what} must be a whole number of frames >= 0, got {value!r}")
    return int(value)


def check_odd_window(window, what: str = "window", least: int = 7) -> int:
    """A window of frames centred on a frame: an odd whole number, at least ``least``.

    Parameters
    ----------
    window : int
        Frames.
    what : str
        Name of the value for the error message.
    least : int
        Smallest window accepted, frames.

    Returns
    -------
    int
        Frames.

    Raises
    ------
    HandcapError
        A bool, a non-integer, an even number or one below ``least``.
    """
    if isinstance(window, bool) or not isinstance(window, (int, np.integer)) or window < least or window % 2 == 0:
        raise HandcapError(f"{what} must be an odd number of frames, at least {least}, got {window!r}")
    return int(window)


def check_numbers(value, what: str) -> np.ndarray:
    """``value`` as a float64 array (any shape); text or objects that are not numbers are refused.

    Parameters
    ----------
    value : array_like
        Any shape and unit.
    what : str
        Name of the value for the error message.

    Returns
    -------
    ndarray
        A float64 copy, same shape; NaN and infinity pass.

    Raises
    ------
    HandcapError
        Numpy cannot convert ``value`` to float64.
    """
    try:
        return np.array(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise HandcapError(f"{what} must be numbers, got {value!r}") from None


def check_finite(array: np.ndarray, what: str) -> np.ndarray:
    """``array`` (float) with no NaN or infinity, made read-only.

    Parameters
    ----------
    array : ndarray
        Any shape and unit. Its ``writeable`` flag is cleared in place.
    what : str
        Name of the value for the error message.

    Returns
    -------
    ndarray
        ``array`` itself (not a copy), read-only.

    Raises
    ------
    HandcapError
        Any element is NaN or infinite.
    """
    if not np.isfinite(array).all():
        raise HandcapError(f"{what} must be finite, got {array.ravel().tolist()}")
    array.setflags(write=False)
    return array


def check_vector(value, n: int, what: str) -> np.ndarray:
    """A finite, read-only float64 copy of shape (n,); OpenCV's (n, 1) and (1, n) are accepted too.

    Parameters
    ----------
    value : array_like of shape (n,), (n, 1) or (1, n)
        Any unit; the caller's.
    n : int
        Number of values expected.
    what : str
        Name of the value for the error message.

    Returns
    -------
    ndarray of shape (n,)
        Float64, finite, read-only.

    Raises
    ------
    HandcapError
        Not numbers, another shape, or NaN or infinity present.
    """
    array = check_numbers(value, what)
    if array.shape not in ((n,), (n, 1), (1, n)):
        raise HandcapError(f"{what} must have {n} values, got shape {array.shape}")
    return check_finite(array.reshape(n), what)


def check_points(points, what: str = "points") -> np.ndarray:
    """Points as a float64 array of shape (..., 3), metres.

    Parameters
    ----------
    points : array_like of shape (..., 3)
        Metres; NaN passes.
    what : str
        Name of the value for the error message.

    Returns
    -------
    ndarray of shape (..., 3)
        Float64 copy, metres.

    Raises
    ------
    HandcapError
        Not numbers, or the last axis is not 3.
    """
    array = check_numbers(points, what)
    if array.ndim < 1 or array.shape[-1] != 3:
        raise HandcapError(f"{what} must have shape (..., 3) in metres, got {array.shape}")
    return array


def check_pixels(pixels, what: str = "pixels") -> np.ndarray:
    """Pixel coordinates as a float64 array of shape (..., 2).

    Parameters
    ----------
    pixels : array_like of shape (..., 2)
        Pixels (x, y); NaN passes.
    what : str
        Name of the value for the error message.

    Returns
    -------
    ndarray of shape (..., 2)
        Float64 copy, pixels.

    Raises
    ------
    HandcapError
        Not numbers, or the last axis is not 2.
    """
    array = check_numbers(pixels, what)
    if array.ndim < 1 or array.shape[-1] != 2:
        raise HandcapError(f"{what} must have shape (..., 2), got {array.shape}")
    return array


def check_cutoff(cutoff, rate: float, order: int) -> float:
    """A low-pass cutoff in Hz below the Nyquist frequency (``rate / 2``) of a Butterworth ``order`` (1 to 8).

    Parameters
    ----------
    cutoff : float
        Cutoff frequency, Hz.
    rate : float
        Frame rate, Hz (frames per second); trusted, not checked here.
    order : int
        Butterworth filter order, 1 to 8.

    Returns
    -------
    float
        The cutoff, Hz.

    Raises
    ------
    HandcapError
        ``order`` outside 1 to 8, ``cutoff`` not positive and finite, or at or above ``rate / 2``.
    """
    if not (isinstance(order, (int, np.integer)) and 1 <= order <= 8):
        raise HandcapError(f"filter order must be an integer from 1 to 8, got {order}")
    try:
        cutoff = float(cutoff)
    except (TypeError, ValueError):
        raise HandcapError(f"filter cutoff must be a positive frequency in Hz, got {cutoff!r}") from None
    if not (np.isfinite(cutoff) and cutoff > 0):
        raise HandcapError(f"filter cutoff must be a positive frequency in Hz, got {cutoff}")
    if cutoff >= rate / 2:
        raise HandcapError(f"filter cutoff {cutoff:g} Hz is not below the Nyquist frequency {rate / 2:g} Hz "
                           f"of a {rate:g} Hz capture; choose a lower cutoff")
    return float(cutoff)


def all_numbers(value) -> bool:
    """Whether ``value`` is a number or a (nested) list of numbers only (no bool, str, date or table).

    For parsed text formats (TOML, JSON), where numpy would turn ``True`` or
    ``"1"`` into numbers silently.
    """
    if isinstance(value, list):
        return all(all_numbers(item) for item in value)
    return isinstance(value, (int, float)) and not isinstance(value, bool)


__all__ = ["all_numbers", "check_cutoff", "check_finite", "check_frames", "check_numbers", "check_odd_window",
           "check_pixels", "check_points", "check_positions", "check_positive", "check_rate", "check_vector"]
