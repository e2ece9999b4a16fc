"""Shared plumbing of the text marker formats (TSV, CSV, TRC): decoding and numbers."""

from __future__ import annotations

import numpy as np

from handcap.core.errors import HandcapError
from handcap.core.files import existing_file

# Cells that mean "no sample": empty, and the spellings of NaN that exporters write.
MISSING_TOKENS = ("", "nan", "NaN", "NAN", "null", "NULL", "Null")


def read_text(path, what: str) -> tuple:
    """``(path, text)`` of a text file, checked not to be empty or binary.

    Parameters
    ----------
    path : str or Path
    what : str
        What the file should be (``"a Qualisys TSV export"``), for messages.

    Raises
    ------
    HandcapError
        Missing, empty or binary file.
    """
    path = existing_file(path)
    data = path.read_bytes()
    if not data.strip():
        raise HandcapError(f"{path}: empty file, expected {what}")
    if b"\0" in data[:65536]:
        raise HandcapError(f"{path}: binary data, not {what}; check the file and its extension")
    try:
        text = data.decode("utf-8-sig")
    except UnicodeDecodeError:
        text = data.decode("latin-1")
    return path, text


def check_complete(text: str, path, what: str) -> None:
    """Refuse a text file that stops in the middle of a line (a cut copy).

    Parameters
    ----------
    text : str
        The file's decoded text.
    path : Path
        For messages.
    what : str
        What the file is (``"the TRC file"``), for messages.

    Raises
    ------
    HandcapError
        ``text`` does not end with a line break.
    """
    if not text.endswith(("\n", "\r")):
        raise HandcapError(f"{path}: {what} ends in the middle of a line, so it looks truncated; "
                           "copy or export it again (if it is complete, end it with a line break)")


def data_rows(lines: list[str], sep: str) -> list[list[str]]:
    """Split data lines into cells, dropping blank lines at the end only.

    Parameters
    ----------
    lines : list of str
        The data lines, without line breaks.
    sep : str
        Cell separator (a tab or a comma).

    Returns
    -------
    list of list of str
        One list of cells per line kept; cells are not stripped.
    """
    end = len(lines)
    while end and not lines[end - 1].strip():
        end -= 1
    return [line.split(sep) for line in lines[:end]]


def uniform_rows(rows: list[list[str]], width: int, path, first_line: int) -> list[list[str]]:
    """Rows cut to ``width`` cells, checked to agree on their length.

    Writers that end every line with a separator give each row one empty cell
    more than it has columns; that is accepted when all rows do it, so that a
    row that lost or gained a value still stands out.

    Parameters
    ----------
    rows : list of list of str
    width : int
        Number of columns the header promises.
    path : Path
        For messages.
    first_line : int
        Line number (1-based) of ``rows[0]`` in the file.

    Raises
    ------
    HandcapError
        If the rows do not all have ``width`` cells (or all ``width`` plus an
        empty one).
    """
    if not rows:
        return rows
    lengths = [len(row) for row in rows]
    usual = max(set(lengths), key=lengths.count)
    if usual not in (width, width + 1):
        raise HandcapError(f"{path}: data lines have {usual} cells, expected {width}; the file is damaged")
    bad = next((r for r, row in enumerate(rows) if len(row) != usual or "".join(row[width:]).strip()), None)
    if bad is not None:
        raise HandcapError(f"{path}: line {first_line + bad} has {len(rows[bad])} cells, the other data lines "
                           f"{usual}; the file is damaged")
    return rows if usual == width else [row[:width] for row in rows]


def floats(cells: np.ndarray, path, describe) -> np.ndarray:
    """Parse a 2-D array of strings into float64, NaN for the missing tokens.

    Parameters
    ----------
    cells : ndarray of str, shape (R, C)
    path : Path
        For messages.
    describe : callable
        ``describe(r, c)`` says where cell (r, c) is, in the file's terms.

    Raises
    ------
    HandcapError
        For the first cell that is not a number, or is infinite.
    """
    cells = np.char.strip(cells) if cells.size else cells.astype(str)
    cells = np.where(np.isin(cells, MISSING_TOKENS), "nan", cells)
    try:
        values = cells.astype(np.float64)
    except ValueError:
        values = None
    if values is None:
        for (r, c), cell in np.ndenumerate(cells):
            try:
                float(cell)
            except ValueError:
                raise HandcapError(f"{path}: {describe(r, c)} holds {cell[:20]!r}, not a number; "
                                   "fix or export the file again") from None
        raise HandcapError(f"{path}: a cell is not a number; fix or export the file again")
    if np.isinf(values).any():
        r, c = np.argwhere(np.isinf(values))[0]
        raise HandcapError(f"{path}: {describe(r, c)} is infinite; use an empty cell for a missing sample")
    return values
