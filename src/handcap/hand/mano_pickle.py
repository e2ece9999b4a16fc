"""Reading MANO's ``.pkl`` model files safely, without chumpy or the old scipy modules.

The files are Python-2 pickles that name ``chumpy`` and old ``scipy.sparse``
classes. A pickle can run any function it names, so they are read with a
restricted unpickler (:func:`read_pickle`) that builds only numpy arrays, plain
chumpy arrays (their state holds the array in key ``x``) and CSC/CSR sparse
matrices (stand-ins turned into dense arrays by :func:`plain_value`), and
refuses every other name (``os.system``, ``builtins.eval``, ...) with a
:class:`~handcap.core.errors.HandcapError`. Neither chumpy nor the pickled scipy
module paths need to be importable.

This module owns that reading only; :mod:`handcap.hand.mano` checks the arrays
and builds the hand model from them.
"""

from __future__ import annotations

import copyreg
import pickle
from pathlib import Path

import numpy as np

from handcap.core.errors import HandcapError

try:
    from numpy._core import multiarray as _multiarray
    from numpy._core import numeric as _numeric
except ImportError:  # numpy < 2 has no numpy._core
    from numpy.core import multiarray as _multiarray
    from numpy.core import numeric as _numeric


# -- stand-ins for the classes the pickle names ---------------------------------------
class _Pickled:
    """Stand-in for a class named in the pickle: keeps its pickled state, runs nothing."""

    qualified = "?"
    state = None  # the pickled dict once BUILD has run

    def __setstate__(self, state):
        # chumpy and scipy pickle a dict; (dict, slots) for classes with __slots__.
        if isinstance(state, tuple) and len(state) == 2:
            state = state[0]
        self.state = state if isinstance(state, dict) else {}


class _Chumpy(_Pickled):
    """A chumpy object; a plain ``chumpy.ch.Ch`` keeps its array in ``state["x"]``."""


class _Sparse(_Pickled):
    """A scipy CSC/CSR matrix: ``data``, ``indices``, ``indptr``, ``_shape``."""

    major = 1  # csc: indptr runs over columns


class _CscMatrix(_Sparse):
    qualified = "scipy.sparse.csc_matrix"


class _CsrMatrix(_Sparse):
    qualified = "scipy.sparse.csr_matrix"
    major = 0


_CHUMPY_CLASSES: dict[str, type] = {}


def _chumpy_class(module: str, name: str) -> type:
    qualified = f"{module}.{name}"
    if qualified not in _CHUMPY_CLASSES:
        _CHUMPY_CLASSES[qualified] = type(f"_Chumpy_{name}", (_Chumpy,), {"qualified": qualified})
    return _CHUMPY_CLASSES[qualified]


# -- what the pickle may name ----------------------------------------------------------
def _reconstructor(cls, base, state):
    """``copyreg._reconstructor`` limited to the stand-in classes (old pickle protocols)."""
    if not (isinstance(cls, type) and issubclass(cls, _Pickled)) or base is not object or state is not None:
        raise pickle.UnpicklingError(f"unexpected copy_reg._reconstructor call for {cls!r}")
    return copyreg._reconstructor(cls, base, state)


def _codecs_encode(text, encoding="utf-8"):
    """``_codecs.encode`` as Python 3 uses it to pickle bytes with protocol 2 (latin-1 only)."""
    if encoding not in ("latin1", "latin-1") or not isinstance(text, str):
        raise pickle.UnpicklingError(f"unexpected _codecs.encode call with encoding {encoding!r}")
    return text.encode("latin1")


_ALLOWED = {
    ("numpy.core.multiarray", "_reconstruct"): _multiarray._reconstruct,
    ("numpy._core.multiarray", "_reconstruct"): _multiarray._reconstruct,
    ("numpy.core.multiarray", "scalar"): _multiarray.scalar,
    ("numpy._core.multiarray", "scalar"): _multiarray.scalar,
    ("numpy", "ndarray"): np.ndarray,
    ("numpy", "dtype"): np.dtype,
    ("copy_reg", "_reconstructor"): _reconstructor,
    ("copyreg", "_reconstructor"): _reconstructor,
    ("__builtin__", "object"): object,
    ("builtins", "object"): object,
    # chumpy's pickled state holds a set (_dirty_vars).
    ("__builtin__", "set"): set,
    ("builtins", "set"): set,
    ("__builtin__", "frozenset"): frozenset,
    ("builtins", "frozenset"): frozenset,
    ("_codecs", "encode"): _codecs_encode,
    ("scipy.sparse.csc", "csc_matrix"): _CscMatrix,
    ("scipy.sparse._csc", "csc_matrix"): _CscMatrix,
    ("scipy.sparse.csr", "csr_matrix"): _CsrMatrix,
    ("scipy.sparse._csr", "csr_matrix"): _CsrMatrix,
}
# Protocol 5 pickles (a file re-saved with numpy >= 1.16) rebuild arrays from a buffer.
if hasattr(_numeric, "_frombuffer"):
    _ALLOWED[("numpy.core.numeric", "_frombuffer")] = _numeric._frombuffer
    _ALLOWED[("numpy._core.numeric", "_frombuffer")] = _numeric._frombuffer

# What a damaged or foreign file can make the unpickler raise (besides HandcapError).
_UNPICKLING_ERRORS = (pickle.UnpicklingError, EOFError, ValueError, TypeError, AttributeError,
                      IndexError, KeyError, OverflowError, MemoryError, RecursionError)


class _RestrictedUnpickler(pickle.Unpickler):
    """Unpickler that builds numpy arrays and stand-ins for chumpy and scipy sparse only."""

    def __init__(self, file, source: str):
        super().__init__(file, encoding="latin1")
        self.source = source

    def find_class(self, module, name):
        if (module, name) in _ALLOWED:
            return _ALLOWED[(module, name)]
        if module == "chumpy" or module.startswith("chumpy."):
            return _chumpy_class(module, name)
        raise HandcapError(f"{self.source}: refusing to load {module}.{name} named in the pickle "
                           "(a MANO file holds only numpy, chumpy and scipy.sparse arrays); "
                           "use the MANO_RIGHT.pkl/MANO_LEFT.pkl from https://mano.is.tue.mpg.de")


# -- reading ---------------------------------------------------------------------------
def read_pickle(path: Path) -> dict:
    """The dict pickled in a MANO file; chumpy and sparse objects still as stand-ins.

    Parameters
    ----------
    path : Path
        A MANO ``.pkl`` file (``MANO_RIGHT.pkl`` / ``MANO_LEFT.pkl``), any
        pickle protocol; Python-2 string data is read as latin-1.

    Returns
    -------
    dict of str to object
        The pickled dict, keys as ``str``. Values are numpy arrays (units as in
        the file, metres for vertex positions), other plain values, or the
        module's stand-ins for chumpy objects and CSC/CSR sparse matrices: pass
        each through :func:`plain_value` to get a numpy array.

    Raises
    ------
    HandcapError
        If the file cannot be read, is not a pickle of a dict, is damaged, or
        names anything but numpy, chumpy and scipy.sparse arrays.
    """
    try:
        with path.open("rb") as fh:
            raw = _RestrictedUnpickler(fh, path.name).load()
    except OSError as err:
        raise HandcapError(f"cannot read MANO file {path}: {err.strerror or err}") from None
    except _UNPICKLING_ERRORS as err:
        reason = str(err).splitlines()[0] if str(err) else type(err).__name__
        raise HandcapError(f"{path} is not a readable MANO model pickle ({reason}); give the "
                           "MANO_RIGHT.pkl or MANO_LEFT.pkl of the MANO download") from None
    if not isinstance(raw, dict):
        raise HandcapError(f"{path} holds a {type(raw).__name__}, not the dict of a MANO model; "
                           "give the MANO_RIGHT.pkl or MANO_LEFT.pkl of the MANO download")
    return {str(k): v for k, v in raw.items()}


def plain_value(value, what: str):
    """Chumpy and sparse stand-ins as numpy arrays; anything else unchanged.

    Parameters
    ----------
    value : object
        One value of the dict :func:`read_pickle` returns.
    what : str
        Name of the value used in error messages, e.g. ``"MANO_RIGHT.pkl: shapedirs"``.

    Returns
    -------
    object
        A plain chumpy ``Ch`` as its array (any shape, units as in the file), a
        CSC/CSR matrix of shape (M, N) as a dense float64 ndarray (M, N),
        anything else as given.

    Raises
    ------
    HandcapError
        If ``value`` is a chumpy expression other than a plain ``Ch`` (it cannot
        be evaluated without chumpy), a damaged sparse matrix, or a stand-in
        whose state the file never gave.
    """
    if isinstance(value, _Chumpy):
        if value.qualified != "chumpy.ch.Ch" or "x" not in (value.state or {}):
            raise HandcapError(f"{what} is a chumpy expression ({value.qualified}) that cannot be "
                               "evaluated without chumpy; save it as a plain array (e.g. with "
                               "chumpy installed: data[key] = np.array(data[key]))")
        return plain_value(value.state["x"], what)
    if isinstance(value, _Sparse) and value.state is not None:
        return _dense(value, what)
    if isinstance(value, _Pickled):  # a stand-in whose state never came
        raise HandcapError(f"{what} is an empty {value.qualified} object; the file is damaged")
    return value


def _dense(matrix: _Sparse, what: str) -> np.ndarray:
    """Dense numpy array of a pickled CSC/CSR matrix."""
    state = matrix.state
    try:
        data = np.asarray(state["data"], dtype=np.float64)
        indices = np.asarray(state["indices"], dtype=np.int64)
        indptr = np.asarray(state["indptr"], dtype=np.int64)
        shape = tuple(int(n) for n in state.get("_shape", state.get("shape")))
    except (KeyError, TypeError, ValueError):
        raise HandcapError(f"{what} is a damaged sparse matrix (needs data, indices, indptr, _shape)") from None
    n_major = shape[matrix.major] if len(shape) == 2 else -1
    if (n_major < 0 or data.ndim != 1 or indices.shape != data.shape or indptr.shape != (n_major + 1,)
            or indptr[0] != 0 or indptr[-1] != data.size or np.any(np.diff(indptr) < 0)
            or np.any(indices < 0) or np.any(indices >= shape[1 - matrix.major])):
        raise HandcapError(f"{what} is a damaged sparse matrix of shape {shape}")
    dense = np.zeros(shape)
    major = np.repeat(np.arange(n_major), np.diff(indptr))
    rows, cols = (indices, major) if matrix.major == 1 else (major, indices)
    np.add.at(dense, (rows, cols), data)  # duplicates add up, as in scipy
    return dense

