"""The coded-patch template: every patch's grid of tags and the corner ids it implies.

A patch is a checkerboard of ``rows x cols`` squares of side ``pitch`` (5 mm by
default). Square ``(r, c)`` (row ``r`` counted downwards, column ``c`` to the
right, as printed) is white when ``r + c`` is even and carries a tag of two
glyphs; the others are black, and a black margin half a square wide surrounds
the patch so that every corner of a white square is a corner in the image.

The markers are the vertices of the grid (DexterCap, Sec. 3.2.4): vertex
``(r, c)`` of patch ``NAME`` on owner ``OWNER`` is the marker
``OWNER:NAME_r{r}c{c}``, for the ``(rows + 1) x (cols + 1)`` vertices that
touch a white square. The tag of square ``(r, c)`` names its four corners in
reading order (the underline at the bottom): top-left ``(r, c)``, top-right
``(r, c + 1)``, bottom-right ``(r + 1, c + 1)``, bottom-left ``(r + 1, c)``.
The owner is a hand side (``right``, ``left``) or an object's name; the hand
layouts name the same corners without the owner (``thumb_proximal_r0c0``), and
a prefix such as ``right:`` is ignored when names are matched.

:class:`Pattern` is that template, written to and read from ``pattern.toml``.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from handcap.core.errors import HandcapError
from handcap.core.files import atomic_output, read_toml
from handcap.patterns.alphabet import ALPHABET, check_alphabet
from handcap.layouts.file import toml_key, toml_value

#: Default side of a square, metres (DexterCap's 5 mm corner pitch).
PITCH = 0.005
_NAME = re.compile(r"^[A-Za-z0-9_.-]+$")
_FORMAT = "handcap-pattern"


@dataclass(frozen=True)
class Patch:
    """One printed patch: a checkerboard of tagged white squares.

    Attributes
    ----------
    name : str
        The patch's name, unique for its owner (``thumb_proximal``, ``U0``).
    owner : str
        ``right``/``left`` for a hand, else the object's name.
    segment : str
        The hand segment it is stuck on, or ``object:NAME``.
    tags : tuple of tuple of str
        ``rows x cols`` grid; the tag of each white square, ``""`` for a black one.
    """

    name: str
    owner: str
    segment: str
    tags: tuple[tuple[str, ...], ...]

    @property
    def rows(self) -> int:
        """Number of square rows."""
        return len(self.tags)

    @property
    def cols(self) -> int:
        """Number of square columns."""
        return len(self.tags[0])

    @property
    def key(self) -> str:
        """``OWNER:NAME``, the patch's name in a session."""
        return f"{self.owner}:{self.name}"

    def corner_name(self, r: int, c: int, *, owner: bool = True) -> str:
        """The marker name of grid vertex ``(r, c)``.

        Parameters
        ----------
        r, c : int
            Vertex row (0 to ``rows``) and column (0 to ``cols``).
        owner : bool
            Prefix the owner (``right:thumb_proximal_r0c0``); False gives the layout's name.

        Returns
        -------
        str
        """
        base = f"{self.name}_r{r}c{c}"
        return f"{self.owner}:{base}" if owner else base

    def blocks(self) -> list[tuple[str, int, int]]:
        """The white squares: ``(tag, r, c)`` row by row.

        Returns
        -------
        list of (str, int, int)
        """
        return [(t, r, c) for r, row in enumerate(self.tags) for c, t in enumerate(row) if t]

    def vertices(self) -> np.ndarray:
        """The grid vertices that are markers (touch a white square), row-major.

        Returns
        -------
        ndarray (K, 2) int
            ``(r, c)`` of each vertex.
        """
        white = np.array([[bool(t) for t in row] for row in self.tags])
        touched = np.zeros((self.rows + 1, self.cols + 1), dtype=bool)
        for dr in (0, 1):
            for dc in (0, 1):
                touched[dr:dr + self.rows, dc:dc + self.cols] |= white
        return np.argwhere(touched)

    def corner_names(self, *, owner: bool = True) -> list[str]:
        """Marker names of :meth:`vertices`, in the same order.

        Parameters
        ----------
        owner : bool
            Prefix the owner.

        Returns
        -------
        list of str
        """
        return [self.corner_name(int(r), int(c), owner=owner) for r, c in self.vertices()]

    def block_vertices(self, r: int, c: int) -> tuple[tuple[int, int], ...]:
        """Vertices of square ``(r, c)`` in reading order: top-left, top-right, bottom-right, bottom-left.

        Parameters
        ----------
        r, c : int
            Square row and column.

        Returns
        -------
        tuple of 4 (int, int)
        """
        return (r, c), (r, c + 1), (r + 1, c + 1), (r + 1, c)


def checker_tags(rows: int, cols: int, next_tag) -> tuple[tuple[str, ...], ...]:
    """A ``rows x cols`` checkerboard whose white squares (``r + c`` even) take tags from ``next_tag()``.

    Parameters
    ----------
    rows, cols : int
        Grid size, 1 or more each.
    next_tag : callable
        Returns the next tag each call.

    Returns
    -------
    tuple of tuple of str
    """
    return tuple(tuple(next_tag() if (r + c) % 2 == 0 else "" for c in range(cols)) for r in range(rows))


@dataclass(frozen=True)
class Pattern:
    """A session's coded patches (see the module docstring).

    Attributes
    ----------
    patches : tuple of Patch
    alphabet : str
        The glyphs the tags are made of.
    pitch : float
        Side of a square, metres.
    font : str
        The font the glyphs are printed in (a name, for the record).
    """

    patches: tuple[Patch, ...]
    alphabet: str = ALPHABET
    pitch: float = PITCH
    font: str = "DejaVu Sans Mono Bold"

    def __post_init__(self):
        check_alphabet(self.alphabet)
        if not (isinstance(self.pitch, float | int) and 0.0005 <= self.pitch <= 0.1):
            raise HandcapError(f"pattern pitch {self.pitch!r} m: give the side of a square in metres, 0.0005 to 0.1 "
                               "(5 mm is 0.005)")
        seen_patch, where = set(), {}
        for p in self.patches:
            if not (_NAME.match(p.name) and _NAME.match(p.owner)):
                raise HandcapError(f"pattern patch {p.key!r}: names take letters, digits, '_', '.', '-'")
            if p.key in seen_patch:
                raise HandcapError(f"pattern: patch {p.key} appears twice")
            seen_patch.add(p.key)
            if not p.tags or not p.tags[0] or any(len(row) != len(p.tags[0]) for row in p.tags):
                raise HandcapError(f"pattern patch {p.key}: tags must be a non-empty grid whose rows have one "
                                   "length")
            for text, r, c in p.blocks():
                if len(text) != 2 or text[0] not in self.alphabet or text[1] not in self.alphabet:
                    raise HandcapError(f"pattern patch {p.key}: tag {text!r} at row {r}, column {c} is not two "
                                       f"glyphs of the alphabet {self.alphabet!r}")
                if text in where:
                    raise HandcapError(f"pattern: tag {text!r} is on both {where[text][0]} and {p.key}; every tag "
                                       "must be unique in a session")
                where[text] = (p.key, r, c)
        object.__setattr__(self, "_where", where)

    def locate(self, text: str) -> tuple[Patch, int, int] | None:
        """The patch and square of tag ``text``, or None when no patch carries it.

        Parameters
        ----------
        text : str

        Returns
        -------
        (Patch, int, int) or None
        """
        hit = self._where.get(text)
        if hit is None:
            return None
        return self.patch(hit[0]), hit[1], hit[2]

    def patch(self, key: str) -> Patch:
        """The patch named ``OWNER:NAME``.

        Parameters
        ----------
        key : str

        Returns
        -------
        Patch
        """
        for p in self.patches:
            if p.key == key:
                return p
        raise HandcapError(f"pattern: no patch {key!r}")

    @property
    def tags(self) -> tuple[str, ...]:
        """Every tag, patch by patch."""
        return tuple(self._where)

    @property
    def owners(self) -> tuple[str, ...]:
        """The owners in order of first appearance."""
        return tuple(dict.fromkeys(p.owner for p in self.patches))

    def corner_names(self) -> list[str]:
        """Every marker name (``OWNER:PATCH_rRcC``), patch by patch.

        Returns
        -------
        list of str
        """
        return [n for p in self.patches for n in p.corner_names()]

    def of_owner(self, owner: str) -> tuple[Patch, ...]:
        """The patches of one owner.

        Parameters
        ----------
        owner : str

        Returns
        -------
        tuple of Patch
        """
        return tuple(p for p in self.patches if p.owner == owner)

    def summary(self) -> str:
        """One line: patches, tags, corners, owners, pitch."""
        return (f"pattern: {len(self.patches)} patches, {len(self.tags)} tags of {len(self.alphabet)**2} "
                f"({self.alphabet}), {len(self.corner_names())} corners, {self.pitch * 1000:g} mm squares; "
                f"owners {', '.join(self.owners)}")

    def to_toml(self) -> str:
        """The template as commented TOML text (what :meth:`save` writes).

        Returns
        -------
        str
        """
        lines = [
            "# handcap coded-patch template (written by `handcap pattern`).",
            "# Every patch is a checkerboard of square tags; square (r, c) (row r downwards, column c to the right, as",
            "# printed) is white and carries the two-glyph tag written at tags[r][c], the first glyph underlined; \"\"",
            "# is a black square. The markers are the grid vertices that touch a white square: vertex (r, c) of",
            "# patch NAME of OWNER is the marker OWNER:NAME_r{r}c{c} (`corners` lists them). A tag's four corners,",
            "# in reading order with the underline at the bottom: top-left (r, c), top-right (r, c+1), bottom-right",
            "# (r+1, c+1), bottom-left (r+1, c). Tags are unique in the whole file.",
            f"format = {toml_value(_FORMAT)}",
            f"alphabet = {toml_value(self.alphabet)}",
            f"pitch = {toml_value(float(self.pitch))}  # metres, side of a square",
            f"font = {toml_value(self.font)}",
            "",
        ]
        for p in self.patches:
            lines += [f"[patches.{toml_key(p.key)}]",
                      f"name = {toml_value(p.name)}",
                      f"owner = {toml_value(p.owner)}",
                      f"segment = {toml_value(p.segment)}",
                      f"rows = {p.rows}",
                      f"cols = {p.cols}",
                      "tags = ["]
            lines += [f"    {toml_value(list(row))}," for row in p.tags]
            lines += ["]", f"corners = {toml_value(p.corner_names())}", ""]
        return "\n".join(lines)

    def save(self, path) -> Path:
        """Write ``pattern.toml`` atomically.

        Parameters
        ----------
        path : str or Path

        Returns
        -------
        Path
        """
        path = Path(path)
        with atomic_output(path, "w") as fh:
            fh.write(self.to_toml())
        return path

    @classmethod
    def load(cls, path) -> "Pattern":
        """Read a ``pattern.toml``, checking every grid, tag and corner list.

        Parameters
        ----------
        path : str or Path

        Returns
        -------
        Pattern

        Raises
        ------
        HandcapError
            A file that is not a handcap pattern, or whose grids, tags or corners disagree.
        """
        doc = read_toml(path)
        if doc.get("format") != _FORMAT or not isinstance(doc.get("patches"), dict):
            raise HandcapError(f"{path}: not a handcap pattern template (no format = \"{_FORMAT}\" and [patches]); "
                               "write one with handcap pattern")
        try:
            patches = []
            for key, table in doc["patches"].items():
                tags = tuple(tuple(str(t) for t in row) for row in table["tags"])
                patch = Patch(str(table["name"]), str(table["owner"]), str(table["segment"]), tags)
                if patch.key != key:
                    raise HandcapError(f"{path}: patch [{key}] says name {patch.name!r}, owner {patch.owner!r}")
                if (table.get("rows"), table.get("cols")) != (patch.rows, patch.cols):
                    raise HandcapError(f"{path}: patch {key}: rows/cols {table.get('rows')}x{table.get('cols')} but "
                                       f"its tag grid is {patch.rows}x{patch.cols}")
                if "corners" in table and list(table["corners"]) != patch.corner_names():
                    raise HandcapError(f"{path}: patch {key}: its corners list is not the one its tag grid implies")
                patches.append(patch)
            return cls(tuple(patches), str(doc.get("alphabet", ALPHABET)), float(doc.get("pitch", PITCH)),
                       str(doc.get("font", "")))
        except (KeyError, TypeError, IndexError) as err:
            raise HandcapError(f"{path}: pattern template is missing or mistypes a field ({err!r})") from None
        except HandcapError as err:
            message = str(err)
            raise HandcapError(message if message.startswith(str(path)) else f"{path}: {message}") from None
