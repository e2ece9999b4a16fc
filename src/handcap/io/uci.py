"""The UCI "MoCap Hand Postures" table (Gardner et al.): static records of a Vicon glove.

Each row of ``Postures.csv`` is one record: ``Class,User,X0,Y0,Z0,...,X11,Y11,Z11``,
up to 12 unlabeled, unordered points in millimetres, in the local frame of a
rigid pattern on the back of the hand, ``?`` where a point is absent. Records
are independent (no frame rate), so they are not a :class:`MarkerSequence`.

Source: "MoCap Hand Postures", UCI Machine Learning Repository (Gardner et
al.), CC BY 4.0; see ``../shared/data/README.md``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from handcap.core.errors import HandcapError
from handcap.io._text import check_complete, data_rows, floats, read_text, uniform_rows

_WHAT = "the UCI hand-postures CSV"


@dataclass(frozen=True, eq=False)
class UciPostures:
    """Records of the UCI hand-postures table.

    Attributes
    ----------
    classes : ndarray of int, shape (N,)
        Posture class of each record.
    users : ndarray of int, shape (N,)
        Subject of each record.
    points : tuple of N ndarrays, each of shape (K_i, 3)
        The points present in record i, in metres, in file order (which is
        arbitrary: the points are unlabeled).
    """

    classes: np.ndarray
    users: np.ndarray
    points: tuple

    def __len__(self) -> int:
        return len(self.classes)

    @property
    def counts(self) -> np.ndarray:
        """Number of points in each record, shape (N,)."""
        return np.array([len(p) for p in self.points], dtype=int)


def read_uci_postures(path) -> UciPostures:
    """Read the UCI "MoCap Hand Postures" table (``Postures.csv``).

    Parameters
    ----------
    path : str or Path
        The CSV file: header ``Class,User,X0,Y0,Z0,...``, one record per row.

    Returns
    -------
    UciPostures
        Classes and users (N,), and each record's present points (K_i, 3) in
        metres; absent (``?``) points are dropped.

    Raises
    ------
    HandcapError
        If the header is not the UCI one, a row has the wrong number of cells,
        a cell is not a number or ``?``, or a point is only partly absent.
    """
    path, text = read_text(path, _WHAT)
    lines = text.splitlines()
    header = [c.strip() for c in lines[0].split(",")]
    n_points = (len(header) - 2) // 3
    expected = ["Class", "User"] + [f"{a}{k}" for k in range(n_points) for a in "XYZ"]
    if header != expected or n_points == 0:
        raise HandcapError(f"{path}: not {_WHAT} (its header should read Class,User,X0,Y0,Z0,...)")
    rows = data_rows(lines[1:], ",")
    if not rows:
        raise HandcapError(f"{path}: {_WHAT} holds no records")
    check_complete(text, path, "the CSV file")
    rows = uniform_rows(rows, len(header), path, 2)
    cells = np.array(rows, dtype=str).reshape(len(rows), len(header))
    cells = np.where(np.char.strip(cells) == "?", "nan", cells)
    values = floats(cells, path, lambda r, c: f"line {r + 2}, column {header[c]!r},")
    labels = values[:, :2]
    if np.isnan(labels).any() or (labels != np.round(labels)).any():
        r = int(np.flatnonzero(np.isnan(labels).any(axis=1) | (labels != np.round(labels)).any(axis=1))[0])
        raise HandcapError(f"{path}: line {r + 2} has a Class or User that is not a whole number")
    coords = values[:, 2:].reshape(len(rows), n_points, 3) * 1e-3
    absent = np.isnan(coords)
    partial = absent.any(axis=2) & ~absent.all(axis=2)
    if partial.any():
        r, k = np.argwhere(partial)[0]
        raise HandcapError(f"{path}: line {r + 2}, point {k} is only partly absent ('?' in some of X, Y, Z)")
    present = ~absent[..., 0]
    points = tuple(c[p] for c, p in zip(coords, present))
    for p in points:
        p.setflags(write=False)
    classes, users = labels[:, 0].astype(int), labels[:, 1].astype(int)
    classes.setflags(write=False)
    users.setflags(write=False)
    return UciPostures(classes, users, points)
