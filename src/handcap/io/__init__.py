"""File formats. Everything is converted to metres at this boundary.

Marker files are chosen by extension:

========  =================================  ==============
suffix    format                             read / write
========  =================================  ==============
``.c3d``  C3D (ezc3d), POINT:UNITS honoured   read, write
``.tsv``  Qualisys QTM TSV export            read
``.csv``  OptiTrack Motive CSV (1.2x),       read
          Vicon Nexus CSV (Trajectories)
``.txt``  Vicon Nexus ASCII (tab-separated)  read
``.trc``  TRC (OpenSim / Motion Analysis)    read, write
``.npz``  handcap's own                      read, write
========  =================================  ==============

The UCI hand-postures table (static, unlabeled records, no frame rate) is not a
marker file: read it with :func:`read_uci_postures`.

Units are settled at this boundary (:mod:`handcap.io._units`): ``units=``
(``--units``) overrides what a file says; a file whose own unit makes its data
implausible (a hand 200 m wide) is read in the one unit that fits, with a
warning, or refused with one line when no unit or several fit.
"""

from __future__ import annotations

from pathlib import Path

from handcap.core.errors import HandcapError
from handcap.core.markers import MarkerSequence
from handcap.core.points import PointCloudSequence
from handcap.core.files import (
    atomic_output,
    check_not_input,
    check_output,
    check_output_folder,
    existing_file,
    load_npz,
    save_npz,
)
from handcap.io._units import UNITS
from handcap.io.c3d import read_c3d, write_c3d
from handcap.io.camera_formats import read_rig, write_rig
from handcap.io.meshes import read_mesh, read_scan_points
from handcap.io.motive import read_motive_csv
from handcap.io.npz import (
    npz_kind,
    read_hand_motion,
    read_markers_npz,
    read_object_motion,
    read_points_npz,
    write_hand_motion,
    write_markers_npz,
    write_object_motion,
    write_points_npz,
)
from handcap.io.qualisys import read_qualisys_tsv
from handcap.io.trc import read_trc, write_trc
from handcap.io.uci import UciPostures, read_uci_postures
from handcap.io.vicon import is_vicon_csv, read_vicon_csv



def read_marker_csv(path, *, units: str | None = None, hand=None) -> MarkerSequence:
    """Read a marker CSV: a Vicon Nexus export (:func:`read_vicon_csv`; its first line names a section, such as
    ``Trajectories``) or else an OptiTrack Motive one (:func:`read_motive_csv`).

    Parameters
    ----------
    path : str or Path
    units : {"mm", "cm", "m"}, optional
        The unit of the coordinates, overriding the file's.
    hand : sequence of str, optional
        Names of one hand's markers, whose spread tells the unit when the file's is implausible.

    Returns
    -------
    MarkerSequence
        Positions (T, M, 3) in metres, NaN where missing.
    """
    with open(existing_file(path), "rb") as file:
        head = file.read(65536).decode("utf-8-sig", errors="replace")
    return (read_vicon_csv if is_vicon_csv(head) else read_motive_csv)(path, units=units, hand=hand)


MARKER_READERS = {".c3d": read_c3d, ".tsv": read_qualisys_tsv, ".csv": read_marker_csv, ".txt": read_vicon_csv,
                  ".trc": read_trc, ".npz": read_markers_npz}
MARKER_WRITERS = {".c3d": write_c3d, ".trc": write_trc, ".npz": write_markers_npz}


def marker_suffix(path, *, write: bool = False) -> str:
    """The lower-case extension of a marker file handcap can read (or, with ``write``, write).

    Parameters
    ----------
    path : str or Path
        The file name; the file need not exist.
    write : bool
        Check against the formats handcap writes instead of those it reads.

    Returns
    -------
    str
        The suffix, lower case with its dot (``".c3d"``).

    Raises
    ------
    HandcapError
        An extension not in the table, naming those it can.
    """
    table, verb = (MARKER_WRITERS, "write") if write else (MARKER_READERS, "read")
    suffix = Path(path).suffix.lower()
    if suffix not in table:
        raise HandcapError(f"{path}: cannot {verb} '{suffix or 'no extension'}' marker files; "
                           f"use one of {', '.join(sorted(table))}")
    return suffix


def read_markers(path, *, partial: bool = False, units: str | None = None, hand=None) -> MarkerSequence:
    """Read labeled markers from any supported file (format from the extension).

    Parameters
    ----------
    path : str or Path
    partial : bool
        C3D only: keep the complete frames of a file shorter than its header
        promises (see :func:`read_c3d`) instead of refusing it.
    units : {"mm", "cm", "m"}, optional
        The unit of the file's coordinates, overriding what the file says (or
        its format's usual unit).
    hand : sequence of str, optional
        Names of one hand's markers (a layout's); their spread, 3-35 cm for a
        hand, tells the unit when the file's own is implausible.

    Returns
    -------
    MarkerSequence
        Positions in metres, NaN where missing; ``warnings`` say if the unit
        was not the file's.

    Raises
    ------
    HandcapError
        Unknown extension, unreadable, truncated or inconsistent file, or
        coordinates that fit no unit (or several, when the file's does not).
    """
    suffix = marker_suffix(path)
    existing_file(path)
    if partial:
        if suffix != ".c3d":
            raise HandcapError(f"{path}: reading part of a file is possible for C3D files only")
        return read_c3d(path, partial=True, units=units, hand=hand)
    return MARKER_READERS[suffix](path, units=units, hand=hand)


def write_markers(markers: MarkerSequence, path) -> None:
    """Write ``markers`` to ``path`` (format from the extension), atomically.

    Parameters
    ----------
    markers : MarkerSequence
        Positions (T, M, 3) in metres, NaN where missing; each writer stores them in its
        format's unit.
    path : str or Path
        ``.c3d``, ``.trc`` or ``.npz``.

    Raises
    ------
    HandcapError
        An extension handcap cannot write, or the file cannot be written.
    """
    writer = MARKER_WRITERS[marker_suffix(path, write=True)]
    writer(markers, path)


def read_points(path, *, units: str | None = None) -> PointCloudSequence:
    """Read unlabeled points: a points ``.npz``, or any marker file with its labels ignored.

    Parameters
    ----------
    path : str or Path
        A points ``.npz`` or any marker file :func:`read_markers` reads.
    units : {"mm", "cm", "m"}, optional
        The unit of the file's coordinates, as for :func:`read_markers`.

    Returns
    -------
    PointCloudSequence
        Points (K_t, 3) per frame, metres.
    """
    if Path(path).suffix.lower() == ".npz" and npz_kind(path) == "points":
        return read_points_npz(path, units=units)
    return PointCloudSequence.from_markers(read_markers(path, units=units))


def write_points(points: PointCloudSequence, path) -> None:
    """Write unlabeled points as a ``.npz`` (NaN-padded ``points (T, K, 3)``, ``rate``).

    Parameters
    ----------
    points : PointCloudSequence
        Points in metres, written as they are.
    path : str or Path
        Must end in ``.npz``.

    Raises
    ------
    HandcapError
        Another extension, or the file cannot be written.
    """
    if Path(path).suffix.lower() != ".npz":
        raise HandcapError(f"{path}: unlabeled points are written as .npz")
    write_points_npz(points, path)


def convert(source, target, *, partial: bool = False, units: str | None = None) -> MarkerSequence:
    """Convert a marker file to another format; never writes over ``source``.

    Parameters
    ----------
    source : str or Path
        Any marker file :func:`read_markers` reads.
    target : str or Path
        ``.c3d``, ``.trc`` or ``.npz``; checked before reading (not ``source``, a writable folder).
    partial : bool
        C3D only: keep the complete frames of a truncated ``source`` (see :func:`read_markers`).
    units : {"mm", "cm", "m"}, optional
        Overrides the unit of ``source`` (see :func:`read_markers`).

    Returns
    -------
    MarkerSequence
        The markers written, metres, with their warnings.
    """
    check_output(target, source)
    markers = read_markers(source, partial=partial, units=units)
    write_markers(markers, target)
    return markers


__all__ = [
    "UNITS", "UciPostures", "atomic_output", "check_not_input", "check_output", "check_output_folder", "convert",
    "existing_file", "load_npz", "marker_suffix", "npz_kind",
    "read_c3d", "read_hand_motion", "read_marker_csv", "read_markers", "read_markers_npz", "read_mesh",
    "read_motive_csv", "read_object_motion", "read_points", "read_points_npz", "read_qualisys_tsv", "read_rig",
    "read_scan_points", "read_trc", "read_vicon_csv",
    "read_uci_postures", "save_npz", "write_c3d", "write_hand_motion", "write_markers", "write_markers_npz",
    "write_object_motion", "write_points", "write_points_npz", "write_rig", "write_trc",
]
