"""Qualisys Track Manager (QTM) TSV exports of 3D marker trajectories.

Layout of a QTM 3D export::

    NO_OF_FRAMES    6000
    NO_OF_CAMERAS   7
    NO_OF_MARKERS   21
    FREQUENCY       100
    ...             (other KEY<TAB>value lines, EVENT lines)
    MARKER_NAMES    hand_top    hand_left   ...
    TRAJECTORY_TYPES    Measured    ...
    Frame   Time    hand_top X  hand_top Y  hand_top Z  ...     (optional)
    1       0.00000 110.406     135.075     460.584     ...

Without the ``Frame Time`` row, data rows hold either the 3M coordinates or
frame, time and the 3M coordinates. QTM writes millimetres and says so nowhere
in the file.

Missing samples are the cells ``nan``, ``null`` or empty (newer QTM), and
triplets that are exactly (0, 0, 0): older QTM versions write ``0.000`` for a
missing marker, the loader of the repository our real recording comes from
reads zeros as missing for that reason, and a measured marker never sits on the
lab origin to the micrometre in all three coordinates.
"""

from __future__ import annotations

import numpy as np

from handcap.core.errors import HandcapError
from handcap.core.markers import MarkerSequence
from handcap.io._text import check_complete, data_rows, floats, read_text, uniform_rows
from handcap.io._units import check_units, metres_per_unit, settle_marker_units

_WHAT = "a Qualisys TSV export"
_REQUIRED = ("NO_OF_FRAMES", "NO_OF_MARKERS", "FREQUENCY", "MARKER_NAMES")


def _is_key(cell: str) -> bool:
    return bool(cell) and cell.replace("_", "").isalnum() and cell.isupper() and not cell[0].isdigit()


def _count(header, key, path) -> int:
    try:
        value = int(header[key][0].strip())
    except (IndexError, ValueError):
        got = " ".join(header[key])[:30]
        raise HandcapError(f"{path}: {key} must be a whole number, got {got!r}") from None
    if value < 0:
        raise HandcapError(f"{path}: {key} is {value}")
    return value


def read_qualisys_tsv(path, *, units: str | None = None, hand=None) -> MarkerSequence:
    """Read a Qualisys QTM TSV export of 3D marker trajectories.

    Parameters
    ----------
    path : str or Path
        A ``.tsv`` file exported by QTM (3D data).
    units : {"mm", "cm", "m"}, optional
        The unit of the coordinates (QTM writes millimetres, the default).
    hand : sequence of str, optional
        Names of one hand's markers, whose spread tells the unit when
        millimetres are implausible (see :mod:`handcap.io._units`).

    Returns
    -------
    MarkerSequence
        ``positions`` (T, M, 3) in metres (the file is in millimetres), NaN
        where missing; ``names`` from MARKER_NAMES; ``rate`` from FREQUENCY (Hz).

    Raises
    ------
    HandcapError
        If a header key is missing, the marker or frame counts disagree with
        the data (a cut file), a column is missing, a cell is not a number, or
        the coordinates fit no length unit.
    """
    units = check_units(units)
    path, text = read_text(path, _WHAT)
    lines = text.splitlines()
    header, i = {}, 0
    while i < len(lines):
        cells = lines[i].split("\t")
        if not lines[i].strip():
            i += 1
            continue
        if not _is_key(cells[0].strip()):
            break
        if cells[0].strip() != "EVENT":
            header[cells[0].strip()] = cells[1:]
        i += 1
    if not header:
        raise HandcapError(f"{path}: not {_WHAT} (no NO_OF_FRAMES ... header lines)")
    missing = [key for key in _REQUIRED if key not in header]
    if missing:
        raise HandcapError(f"{path}: not a complete QTM TSV 3D export, header lacks {', '.join(missing)}")
    kind = header.get("DATA_INCLUDED", ["3D"])[0].strip()
    if kind != "3D":
        raise HandcapError(f"{path}: holds {kind} data; export 3D marker trajectories from QTM")
    n_frames, n_markers = _count(header, "NO_OF_FRAMES", path), _count(header, "NO_OF_MARKERS", path)
    try:
        rate = float(header["FREQUENCY"][0])
    except (IndexError, ValueError):
        raise HandcapError(f"{path}: FREQUENCY must be a number in Hz") from None
    names = [n.strip() for n in header["MARKER_NAMES"]]
    while names and not names[-1]:
        names.pop()
    if len(names) != n_markers:
        raise HandcapError(f"{path}: NO_OF_MARKERS is {n_markers} but MARKER_NAMES lists {len(names)}")

    first = lines[i].split("\t") if i < len(lines) else []
    if first and first[0].strip() in ("Frame", "Time"):
        columns = [c.strip() for c in first]
        while columns and not columns[-1]:     # QTM ends this row with a tab
            columns.pop()
        index = {c: k for k, c in enumerate(columns)}
        wanted = [f"{name} {axis}" for name in names for axis in "XYZ"]
        absent = [c for c in wanted if c not in index]
        if absent:
            raise HandcapError(f"{path}: no column {absent[0]!r} in the column header row; "
                               "the file is damaged or not a 3D export")
        cols = [index[c] for c in wanted]
        frame_col = index.get("Frame")
        i += 1
    else:
        width = len(first)
        if width in (3 * n_markers + 1, 3 * n_markers + 3) and not first[-1].strip():
            width -= 1                         # a trailing tab
        if width not in (3 * n_markers, 3 * n_markers + 2):
            raise HandcapError(f"{path}: data rows have {width} cells, expected {3 * n_markers} coordinates "
                               f"of {n_markers} markers (plus frame and time)")
        columns = [f"{name} {axis}" for name in names for axis in "XYZ"]
        cols = list(range(width - 3 * n_markers, width))
        frame_col = 0 if width == 3 * n_markers + 2 else None
        columns = (["Frame", "Time"] if frame_col == 0 else []) + columns
    rows = data_rows(lines[i:], "\t")
    if len(rows) != n_frames:
        raise HandcapError(f"{path}: NO_OF_FRAMES is {n_frames} but the file holds {len(rows)} data rows; "
                           "it is cut or damaged, export it again")
    check_complete(text, path, "the TSV file")
    width = len(columns)
    rows = uniform_rows(rows, width, path, i + 1)
    cells = np.array(rows, dtype=str).reshape(len(rows), width)
    take = cols + ([frame_col] if frame_col is not None else [])
    values = floats(cells[:, take], path, lambda r, c: f"line {i + r + 1}, column {columns[take[c]]!r},")
    if frame_col is not None and len(rows) > 1 and not (np.diff(values[:, -1]) == 1).all():
        r = int(np.flatnonzero(np.diff(values[:, -1]) != 1)[0])
        raise HandcapError(f"{path}: frame numbers jump from {values[r, -1]:g} to {values[r + 1, -1]:g} at "
                           f"line {i + r + 2}; the file is damaged")
    positions = values[:, :3 * n_markers].reshape(len(rows), n_markers, 3) * metres_per_unit(units or "mm", "units")
    positions[(positions == 0).all(axis=2)] = np.nan
    try:
        markers = MarkerSequence(positions, names, rate)
    except HandcapError as err:
        raise HandcapError(f"{path}: {err}") from None
    return settle_marker_units(markers, declared="mm", units=units, where=path, hand=hand)
