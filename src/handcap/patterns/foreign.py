"""Templates of patches printed by another generator: DexterCap's patch JSON as a handcap ``pattern.toml``.

A lab that printed its patches with DexterCap's generator has them taped on already, and has that generator's
template: a JSON object ``{patch_name: [row, ...]}`` whose rows concatenate two-glyph cells, ``**`` for a black
square (``["9F**CF**EF**", "**8L**9L**CL", ...]``). The grid conventions are handcap's
(:mod:`~handcap.patterns.pattern`): markers are the grid's vertices, row-major, a cell's first glyph is the
underlined one and its corners in reading order are top-left, top-right, bottom-right, bottom-left. So
:func:`import_template` only has to carry the grids over, give each patch an owner (a hand side or an object's
name), and settle what handcap's template refuses:

- a tag printed on two squares (that generator's counter starts again after ``L * L - 2`` tags, so a big session
  repeats tags): neither square can name its corners, so both are written as plain squares (``""``) and a warning
  names them; their corners are still named through the neighbouring squares;
- glyphs the shipped reader does not know, cells that are not two glyphs, rows of unequal length: one clear error.

With the template, ``handcap detect --pattern`` reads such patches through the vote over each patch, which reads
far more of them than the reader alone does without a template (README, "Patches printed by another generator").

Rows may also be lists of cells, or cells separated by spaces (``"9F ** CF"``), as a template typed by hand is.
"""

from __future__ import annotations

import json
from fnmatch import fnmatchcase
from pathlib import Path

from handcap.core.errors import HandcapError
from handcap.core.files import existing_file
from handcap.patterns.alphabet import READABLE, check_alphabet
from handcap.patterns.pattern import PITCH, Patch, Pattern

#: The cell of a black square in the imported rows.
BLACK = "**"
#: Largest template file read, bytes (a session's template is a few kilobytes).
MAX_BYTES = 20_000_000
#: Owner of the patches no ``owners`` rule matches.
DEFAULT_OWNER = "right"


def read_grids(path) -> dict[str, list[list[str]]]:
    """The patch grids of another generator's template file: patch name -> rows of two-glyph cells.

    Parameters
    ----------
    path : str or Path
        A JSON object ``{patch_name: [row, ...]}``; a row is a string of two-glyph cells (``"9F**CF"``), the cells
        separated by spaces or not, or a list of cells. ``**`` is a black square.

    Returns
    -------
    dict
        Patch name -> list of rows, each a list of cells (``"**"`` for black), in the file's order.

    Raises
    ------
    HandcapError
        A file that is not such a JSON object, a row that is not whole two-glyph cells, or rows of unequal length.
    """
    path = existing_file(path)
    if path.stat().st_size > MAX_BYTES:
        raise HandcapError(f"{path}: {path.stat().st_size} bytes is too big for a patch template (at most "
                           f"{MAX_BYTES}); give the generator's JSON of patch grids")
    try:
        doc = json.loads(path.read_bytes().decode("utf-8"))
    except UnicodeDecodeError:
        raise HandcapError(f"{path}: not a patch template (not UTF-8 text); give the generator's JSON of patch "
                           "grids, {patch_name: [row, ...]}") from None
    except (json.JSONDecodeError, RecursionError) as err:
        raise HandcapError(f"{path}: not valid JSON ({err}); give the generator's JSON of patch grids, "
                           "{patch_name: [row, ...]}") from None
    if not isinstance(doc, dict) or not doc:
        raise HandcapError(f"{path}: a patch template is a JSON object of patch grids, {{patch_name: [row, ...]}}; "
                           f"this one holds {type(doc).__name__ if doc else 'nothing'}")
    grids = {}
    for name, rows in doc.items():
        if not isinstance(rows, list) or not rows:
            raise HandcapError(f"{path}: patch {name!r}: give its rows as a list of strings, e.g. "
                               "[\"9F**CF\", \"**8L**\"]")
        grid = [_cells(path, name, k, row) for k, row in enumerate(rows)]
        if any(len(row) != len(grid[0]) for row in grid):
            lengths = sorted({len(row) for row in grid})
            raise HandcapError(f"{path}: patch {name!r}: its rows hold {' and '.join(map(str, lengths))} cells; "
                               "every row of a patch has one length")
        grids[str(name)] = grid
    return grids


def _cells(path: Path, name, k: int, row) -> list[str]:
    """One row's cells (see :func:`read_grids`)."""
    if isinstance(row, list):
        cells = row
    elif isinstance(row, str):
        text = row.strip()
        cells = text.split() if any(ch.isspace() for ch in text) else [text[i:i + 2] for i in range(0, len(text), 2)]
    else:
        cells = None
    if not cells or not all(isinstance(c, str) and len(c) == 2 and not any(ch.isspace() for ch in c)
                            for c in cells):
        raise HandcapError(f"{path}: patch {name!r}, row {k}: {row!r} is not a row of two-glyph cells "
                           f"(\"{BLACK}\" for a black square)")
    return list(cells)


def owner_rule(spec: str) -> tuple[str, str]:
    """``GLOB=OWNER`` as ``(glob, owner)``: the patches whose name matches the shell pattern belong to the owner.

    Parameters
    ----------
    spec : str
        E.g. ``cube_*=cube`` or ``*=left``.

    Returns
    -------
    (str, str)
    """
    glob, sep, owner = str(spec).partition("=")
    if not sep or not glob.strip() or not owner.strip():
        raise HandcapError(f"--owner {spec!r}: give PATCHES=OWNER, e.g. 'cube_*=cube' or '*=left' (a shell "
                           "pattern of patch names, then a hand side or an object's name)")
    return glob.strip(), owner.strip()


def import_template(path, *, owners=(), alphabet: str | None = None, pitch: float = PITCH) -> tuple[Pattern, list]:
    """Another generator's template (:func:`read_grids`) as a handcap :class:`~handcap.patterns.pattern.Pattern`.

    Parameters
    ----------
    path : str or Path
        The generator's JSON of patch grids.
    owners : sequence of str or (str, str)
        ``GLOB=OWNER`` rules (:func:`owner_rule`), the first that matches a patch's name wins; patches no rule
        matches belong to :data:`DEFAULT_OWNER`.
    alphabet : str, optional
        The glyphs, in the generator's order (default: those the tags use, digits then letters then others).
    pitch : float
        Side of a square, metres.

    Returns
    -------
    pattern : Pattern
    warnings : list of str
        Tags printed on more than one square (written as plain squares), patches left without a tag (dropped).

    Raises
    ------
    HandcapError
        A bad file (:func:`read_grids`), a glyph outside ``alphabet`` or unknown to the shipped reader, a patch
        name handcap cannot use.
    """
    grids = read_grids(path)
    rules = [owner_rule(r) if isinstance(r, str) else tuple(r) for r in owners]
    used = sorted({ch for grid in grids.values() for row in grid for cell in row if cell != BLACK for ch in cell},
                  key=lambda ch: (not ch.isdigit(), not ch.isalpha(), ch))
    if not used:
        raise HandcapError(f"{path}: no patch holds a tag (every cell is {BLACK}); nothing to detect")
    if alphabet is None:
        alphabet = "".join(used)
    check_alphabet(alphabet)
    foreign = [ch for ch in used if ch not in alphabet]
    if foreign:
        raise HandcapError(f"{path}: the tags use {''.join(foreign)!r}, which is not in the alphabet {alphabet!r}")
    unreadable = [ch for ch in alphabet if ch not in READABLE]
    if unreadable:
        raise HandcapError(f"{path}: the detector's reader knows no glyph {''.join(unreadable)!r} (it reads "
                           f"{READABLE}); such patches cannot be read")
    places: dict[str, list] = {}
    for name, grid in grids.items():
        for r, row in enumerate(grid):
            for c, cell in enumerate(row):
                if cell != BLACK:
                    places.setdefault(cell, []).append((name, r, c))
    twice = {tag: at for tag, at in places.items() if len(at) > 1}
    warnings = []
    if twice:
        shown = "; ".join(f"{tag} on " + ", ".join(f"{n} r{r}c{c}" for n, r, c in at[:3])
                          for tag, at in list(twice.items())[:3])
        squares = sum(len(at) for at in twice.values())
        many = f"{len(twice)} tags are" if len(twice) > 1 else "1 tag is"
        warnings.append(f"{path}: {many} printed on more than one square ({squares} squares; {shown}"
                        f"{' ...' if len(twice) > 3 else ''}): a reading of one cannot say which square it is, so "
                        "these squares name no corner (their corners are named through the squares beside them)")
    patches, empty = [], []
    for name, grid in grids.items():
        owner = next((o for glob, o in rules if fnmatchcase(name, glob)), DEFAULT_OWNER)
        tags = tuple(tuple("" if cell == BLACK or cell in twice else cell for cell in row) for row in grid)
        if not any(any(row) for row in tags):
            empty.append(name)
            continue
        segment = "unknown" if owner in ("right", "left") else f"object:{owner}"  # where on the hand: not in the file
        patches.append(Patch(name, owner, segment, tags))
    if empty:
        warnings.append(f"{path}: {len(empty)} patches are left without a tag of their own and are not in the "
                        f"template: {', '.join(empty[:6])}{' ...' if len(empty) > 6 else ''}")
    if not patches:
        raise HandcapError(f"{path}: no patch keeps a tag of its own; nothing to detect")
    try:
        return Pattern(tuple(patches), alphabet, pitch, ""), warnings
    except HandcapError as err:
        raise HandcapError(f"{path}: {err}") from None
