"""C3D marker files, read into and written from a MarkerSequence with ezc3d.

This module owns the markers of a C3D file: the points and residuals ezc3d
reads and writes, their units, missing samples, labels and big-endian files.

Reading
-------
Before ezc3d sees a file, its header and parameter section are parsed with
:mod:`struct` and checked (:mod:`handcap.io.c3d_header`), and the size of the
data section they promise is compared with the size of the file. ezc3d 1.7
crashes (segmentation fault), hangs or runs out of memory on some corrupted
parameter sections, and it reads a truncated file without complaint, returning
only the frames that are there (``Vicon.c3d`` cut to 200000 bytes gives 48 of
its 580 frames). Every such file raises :class:`~handcap.HandcapError` here
instead; ``read_c3d(path, partial=True)`` keeps the complete frames of a file
cut short. Where the header and the parameters disagree, the parameters win
(POINT:USED, POINT:FRAMES, ANALOG:USED, ANALOG:RATE), as they do in ezc3d.

Big-endian files (processor type SGI/MIPS, which ezc3d refuses) are converted to
Intel byte order in a temporary copy and read from there.

Units come from POINT:UNITS (``mm``, ``cm``, ``m``); a file with no or an empty
POINT:UNITS is taken to be in millimetres, the C3D default that Vicon and
Qualisys write. Labels are kept as written, ``Subject:`` prefix included;
POINT:LABELS2, LABELS3, ... continue POINT:LABELS for files of more than 255
points, and labels beyond the number of points are ignored.

Missing data
------------
A sample is missing (NaN) where

* its residual is negative: the C3D convention (residual -1), used by the
  Vicon, Optotrak and c3d.org sample files; ezc3d turns these into NaN;
* the file stores NaN coordinates (the kineticstoolkit and auto_marker_label
  files do, with residual 0);
* it is exactly (0, 0, 0) with residual 0: some writers mark missing samples
  this way, and none of the real files in ``../shared/data/markers`` holds a
  sample there. A marker that really sits on the lab origin to the last bit in
  all three coordinates, with no residual, is read as missing.

Residuals are kept in ``MarkerSequence.residuals``, in metres. Coordinates
beyond 10 km are refused as garbage bytes read as floats.

Writing
-------
:func:`write_c3d` writes float storage in millimetres, missing samples as
(0, 0, 0) with residual -1, and the sequence's residuals (0 where it has none),
rounded to the POINT:SCALE step (0.01 mm, coarser if a residual exceeds 1.27 mm,
because C3D keeps residuals in 7 bits). The rate is stored as float32, as C3D
does; the reader gives back the shortest decimal with that float32 value.
"""

from __future__ import annotations

import os
import struct
import tempfile
from pathlib import Path

import ezc3d
import numpy as np

from handcap.core.errors import HandcapError
from handcap.core.markers import MarkerSequence
from handcap.core.files import atomic_output, existing_file
from handcap.io._units import check_units, metres_per_unit, settle_marker_units, unit_name
from handcap.io.c3d_header import FLOAT, INT, INTEL, MIPS, C3DLayout, inspect_c3d, parameter_strings

# Coordinates beyond this (metres) cannot come from a capture volume; they come
# from garbage bytes read as floats.
_IMPLAUSIBLE = 1e4
# C3D keeps residuals in 7 bits of the fourth word, in steps of |POINT:SCALE|.
_RESIDUAL_LEVELS = 127
_RESIDUAL_STEP_MM = 0.01
# What ezc3d raises for the errors it reports (std::ios_base::failure arrives
# as OSError, std::bad_alloc as MemoryError or RuntimeError).
_EZC3D_ERRORS = (RuntimeError, OSError, ValueError, IndexError, MemoryError, OverflowError)


def _one_line(err: BaseException) -> str:
    """ezc3d's message on one line (some of them span several)."""
    return " ".join(str(err).split())[:200]


# -- big-endian files --------------------------------------------------------------------

def _swap(buf: bytearray, start: int, stop: int, width: int) -> None:
    """Reverse the byte order of the ``width``-byte values in ``buf[start:stop]``."""
    view = np.frombuffer(buf, np.uint8, count=stop - start, offset=start).reshape(-1, width)
    buf[start:stop] = view[:, ::-1].tobytes()


def _intel_copy(layout: C3DLayout, target: Path) -> None:
    """Write a copy of a big-endian (SGI/MIPS) C3D file in Intel byte order."""
    buf = bytearray(layout.path.read_bytes())
    _swap(buf, 2, 12, 2)            # words 2-6: points, analogs, first/last frame, gap
    _swap(buf, 12, 16, 4)           # words 7-8: scale
    _swap(buf, 16, 20, 2)           # words 9-10: data start, analog samples
    _swap(buf, 20, 24, 4)           # words 11-12: frame rate
    _swap(buf, 24, 304, 2)          # words 13-152: reserved, label and event keys
    _swap(buf, 304, 376, 4)         # words 153-188: 18 event times
    _swap(buf, 394, 396, 2)         # word 198: reserved (event flags and labels are bytes)
    buf[layout.param_start + 3] = INTEL
    for offset_at, offset, param in layout.records:
        struct.pack_into("<H", buf, offset_at, offset)
        if param is not None and param.type in (INT, FLOAT) and param.raw:
            _swap(buf, param.start, param.start + len(param.raw), param.type)
    width = 4 if layout.is_float else 2
    _swap(buf, layout.data_start, layout.data_start + layout.n_frames * layout.frame_bytes, width)
    target.write_bytes(bytes(buf))


def _read_points(layout: C3DLayout) -> tuple[np.ndarray, np.ndarray]:
    """Points (4, M, T) and residuals (1, M, T) read by ezc3d, in file units."""
    with tempfile.TemporaryDirectory(prefix="handcap-c3d-") as tmp:
        source = layout.path
        if layout.processor == MIPS:
            source = Path(tmp) / "intel.c3d"
            _intel_copy(layout, source)
        try:
            c3d = ezc3d.c3d(str(source))
            points = np.asarray(c3d["data"]["points"], dtype=np.float64)
            residuals = np.asarray(c3d["data"]["meta_points"]["residuals"], dtype=np.float64)
        except _EZC3D_ERRORS as err:
            raise HandcapError(f"{layout.path}: unreadable C3D file ({_one_line(err)}); export it again") from None
    # A file cut short (read with partial=True) may give one more, incomplete frame.
    points, residuals = points[:, :, :layout.n_frames], residuals[:, :, :layout.n_frames]
    expected = (4, layout.n_points, layout.n_frames)
    if points.shape != expected or residuals.shape != (1,) + expected[1:]:
        raise HandcapError(f"{layout.path}: inconsistent C3D file (read {points.shape[2]} frames of "
                           f"{points.shape[1]} points, its header promises {layout.n_frames} of "
                           f"{layout.n_points}); export it again")
    return points, residuals


def _labels(layout: C3DLayout) -> list[str]:
    """POINT:LABELS, LABELS2, ... cut to the number of points, made unique."""
    labels, k = [], 1
    while ("POINT", "LABELS" + (str(k) if k > 1 else "")) in layout.params:
        labels += parameter_strings(layout.params[("POINT", "LABELS" + (str(k) if k > 1 else ""))])
        k += 1
    labels = labels[:layout.n_points]
    labels += [""] * (layout.n_points - len(labels))
    names, taken = [], set(labels)
    for i, label in enumerate(labels):
        name = label or f"point{i + 1}"
        if name in names:              # a repeated label: the later ones get a suffix
            k = 2
            while f"{name}~{k}" in taken:
                k += 1
            name = f"{name}~{k}"
        taken.add(name)
        names.append(name)
    return names


def read_c3d(path, *, partial: bool = False, units: str | None = None, hand=None) -> MarkerSequence:
    """Read the 3D points of a C3D file.

    Parameters
    ----------
    path : str or Path
        A ``.c3d`` file (Intel, DEC or SGI/MIPS byte order; integer or float storage).
    partial : bool, optional
        Read the complete frames of a file that is shorter than its header and
        POINT:FRAMES promise, instead of refusing it. Off by default, because
        such a file is almost always a cut copy. (``ezc3d/Optotrak.c3d`` is one:
        its header promises 1149 frames, it holds 29.)
    units : {"mm", "cm", "m"}, optional
        The unit of the coordinates, overriding POINT:UNITS.
    hand : sequence of str, optional
        Names of one hand's markers, whose spread tells the unit when the
        file's is implausible (see :mod:`handcap.io._units`).

    Returns
    -------
    MarkerSequence
        ``positions`` (T, M, 3) in metres, NaN where missing (see the module
        notes for the rule), ``names`` from POINT:LABELS (LABELS2, ... for more
        than 255 points), ``rate`` from POINT:RATE in Hz, ``residuals`` (T, M)
        in metres.

    Raises
    ------
    HandcapError
        If the file is not a C3D file, is truncated or corrupt, names an
        unknown unit, holds no points, or its coordinates fit no length unit.

    Notes
    -----
    Units come from POINT:UNITS; a missing or empty POINT:UNITS means
    millimetres. Empty labels become ``point<i>`` (1-based) and repeated labels
    get a ``~2``, ``~3`` suffix, so that names stay unique.
    """
    units = check_units(units)
    path = existing_file(path)
    layout = inspect_c3d(path, partial)
    points, residuals = _read_points(layout)
    said = parameter_strings(layout.params[("POINT", "UNITS")]) if ("POINT", "UNITS") in layout.params else []
    unit = said[0] if said and said[0] else "mm"
    metres_per_unit(unit, f"{path}: POINT:UNITS")
    scale = metres_per_unit(units or unit, "units")
    positions = points[:3].transpose(2, 1, 0) * scale
    residuals = residuals[0].T * scale
    zero = (positions == 0).all(axis=2) & (residuals == 0)
    positions[zero] = np.nan
    if np.isinf(positions).any() or (np.abs(positions) > _IMPLAUSIBLE).any():
        t, m = np.argwhere(np.isinf(positions) | (np.abs(positions) > _IMPLAUSIBLE))[0][:2]
        raise HandcapError(f"{path}: corrupt C3D data (coordinate beyond {_IMPLAUSIBLE:g} m at frame {t}, "
                           f"point {m}); export the file again")
    warnings = (_joined(parameter_strings(layout.params[("HANDCAP", "WARNINGS")]))
                if ("HANDCAP", "WARNINGS") in layout.params else [])
    try:
        markers = MarkerSequence(positions, _labels(layout), layout.rate, residuals, tuple(w for w in warnings if w))
    except HandcapError as err:
        raise HandcapError(f"{path}: {err}") from None
    return settle_marker_units(markers, declared=unit_name(unit), units=units, where=path, hand=hand)


# -- writing -----------------------------------------------------------------------------

#: A C3D parameter's dimensions are single bytes: its strings are at most 255 bytes long, and at most 255 of them.
_C3D_DIM = 255
#: Ends a piece of a warning that goes on in the next string of ``HANDCAP:WARNINGS``.
_GOES_ON = "\\"


def _pieces(texts) -> list[str]:
    """``texts`` as the strings of a C3D character parameter: each at most :data:`_C3D_DIM` bytes (UTF-8), a
    longer one cut into pieces that all but the last end in :data:`_GOES_ON`; at most :data:`_C3D_DIM` strings,
    the last of them saying how many texts were left out. ezc3d writes longer or more strings without a word,
    and the file it writes is damaged (a warning of 300 characters made a synthetic take unreadable)."""
    out: list[list[str]] = []
    for text in texts:
        pieces, rest = [], text
        while len(rest.encode()) > _C3D_DIM or rest.endswith(_GOES_ON):  # a text's own last backslash too
            # The longest head of at most 254 bytes that ends on a whole character (at least one).
            head = rest.encode()[:_C3D_DIM - len(_GOES_ON)].decode(errors="ignore") or rest[0]
            pieces.append(head + _GOES_ON)
            rest = rest[len(head):]
        out.append(pieces + [rest])
    flat = [piece for pieces in out for piece in pieces]
    if len(flat) <= _C3D_DIM:
        return flat
    kept: list[str] = []
    for k, pieces in enumerate(out):
        if len(kept) + len(pieces) > _C3D_DIM - 1:
            return kept + [f"{len(out) - k} more warning(s) left out: a C3D file holds {_C3D_DIM} lines"]
        kept += pieces
    return kept


def _joined(pieces) -> list[str]:
    """The texts that :func:`_pieces` cut, joined again."""
    out, carried = [], ""
    for piece in pieces:
        if piece.endswith(_GOES_ON):
            carried += piece[:-len(_GOES_ON)]
        else:
            out.append(carried + piece)
            carried = ""
    return out + ([carried] if carried else [])


def _check_names(names, path) -> None:
    for name in names:
        if not name or name != name.rstrip() or "\0" in name:
            raise HandcapError(f"{path}: marker name {name!r} cannot be stored in C3D (empty, trailing "
                               "space or NUL); rename the marker")
        if len(name.encode("utf-8")) > 255:
            raise HandcapError(f"{path}: marker name {name[:40]!r}... is longer than the 255 bytes C3D allows; "
                               "rename the marker")


def write_c3d(markers: MarkerSequence, path) -> None:
    """Write markers as a C3D file (float storage, millimetres), atomically.

    Parameters
    ----------
    markers : MarkerSequence
        T >= 1 frames of M >= 1 markers; positions in metres, NaN where missing.
    path : str or Path
        Output file; written under a temporary name and renamed when complete.

    Raises
    ------
    HandcapError
        If there is nothing to write, a name cannot be stored in C3D, or the
        file cannot be written.

    Notes
    -----
    Missing samples are written as (0, 0, 0) with residual -1. Residuals are
    written in millimetres, rounded to the POINT:SCALE step (0.01 mm, or
    max residual / 127 if that is larger); without residuals they are 0. More
    than 255 markers go to POINT:LABELS, LABELS2, ...
    """
    if not isinstance(markers, MarkerSequence):
        raise HandcapError(f"write_c3d needs a MarkerSequence, got {type(markers).__name__}")
    if markers.n_frames == 0 or markers.n_markers == 0:
        raise HandcapError(f"{path}: nothing to write ({markers.n_frames} frames, {markers.n_markers} markers)")
    _check_names(markers.names, path)
    if (np.abs(np.nan_to_num(markers.positions)) > _IMPLAUSIBLE).any():
        raise HandcapError(f"{path}: coordinates beyond {_IMPLAUSIBLE:g} m cannot be written; "
                           "positions must be in metres")
    missing = markers.missing
    points = np.ones((4, markers.n_markers, markers.n_frames))
    points[:3] = np.nan_to_num(markers.positions * 1000.0, nan=0.0).transpose(2, 1, 0)
    residual_mm = np.zeros(missing.shape) if markers.residuals is None else markers.residuals * 1000.0
    residual_mm = np.clip(np.nan_to_num(residual_mm, nan=0.0), 0.0, None)
    step = max(_RESIDUAL_STEP_MM, float(residual_mm.max()) / _RESIDUAL_LEVELS)
    # ezc3d truncates residual / step to an integer: aim at the middle of the level.
    residual_mm = (np.rint(residual_mm / step) + 0.5) * step
    residual_mm[missing] = -1.0
    c3d = ezc3d.c3d()
    c3d["parameters"]["POINT"]["RATE"]["value"] = [markers.rate]
    c3d["parameters"]["POINT"]["LABELS"]["value"] = list(markers.names)
    c3d.add_parameter("POINT", "UNITS", "mm")
    c3d.add_parameter("POINT", "SCALE", -step)
    if markers.warnings:  # handcap's warnings about the data travel with it (File contracts)
        c3d.add_parameter("HANDCAP", "WARNINGS", _pieces(markers.warnings))
    c3d["data"]["points"] = points
    c3d["data"]["meta_points"] = {"residuals": residual_mm.T[np.newaxis]}
    with atomic_output(path, mode=None) as tmp:
        # ezc3d appends ".c3d" to names that do not end with it (e.g. ".C3D").
        target = tmp if tmp.name.endswith(".c3d") else tmp.with_name(tmp.name + ".c3d")
        try:
            c3d.write(str(target))
            if target != tmp:
                os.replace(target, tmp)
        except _EZC3D_ERRORS + (TypeError,) as err:
            raise HandcapError(f"{path}: could not write the C3D file ({_one_line(err)})") from None
        finally:
            if target != tmp and target.exists():
                target.unlink()
