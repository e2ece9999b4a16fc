"""OptiTrack Motive CSV exports (format versions 1.2x) of marker trajectories.

Layout, as Motive writes it (1.23)::

    Format Version,1.23,Take Name,...,Export Frame Rate,120.000000,...,
        Total Exported Frames,906,Rotation Type,Quaternion,Length Units,Millimeters,...
    (blank line)
    ,Type,Rigid Body,...,Rigid Body Marker,...,Marker,Marker,Marker,...
    ,Name,Left,...,Left:Marker1,...,Box:Marker1,Box:Marker1,Box:Marker1,...
    ,ID,7264DAA5...,...,"C5B98015...",...
    ,,Rotation,...,Position,...,Position,Position,Position,...
    Frame,Time (Seconds),X,Y,Z,W,X,Y,Z,...
    0,0.000000,0.032550,...

Format 1.21 leaves the ``Type``/``Name``/``ID`` labels out (the four rows come
in that order) and calls the time column ``Time``. Newer exports may add rows
such as ``Parent``; they are ignored.

What is read: the ``Position`` X/Y/Z columns of every ``Marker`` column group,
that is the labeled markers (``Subject:Name``; a rigid body's measured markers
appear here as ``Body:Marker1``) and the unlabeled ones (``Unlabeled 1000`` or
``Unlabeled:108``), which are kept under their Motive names so that
``handcap label`` sees every point. Not read: ``Rigid Body`` and ``Bone`` poses,
their error and quality columns, and ``Rigid Body Marker`` / ``Bone Marker``
columns, which hold the positions the solved body implies for its markers, not
measurements. Empty cells are missing samples. Units come from ``Length Units``
(Millimeters, Centimeters, Meters); the rate from ``Export Frame Rate`` (else
``Capture Frame Rate``).
"""

from __future__ import annotations

import csv

import numpy as np

from handcap.core.errors import HandcapError
from handcap.core.markers import MarkerSequence
from handcap.io._text import check_complete, data_rows, floats, read_text, uniform_rows
from handcap.io._units import check_units, metres_per_unit, settle_marker_units, unit_name

_WHAT = "an OptiTrack Motive CSV export"
_LABELS = ("Type", "Name", "ID")


def _metadata(first: list[str], path) -> dict:
    if not first or first[0].strip() != "Format Version":
        if [c.strip() for c in first[:3]] == ["Class", "User", "X0"]:
            raise HandcapError(f"{path}: this is the UCI hand-postures table, not {_WHAT}; "
                               "read it with handcap.io.read_uci_postures")
        raise HandcapError(f"{path}: not a marker CSV handcap reads: {_WHAT} starts with 'Format Version', a Vicon "
                           "Nexus export with a section name (Trajectories)")
    cells = [c.strip() for c in first]
    meta = dict(zip(cells[0::2], cells[1::2]))
    if not meta.get("Format Version", "").startswith("1.2"):
        raise HandcapError(f"{path}: Motive CSV format version {meta.get('Format Version')!r} is not supported; "
                           "export it from Motive as CSV format 1.2x")
    return meta


def _rate(meta: dict, path) -> float:
    for key in ("Export Frame Rate", "Capture Frame Rate"):
        if meta.get(key):
            try:
                rate = float(meta[key])
            except ValueError:
                raise HandcapError(f"{path}: {key} must be a number in Hz, got {meta[key]!r}") from None
            if not np.isfinite(rate) or rate <= 0:
                raise HandcapError(f"{path}: {key} is {meta[key]}")
            return rate
    raise HandcapError(f"{path}: first line has no Export Frame Rate or Capture Frame Rate")


def _header_rows(rows: list[list[str]], path) -> tuple[list[str], list[str], list[str]]:
    """The Type, Name and component (Position/Rotation) rows, from the rows above ``Frame``."""
    labelled = {row[1].strip(): row for row in rows if len(row) > 1 and row[1].strip() in _LABELS}
    if labelled:
        missing = [label for label in ("Type", "Name") if label not in labelled]
        if missing:
            raise HandcapError(f"{path}: Motive CSV lacks its {missing[0]!r} header row; export the file again")
        component = rows[-1] if rows and rows[-1][1:2] in ([""], []) else None
        if component is None:
            raise HandcapError(f"{path}: Motive CSV lacks the Position/Rotation row above the 'Frame' row")
        return labelled["Type"], labelled["Name"], component
    if len(rows) != 4:
        raise HandcapError(f"{path}: Motive CSV has {len(rows)} header rows above 'Frame', expected Type, Name, "
                           "ID and Position/Rotation; export the file again")
    return rows[0], rows[1], rows[3]


def read_motive_csv(path, *, units: str | None = None, hand=None) -> MarkerSequence:
    """Read the marker trajectories of an OptiTrack Motive CSV export (format 1.2x).

    Parameters
    ----------
    path : str or Path
        A ``.csv`` exported by Motive with markers included.
    units : {"mm", "cm", "m"}, optional
        The unit of the coordinates, overriding the file's ``Length Units``.
    hand : sequence of str, optional
        Names of one hand's markers, whose spread tells the unit when the
        file's is implausible (see :mod:`handcap.io._units`).

    Returns
    -------
    MarkerSequence
        ``positions`` (T, M, 3) in metres, NaN where a cell is empty; one marker
        per ``Marker`` column group, labeled and unlabeled, named as in the file.

    Raises
    ------
    HandcapError
        If the file is not a Motive export (the UCI hand-postures CSV included),
        lacks header rows, has no Marker columns, or its rows disagree with the
        header or with ``Total Exported Frames``, or the coordinates fit no
        length unit.
    """
    units = check_units(units)
    path, text = read_text(path, _WHAT)
    lines = text.splitlines()
    meta = _metadata(next(csv.reader(lines[:1]), []), path)
    rate = _rate(meta, path)
    if "Length Units" not in meta:
        raise HandcapError(f"{path}: first line has no Length Units; export again with units included")
    metres_per_unit(meta["Length Units"], f"{path}: Length Units")
    declared = unit_name(meta["Length Units"])
    scale = metres_per_unit(units or declared, "units")
    start = 1
    while start < len(lines) and not lines[start].strip():
        start += 1
    stop = next((k for k in range(start, min(len(lines), start + 20)) if lines[k].startswith("Frame,")), None)
    if stop is None:
        raise HandcapError(f"{path}: Motive CSV lacks its 'Frame,Time' column header row; export the file again")
    types, names, components = _header_rows(list(csv.reader(lines[start:stop])), path)
    axes = [c.strip() for c in lines[stop].split(",")]
    width = len(axes)
    for label, row in (("Type", types), ("Name", names), ("Position/Rotation", components)):
        if len(row) != width:
            raise HandcapError(f"{path}: the {label} row has {len(row)} cells for {width} columns; "
                               "the file is damaged")
    columns: dict[str, dict[str, int]] = {}
    for k in range(2, width):
        if types[k].strip() == "Marker" and components[k].strip() == "Position" and axes[k] in ("X", "Y", "Z"):
            axis = columns.setdefault(names[k].strip(), {})
            if axes[k] in axis:
                raise HandcapError(f"{path}: marker {names[k].strip()!r} has two {axes[k]} columns")
            axis[axes[k]] = k
    if not columns:
        kinds = sorted({t.strip() for t in types[2:] if t.strip()})
        raise HandcapError(f"{path}: no Marker position columns (found {', '.join(kinds) or 'none'}); "
                           "export again with markers included")
    incomplete = [n for n, axis in columns.items() if len(axis) != 3]
    if incomplete:
        raise HandcapError(f"{path}: marker {incomplete[0]!r} lacks some of its X, Y, Z columns")
    rows = data_rows(lines[stop + 1:], ",")
    if "Total Exported Frames" in meta:
        try:
            expected = int(meta["Total Exported Frames"])
        except ValueError:
            raise HandcapError(f"{path}: Total Exported Frames must be a whole number") from None
        if len(rows) != expected:
            raise HandcapError(f"{path}: Total Exported Frames is {expected} but the file holds {len(rows)} data "
                               "rows; it is cut or damaged, export it again")
    if not rows:
        raise HandcapError(f"{path}: Motive CSV holds no frames")
    check_complete(text, path, "the CSV file")
    rows = uniform_rows(rows, width, path, stop + 2)
    names_out = list(columns)
    take = [columns[n][a] for n in names_out for a in "XYZ"] + [0]
    cells = np.array(rows, dtype=str).reshape(len(rows), width)[:, take]
    values = floats(cells, path, lambda r, c: f"line {stop + r + 2}, column {take[c] + 1} "
                                              f"({f'{names[take[c]].strip()} {axes[take[c]]}'.strip()}),")
    frame = values[:, -1]
    if np.isnan(frame).any() or (np.diff(frame) <= 0).any():
        raise HandcapError(f"{path}: the Frame column is not strictly increasing; the file is damaged")
    positions = values[:, :-1].reshape(len(rows), len(names_out), 3) * scale
    try:
        markers = MarkerSequence(positions, names_out, rate)
    except HandcapError as err:
        raise HandcapError(f"{path}: {err}") from None
    return settle_marker_units(markers, declared=declared, units=units, where=path, hand=hand)
