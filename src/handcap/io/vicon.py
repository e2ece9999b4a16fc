"""Vicon Nexus CSV exports of marker trajectories (and its tab-separated ``.txt`` exports).

Layout, as Nexus 2 writes it (Export ASCII, or File > Export > CSV; a ``.txt`` export has tabs for commas)::

    Devices                              <- other sections, before or after: skipped
    1000
    ...
    (blank line)
    Trajectories                         <- the section read
    100                                  <- frames per second
    ,,Sub:LASI,,,Sub:RASI,,,*12,,,        <- one name per marker, above its X column
    Frame,Sub Frame,X,Y,Z,X,Y,Z,X,Y,Z
    ,,mm,mm,mm,mm,mm,mm,mm,mm,mm
    1,0,120.51,-33.2,870.1,...
    (blank line, or the file's end)

Only the ``Trajectories`` section is read: one marker per name of its name row,
from the columns named ``X``, ``Y`` and ``Z`` under it (the velocity and
acceleration columns ``X'`` ... ``Z''`` an export may add are skipped).
Labelled markers keep their ``Subject:`` prefix; unlabelled trajectories
(``*12``) keep their names, so that ``handcap label`` sees every point. Empty
cells are missing samples. The unit comes from the units row (``mm``, ``cm``,
``m``; Nexus's ``mm`` where the row is absent). Frame numbers may start
anywhere (a cropped trial); a frame number the file skips is a frame of
missing samples, and a warning says how many there were.
"""

from __future__ import annotations

import csv
import re

import numpy as np

from handcap.core.errors import HandcapError, warn
from handcap.core.markers import MarkerSequence
from handcap.io._text import check_complete, floats, read_text, uniform_rows
from handcap.io._units import check_units, metres_per_unit, settle_marker_units, unit_name

_WHAT = "a Vicon Nexus CSV export"
#: Section names Nexus writes; a file that shows one of them first is a Nexus export.
SECTIONS = ("Trajectories", "Devices", "Model Outputs", "Joints", "Segments")


def is_vicon_csv(text: str) -> bool:
    """Whether ``text`` (a CSV or ``.txt`` file's decoded text) starts, after blank lines, with a Nexus section name.

    Parameters
    ----------
    text : str

    Returns
    -------
    bool
    """
    for line in text.splitlines()[:50]:
        if line.strip(" ,\t"):
            return re.split("[,\t]", line)[0].strip() in SECTIONS
    return False


def _separator(lines: list[str]) -> str:
    """A tab where the file's first lines hold more tabs than commas (a ``.txt`` export), else a comma."""
    head = "".join(lines[:30])
    return "\t" if head.count("\t") > head.count(",") else ","


def _section(lines: list[str], sep: str, path) -> int:
    """The line index of the ``Trajectories`` section's name."""
    for k, line in enumerate(lines):
        cells = line.split(sep)
        if cells[0].strip() == "Trajectories" and not "".join(cells[1:]).strip():
            return k
    found = sorted({line.split(sep)[0].strip() for line in lines if line.split(sep)[0].strip() in SECTIONS})
    raise HandcapError(f"{path}: {_WHAT} without a Trajectories section (it holds {', '.join(found) or 'none'}); "
                       "export again with Trajectories ticked")


def _rate(cell: str, path, line: int) -> float:
    try:
        rate = float(cell.strip())
    except ValueError:
        raise HandcapError(f"{path}: line {line} should give the Trajectories' frame rate in Hz, "
                           f"got {cell.strip()[:20]!r}") from None
    if not np.isfinite(rate) or rate <= 0:
        raise HandcapError(f"{path}: line {line}: the Trajectories' frame rate is {cell.strip()}")
    return rate


def _markers(names: list[str], roles: list[str], path, line: int) -> dict[str, list[int]]:
    """Each marker's X, Y, Z column indices, from the name row and the row of column roles below it."""
    starts = [k for k in range(2, len(names)) if names[k].strip()]
    columns: dict[str, list[int]] = {}
    for s, start in enumerate(starts):
        name = names[start].strip()
        if name in columns:
            raise HandcapError(f"{path}: line {line} names marker {name!r} twice")
        group = range(start, starts[s + 1] if s + 1 < len(starts) else len(roles))
        axes = {roles[k].strip(): k for k in group if k < len(roles)}
        if not all(a in axes for a in "XYZ"):
            raise HandcapError(f"{path}: marker {name!r} lacks some of its X, Y, Z columns (line {line + 1})")
        columns[name] = [axes[a] for a in "XYZ"]
    if not columns:
        raise HandcapError(f"{path}: the Trajectories section names no marker (line {line}); "
                           "export again with markers")
    return columns


def read_vicon_csv(path, *, units: str | None = None, hand=None) -> MarkerSequence:
    """Read the marker trajectories of a Vicon Nexus CSV export (its ``Trajectories`` section).

    Parameters
    ----------
    path : str or Path
        A ``.csv`` written by Nexus with Trajectories included.
    units : {"mm", "cm", "m"}, optional
        The unit of the coordinates, overriding the file's units row.
    hand : sequence of str, optional
        Names of one hand's markers, whose spread tells the unit when the
        file's is implausible (see :mod:`handcap.io._units`).

    Returns
    -------
    MarkerSequence
        ``positions`` (T, M, 3) in metres, NaN where a cell is empty or a frame
        number is skipped; one marker per name, labelled and unlabelled, named
        as in the file.

    Raises
    ------
    HandcapError
        If the file is no Nexus export or has no Trajectories section, its
        header rows are damaged, its rows disagree with them, its frame numbers
        do not increase, or the coordinates fit no length unit.
    """
    units = check_units(units)
    path, text = read_text(path, _WHAT)
    lines = text.splitlines()
    if not is_vicon_csv(text):
        raise HandcapError(f"{path}: not {_WHAT} (its first line should name a section, such as Trajectories)")
    sep = _separator(lines)
    top = _section(lines, sep, path)
    if top + 4 >= len(lines):
        raise HandcapError(f"{path}: the Trajectories section stops within its header rows; the file is cut")
    rate = _rate(lines[top + 1].split(sep)[0], path, top + 2)
    names, roles = (next(csv.reader([lines[top + k]], delimiter=sep)) for k in (2, 3))
    if [c.strip() for c in roles[:2]] != ["Frame", "Sub Frame"]:
        raise HandcapError(f"{path}: line {top + 4} should start with the columns Frame and Sub Frame; "
                           "the file is damaged")
    columns = _markers(names, roles, path, top + 3)
    xyz = [k for axes in columns.values() for k in axes]
    first = top + 4
    if not lines[first].strip(" ,\t"):
        raise HandcapError(f"{path}: the Trajectories section holds no frames")
    unit_cells = next(csv.reader([lines[first]], delimiter=sep))
    declared = "mm"
    if not unit_cells[0].strip():  # the units row (Nexus 2 always writes it)
        found = {unit_cells[k].strip() for k in xyz if k < len(unit_cells)}
        if len(found) != 1:
            raise HandcapError(f"{path}: line {first + 1} gives the markers {len(found) or 'no'} units "
                               f"({', '.join(sorted(found))}); expected one length unit")
        unit = found.pop()
        metres_per_unit(unit, f"{path}: line {first + 1}")
        declared = unit_name(unit)
        first += 1
    end = next((k for k in range(first, len(lines)) if not lines[k].strip(" ,\t")), len(lines))
    if end == first:
        raise HandcapError(f"{path}: the Trajectories section holds no frames")
    if end == len(lines):
        check_complete(text, path, "the CSV file")
    width = len(roles)
    rows = uniform_rows([line.split(sep) for line in lines[first:end]], width, path, first + 1)
    take = xyz + [0]
    cells = np.array(rows, dtype=str).reshape(len(rows), width)[:, take]
    values = floats(cells, path, lambda r, c: f"line {first + r + 1}, column {take[c] + 1} "
                                              f"({roles[take[c]].strip() or 'Frame'}),")
    frame = values[:, -1]
    if np.isnan(frame).any() or (frame != np.round(frame)).any():
        raise HandcapError(f"{path}: the Frame column holds a cell that is no whole number; the file is damaged")
    step = np.diff(frame)
    if (step <= 0).any():
        bad = int(np.flatnonzero(step <= 0)[0])
        raise HandcapError(f"{path}: line {first + bad + 2}: frame {frame[bad + 1]:.0f} follows frame "
                           f"{frame[bad]:.0f}; the frame numbers must increase")
    if frame[-1] - frame[0] + 1 > 2 * len(rows):
        bad = int(np.argmax(step))
        raise HandcapError(f"{path}: line {first + bad + 2}: frame {frame[bad + 1]:.0f} follows frame "
                           f"{frame[bad]:.0f}, and more frame numbers have no row than have one; the file is damaged")
    scale = metres_per_unit(units or declared, "units")
    positions = np.full((int(frame[-1] - frame[0]) + 1, len(columns), 3), np.nan)
    positions[(frame - frame[0]).astype(int)] = values[:, :-1].reshape(len(rows), len(columns), 3) * scale
    try:
        markers = MarkerSequence(positions, list(columns), rate)
    except HandcapError as err:
        raise HandcapError(f"{path}: {err}") from None
    skipped = len(positions) - len(rows)
    if skipped:
        markers = markers.with_warnings(warn(
            f"{path}: {skipped} frame number(s) between {frame[0]:.0f} and {frame[-1]:.0f} have no row; "
            "read as frames of missing samples"))
    return settle_marker_units(markers, declared=declared, units=units, where=path, hand=hand)
