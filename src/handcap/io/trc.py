"""TRC marker files (Motion Analysis / OpenSim, ``PathFileType 4``).

Layout (tab-separated)::

    PathFileType  4  (X/Y/Z)  walk.trc
    DataRate  CameraRate  NumFrames  NumMarkers  Units  OrigDataRate  OrigDataStartFrame  OrigNumFrames
    100       100         580        51          mm     100           1                   580
    Frame#  Time  RFT1        LFT1 ...
                  X1  Y1  Z1  X2  Y2  Z2 ...
    (blank line)
    1  0.000000  120.5  ...

Units come from the ``Units`` field (``mm``, ``cm``, ``m``); missing samples are
empty fields (``NaN`` is accepted too). :func:`write_trc` writes millimetres with
six decimals (1 nm), empty fields for missing samples.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from handcap.core.errors import HandcapError
from handcap.core.markers import MarkerSequence
from handcap.core.files import atomic_output
from handcap.io._text import check_complete, data_rows, floats, read_text, uniform_rows
from handcap.io._units import check_units, metres_per_unit, settle_marker_units, unit_name

_WHAT = "a TRC file"
_FIELDS = ("DataRate", "CameraRate", "NumFrames", "NumMarkers", "Units",
           "OrigDataRate", "OrigDataStartFrame", "OrigNumFrames")


def _field(info: dict, key: str, path, cast):
    try:
        value = cast(info[key])
    except KeyError:
        raise HandcapError(f"{path}: TRC header lacks {key}") from None
    except ValueError:
        raise HandcapError(f"{path}: TRC {key} must be a number, got {info[key]!r}") from None
    if value < 0 or (cast is float and not np.isfinite(value)):
        raise HandcapError(f"{path}: TRC {key} is {info[key]}")
    return value


def read_trc(path, *, units: str | None = None, hand=None) -> MarkerSequence:
    """Read a TRC marker file (``PathFileType 4``).

    Parameters
    ----------
    path : str or Path
        A ``.trc`` file.
    units : {"mm", "cm", "m"}, optional
        The unit of the coordinates, overriding the file's ``Units`` (for a
        file that declares the wrong one).
    hand : sequence of str, optional
        Names of one hand's markers, whose spread tells the unit when the
        file's is implausible (see :mod:`handcap.io._units`).

    Returns
    -------
    MarkerSequence
        ``positions`` (T, M, 3) in metres (converted from ``Units``), NaN where
        a field is empty; ``names`` from the marker row; ``rate`` = DataRate (Hz).

    Raises
    ------
    HandcapError
        If the header is incomplete, NumMarkers or NumFrames disagree with the
        names or the data, a field is not a number, or the coordinates fit no
        length unit.
    """
    units = check_units(units)
    path, text = read_text(path, _WHAT)
    lines = text.splitlines()
    if not lines[0].startswith("PathFileType"):
        raise HandcapError(f"{path}: not {_WHAT} (its first line should start with 'PathFileType')")
    if len(lines) < 5:
        raise HandcapError(f"{path}: TRC header is incomplete ({len(lines)} lines); the file is cut or damaged")
    keys = [c.strip() for c in lines[1].split("\t")]
    values = [c.strip() for c in lines[2].split("\t")]
    info = dict(zip(keys, values))
    rate = _field(info, "DataRate", path, float)
    n_frames = _field(info, "NumFrames", path, int)
    n_markers = _field(info, "NumMarkers", path, int)
    if "Units" not in info:
        raise HandcapError(f"{path}: TRC header lacks Units (mm, cm or m)")
    metres_per_unit(info["Units"], f"{path}: TRC Units")
    declared = unit_name(info["Units"])
    scale = metres_per_unit(units or declared, "units")
    label_row = lines[3].split("\t")
    if [c.strip() for c in label_row[:2]] != ["Frame#", "Time"]:
        raise HandcapError(f"{path}: TRC marker row should start with 'Frame#' and 'Time'")
    names = [c.strip() for c in label_row[2:] if c.strip()]
    if len(names) != n_markers:
        raise HandcapError(f"{path}: NumMarkers is {n_markers} but the marker row names {len(names)}")
    axes = [c.strip() for c in lines[4].split("\t") if c.strip()]
    if len(axes) != 3 * n_markers:
        raise HandcapError(f"{path}: NumMarkers is {n_markers} but the coordinate row has {len(axes)} labels, "
                           f"expected {3 * n_markers}")
    first = 5
    while first < len(lines) and not lines[first].strip():
        first += 1
    rows = data_rows(lines[first:], "\t")
    if len(rows) != n_frames:
        raise HandcapError(f"{path}: NumFrames is {n_frames} but the file holds {len(rows)} data rows; "
                           "it is cut or damaged")
    check_complete(text, path, "the TRC file")
    width = 2 + 3 * n_markers
    rows = uniform_rows(rows, width, path, first + 1)
    if not rows:
        return MarkerSequence(np.zeros((0, n_markers, 3)), names, rate)
    cells = np.array(rows, dtype=str).reshape(len(rows), width)
    columns = ["Frame#", "Time"] + [f"{n} {a}" for n in names for a in "XYZ"]
    values = floats(cells, path, lambda r, c: f"line {first + r + 1}, column {columns[c]!r},")
    if np.isnan(values[:, 0]).any() or (np.diff(values[:, 0]) <= 0).any():
        raise HandcapError(f"{path}: the Frame# column is not strictly increasing; the file is damaged")
    positions = values[:, 2:].reshape(len(rows), n_markers, 3) * scale
    try:
        markers = MarkerSequence(positions, names, rate)
    except HandcapError as err:
        raise HandcapError(f"{path}: {err}") from None
    return settle_marker_units(markers, declared=declared, units=units, where=path, hand=hand)


def write_trc(markers: MarkerSequence, path) -> None:
    """Write markers as a TRC file in millimetres, atomically.

    Parameters
    ----------
    markers : MarkerSequence
        Positions in metres, NaN where missing.
    path : str or Path
        Output file; written under a temporary name and renamed when complete.

    Raises
    ------
    HandcapError
        If a marker name is empty or holds a tab or line break.

    Notes
    -----
    Coordinates are written with six decimals of a millimetre; missing samples
    as empty fields. Frame numbers start at 1, times at 0 s.
    """
    if not isinstance(markers, MarkerSequence):
        raise HandcapError(f"write_trc needs a MarkerSequence, got {type(markers).__name__}")
    for name in markers.names:
        if not name.strip() or any(c in name for c in "\t\r\n"):
            raise HandcapError(f"{path}: marker name {name!r} cannot be stored in TRC (empty, tab or line break)")
    T, M = markers.n_frames, markers.n_markers
    rate = repr(markers.rate)
    head = ["PathFileType\t4\t(X/Y/Z)\t" + Path(path).name,
            "\t".join(_FIELDS),
            "\t".join([rate, rate, str(T), str(M), "mm", rate, "1", str(T)]),
            "\t".join(["Frame#", "Time"] + [f"{n}\t\t" for n in markers.names]),
            "\t".join(["", ""] + [f"X{m + 1}\tY{m + 1}\tZ{m + 1}" for m in range(M)]),
            ""]
    coords = markers.positions.reshape(T, 3 * M) * 1000.0
    text = np.char.mod("%.6f", coords) if coords.size else np.zeros((T, 0), dtype=str)
    text = np.where(np.isnan(coords), "", text)
    frames = [f"{t + 1}\t{t / markers.rate:.6f}" for t in range(T)]
    body = ["\t".join([frame, *row]) for frame, row in zip(frames, text.tolist())]
    with atomic_output(path, "w") as fh:
        fh.write("\n".join(head + body) + "\n")
