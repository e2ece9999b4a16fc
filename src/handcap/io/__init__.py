"""File formats. Everything is converted to metres at this boundary.

Marker files are chosen by extension:

========  =================================  ==============
suffix    format                             read / write
========  =================================  ==============
``.c3d``  C3D (ezc3d), POINT:UNITS honoured   read, write
``.tsv``  Qualisys QTM TSV export            read
``.csv``  OptiTrack Motive CSV (1.2x)        read
``.trc``  TRC (OpenSim / Motion Analysis)    read, write
``.npz``  handcap's own                      read, write
========  =================================  ==============

The UCI hand-postures table (static, unlabeled records, no frame rate) is not a
marker file: read it with :func:`read_uci_postures`.
"""

from __future__ import annotations

from pathlib import Path

from handcap.core.errors import HandcapError
from handcap.core.markers import MarkerSequence
from handcap.core.points import PointCloudSequence
from handcap.io._files import atomic_output, check_not_input, existing_file, load_npz, save_npz
from handcap.io.c3d import read_c3d, write_c3d
from handcap.io.camera_formats import read_rig, write_rig
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

MARKER_READERS = {".c3d": read_c3d, ".tsv": read_qualisys_tsv, ".csv": read_motive_csv,
                  ".trc": read_trc, ".npz": read_markers_npz}
MARKER_WRITERS = {".c3d": write_c3d, ".trc": write_trc, ".npz": write_markers_npz}


def _suffix(path, table, verb: str) -> str:
    suffix = Path(path).suffix.lower()
    if suffix not in table:
        raise HandcapError(f"{path}: cannot {verb} '{suffix or 'no extension'}' marker files; "
                           f"use one of {', '.join(sorted(table))}")
    return suffix


def read_markers(path, *, partial: bool = False) -> MarkerSequence:
    """Read labeled markers from any supported file (format from the extension).

    Parameters
    ----------
    path : str or Path
    partial : bool
        C3D only: keep the complete frames of a file shorter than its header
        promises (see :func:`read_c3d`) instead of refusing it.

    Returns
    -------
    MarkerSequence
        Positions in metres, NaN where missing.

    Raises
    ------
    HandcapError
        Unknown extension, unreadable, truncated or inconsistent file.
    """
    suffix = _suffix(path, MARKER_READERS, "read")
    existing_file(path)
    if partial:
        if suffix != ".c3d":
            raise HandcapError(f"{path}: reading part of a file is possible for C3D files only")
        return read_c3d(path, partial=True)
    return MARKER_READERS[suffix](path)


def write_markers(markers: MarkerSequence, path) -> None:
    """Write ``markers`` to ``path`` (format from the extension), atomically."""
    writer = MARKER_WRITERS[_suffix(path, MARKER_WRITERS, "write")]
    writer(markers, path)


def read_points(path) -> PointCloudSequence:
    """Read unlabeled points: a points ``.npz``, or any marker file with its labels ignored."""
    if Path(path).suffix.lower() == ".npz" and npz_kind(path) == "points":
        return read_points_npz(path)
    return PointCloudSequence.from_markers(read_markers(path))


def write_points(points: PointCloudSequence, path) -> None:
    """Write unlabeled points as a ``.npz`` (NaN-padded ``points (T, K, 3)``, ``rate``)."""
    if Path(path).suffix.lower() != ".npz":
        raise HandcapError(f"{path}: unlabeled points are written as .npz")
    write_points_npz(points, path)


def convert(source, target, *, partial: bool = False) -> MarkerSequence:
    """Convert a marker file to another format; never writes over ``source``."""
    check_not_input(target, source)
    markers = read_markers(source, partial=partial)
    write_markers(markers, target)
    return markers


__all__ = [
    "UciPostures", "atomic_output", "check_not_input", "convert", "existing_file", "load_npz", "npz_kind",
    "read_c3d", "read_hand_motion", "read_markers", "read_markers_npz", "read_motive_csv",
    "read_object_motion", "read_points", "read_points_npz", "read_qualisys_tsv", "read_rig", "read_trc",
    "read_uci_postures", "save_npz", "write_c3d", "write_hand_motion", "write_markers", "write_markers_npz",
    "write_object_motion", "write_points", "write_points_npz", "write_rig", "write_trc",
]
