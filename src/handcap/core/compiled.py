"""Optional compiled loops: numba's ``njit`` where numba is installed (extra 'stream'), else plain Python.

The live stream's per-frame code (:mod:`handcap.solve.kernel`, :mod:`handcap.labeling.lap`) is written as
loops over one frame; compiled they run in microseconds, uncompiled they would be far too slow, so their
callers check :data:`AVAILABLE` and use their numpy code otherwise.
"""

from __future__ import annotations

try:
    import numba
except ImportError:  # AVAILABLE is then False and njit leaves functions as they are
    numba = None

#: Whether numba is installed.
AVAILABLE = numba is not None


def njit(function):
    """``function`` compiled by numba (cached on disk, without the GIL), or ``function`` itself without numba.

    Parameters
    ----------
    function : callable
        Loops over numpy arrays and numbers, in numba's subset of Python.

    Returns
    -------
    callable
    """
    return numba.njit(cache=True, nogil=True)(function) if numba is not None else function
