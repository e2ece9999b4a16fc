"""Marker layouts as data and as TOML files: :class:`MarkerLayout`, :func:`load_layout`.

The file format is described in the package docstring (:mod:`handcap.layouts`).
"""

from __future__ import annotations

import difflib
import re
import tomllib
from dataclasses import dataclass, field, replace
from importlib.resources import files
from pathlib import Path

import numpy as np

from handcap.core.errors import HandcapError
from handcap.core.files import atomic_output
from handcap.core.motion import check_side
from handcap.hand.anatomy import SEGMENT_NAMES

SHIPPED = ("dense-patches", "glove-13", "joints-19", "tips-5", "active-9")
MARKER_KINDS = ("sphere", "patch")
#: Least space between two sphere markers' surfaces, metres: no one sticks a marker on where it touches another,
#: and two that do merge into one blob in the cameras.
MARKER_GAP = 0.001


#: A patch corner's marker name: ``PATCH_rRcC`` (patch, row, column).
_PATCH_CORNER = re.compile(r"^(.+)_r(\d+)c(\d+)$")


@dataclass(frozen=True)
class LayoutMarker:
    """One marker of a layout.

    Attributes
    ----------
    name : str
    segment : str
        A hand segment name (``palm``, ``index_proximal``, ...) or ``object:NAME``.
    position : ndarray (3,) or None
        Nominal position on the template hand (metres), if known.
    patch : str or None
        The printed patch this corner belongs to (dense layouts).
    """

    name: str
    segment: str
    position: np.ndarray | None = None
    patch: str | None = None

    @property
    def on_object(self) -> bool:
        """Whether the marker sits on an object (segment ``object:NAME``) rather than the hand."""
        return self.segment.startswith("object:")


@dataclass(frozen=True)
class MarkerLayout:
    """A named set of markers on hand segments.

    Attributes
    ----------
    name : str
    side : {"right", "left"}
    markers : tuple of LayoutMarker
    rigid : tuple of str
        Markers fixed to one rigid segment, used to find the hand frame.
    marker_radius : float
        Distance from the skin to the marker centre, metres.
    marker_kind : {"sphere", "patch"}
        Spheres are seen from every side; patch corners only from the front.
    """

    name: str
    side: str
    markers: tuple[LayoutMarker, ...]
    rigid: tuple[str, ...] = ()
    marker_radius: float = 0.005
    marker_kind: str = "sphere"
    description: str = field(default="", compare=False)

    def __post_init__(self):
        check_side(self.side)
        names = [m.name for m in self.markers]
        if not names:
            raise HandcapError(f"layout {self.name!r} has no markers")
        repeated = sorted({n for n in names if names.count(n) > 1})
        if repeated:
            raise HandcapError(f"layout {self.name!r} repeats marker names: {', '.join(repeated)}")
        for m in self.markers:
            if m.segment not in SEGMENT_NAMES and not (m.on_object and len(m.segment) > 7):
                close = difflib.get_close_matches(m.segment, SEGMENT_NAMES, n=1)
                hint = f"did you mean {close[0]!r}? " if close else ""
                raise HandcapError(f"layout {self.name!r}: marker {m.name!r} has unknown segment {m.segment!r}; "
                                   f"{hint}use one of {', '.join(SEGMENT_NAMES)} or object:NAME")
        unknown = [r for r in self.rigid if r not in names]
        if unknown:
            raise HandcapError(f"layout {self.name!r}: rigid markers not in the layout: {', '.join(unknown)}")
        if not np.isfinite(self.marker_radius) or not 0 <= self.marker_radius < 0.05:
            raise HandcapError(f"layout {self.name!r}: marker_radius must be 0-0.05 m, got {self.marker_radius}")
        if self.marker_kind not in MARKER_KINDS:
            raise HandcapError(f"layout {self.name!r}: marker_kind must be one of {MARKER_KINDS}")

    @property
    def names(self) -> tuple[str, ...]:
        """Marker names (M,), in layout order."""
        return tuple(m.name for m in self.markers)

    @property
    def segments(self) -> tuple[str, ...]:
        """Segment of each marker (M,), in layout order."""
        return tuple(m.segment for m in self.markers)

    @property
    def hand_markers(self) -> tuple[LayoutMarker, ...]:
        """The markers on hand segments (object markers left out), in layout order."""
        return tuple(m for m in self.markers if not m.on_object)

    def __len__(self) -> int:
        return len(self.markers)

    def __repr__(self) -> str:
        return f"MarkerLayout({self.name!r}, {self.side}, {len(self)} markers)"

    def positions(self) -> np.ndarray:
        """Nominal positions (M, 3) on the template of this side, NaN where not given."""
        out = np.full((len(self.markers), 3), np.nan)
        for i, m in enumerate(self.markers):
            if m.position is not None:
                out[i] = m.position
        return out

    def mirrored(self) -> "MarkerLayout":
        """The same layout on the other hand (positions mirrored in z).

        A printed patch is not mirrored: stuck on the other hand it reads the right way round, its rows running
        along the hand as on this one and its columns the other way across it. So a patch corner ``PATCH_rRcC``
        takes the place of ``PATCH_rRc(N - C)``, mirrored, where N is the patch's last column (the largest this
        layout lists for it: every corner of a patch, or at least one of its last column).
        """
        flip = np.array([1.0, 1.0, -1.0])
        grids = {m.name: (m.patch, grid) for m in self.markers if m.patch and (grid := _PATCH_CORNER.match(m.name))}
        last = {}
        for patch, grid in grids.values():
            last[patch] = max(last.get(patch, 0), int(grid[3]))
        renamed = {name: f"{grid[1]}_r{grid[2]}c{last[patch] - int(grid[3])}" for name, (patch, grid) in grids.items()}
        markers = tuple(LayoutMarker(renamed.get(m.name, m.name), m.segment,
                                     None if m.position is None else m.position * flip, m.patch) for m in self.markers)
        return MarkerLayout(self.name, "left" if self.side == "right" else "right", markers,
                            tuple(renamed.get(r, r) for r in self.rigid), self.marker_radius, self.marker_kind,
                            self.description)

    def for_side(self, side: str) -> "MarkerLayout":
        """This layout on hand ``side`` (mirrored if needed)."""
        return self if check_side(side) == self.side else self.mirrored()

    def subset(self, names) -> "MarkerLayout":
        """This layout with only the markers named in ``names`` (layout order kept; rigid markers too).

        Parameters
        ----------
        names : iterable of str
        """
        keep = set(names)
        return replace(self, markers=tuple(m for m in self.markers if m.name in keep),
                       rigid=tuple(r for r in self.rigid if r in keep))

    def to_toml(self) -> dict:
        """The layout as a TOML document (a dict): its settings, then one ``markers`` table per marker.

        Returns
        -------
        dict
            ``name``, ``side``, ``marker_radius`` (metres), ``marker_kind``, ``rigid``, ``description``
            when set, and ``markers``: {name: {``segment``, ``position`` (3 floats, metres, rounded to
            1 micrometre) when known, ``patch`` when set}}.
        """
        table = {"name": self.name, "side": self.side, "marker_radius": self.marker_radius,
                 "marker_kind": self.marker_kind, "rigid": list(self.rigid)}
        if self.description:
            table["description"] = self.description
        table["markers"] = {}
        for m in self.markers:
            entry = {"segment": m.segment}
            if m.position is not None:
                entry["position"] = [round(float(v), 6) for v in m.position]
            if m.patch is not None:
                entry["patch"] = m.patch
            table["markers"][m.name] = entry
        return table

    def save(self, path) -> None:
        """Write the layout as TOML (atomically), one line per value."""

        table = self.to_toml()
        markers = table.pop("markers")
        lines = [f"{key} = {toml_value(value)}" for key, value in table.items()]
        for name, entry in markers.items():
            lines += ["", f"[markers.{toml_key(name)}]"]
            lines += [f"{key} = {toml_value(value)}" for key, value in entry.items()]
        with atomic_output(path) as fh:
            fh.write(("\n".join(lines) + "\n").encode())


def toml_key(key: str) -> str:
    """``key`` as a TOML key: bare when it holds only ``_``, ``-`` and what :meth:`str.isalnum` accepts, else quoted.

    Parameters
    ----------
    key : str

    Returns
    -------
    str
    """
    return key if key.replace("_", "a").replace("-", "a").isalnum() else toml_value(key)


def toml_value(value) -> str:
    """``value`` written as a TOML value on one line (lists inline, elements comma-separated).

    Parameters
    ----------
    value : str, int, float, bool or list
        Written by ``tomli_w``; lists are joined here so they stay on one line.

    Returns
    -------
    str
    """
    import tomli_w
    if isinstance(value, list):
        return "[" + ", ".join(toml_value(v) for v in value) + "]"
    return tomli_w.dumps({"v": value})[len("v = "):].strip()


def _layout_from_table(table: dict, source: str) -> MarkerLayout:
    try:
        markers_table = table["markers"]
        if not isinstance(markers_table, dict):
            raise HandcapError(f"{source}: markers must be tables [markers.NAME] with a segment each")
        markers = []
        for name, entry in markers_table.items():
            if not isinstance(entry, dict) or "segment" not in entry:
                raise HandcapError(f"{source}: marker {name!r} needs a segment")
            position = entry.get("position")
            if position is not None:
                if not isinstance(position, list) or not all(isinstance(v, (int, float)) for v in position):
                    raise HandcapError(f"{source}: marker {name!r} position must be three numbers in metres")
                position = np.asarray(position, dtype=np.float64)
                if position.shape != (3,) or not np.isfinite(position).all():
                    raise HandcapError(f"{source}: marker {name!r} position must be three numbers in metres")
            patch = entry.get("patch")
            markers.append(LayoutMarker(str(name), str(entry["segment"]), position,
                                        None if patch is None else str(patch)))
        rigid = table.get("rigid", [])
        if not isinstance(rigid, list) or not all(isinstance(r, str) for r in rigid):
            raise HandcapError(f"{source}: rigid must be a list of marker names, e.g. rigid = [\"a\", \"b\", \"c\"]")
        return MarkerLayout(str(table.get("name", Path(source).stem)), str(table.get("side", "right")),
                            tuple(markers), tuple(rigid),
                            float(table.get("marker_radius", 0.005)), str(table.get("marker_kind", "sphere")),
                            str(table.get("description", "")))
    except KeyError as err:
        raise HandcapError(f"{source}: layout lacks {err}") from None
    except (TypeError, ValueError) as err:
        raise HandcapError(f"{source}: malformed layout ({err})") from None


def sides_named(names) -> set:
    """The hands that ``left:`` or ``right:`` prefixes of marker names give (detect names each hand's corners so).

    Parameters
    ----------
    names : iterable of str

    Returns
    -------
    set of str
        Empty, ``{"right"}``, ``{"left"}`` or both.
    """
    return {str(n).split(":", 1)[0].lower() for n in names if ":" in str(n)} & {"left", "right"}


def load_layout(name_or_path, side: str | None = None) -> MarkerLayout:
    """A shipped layout by name, or a layout TOML file.

    Parameters
    ----------
    name_or_path : str or path
        One of :data:`SHIPPED`, or a path to a ``.toml`` file.
    side : {"right", "left"}, optional
        Mirror the layout onto this hand if it was written for the other.
    """
    key = str(name_or_path)
    if key in SHIPPED:
        text = files("handcap.layouts").joinpath(f"{key}.toml").read_text()
        source = key
    else:
        path = Path(key)
        if not path.is_file():
            raise HandcapError(f"unknown layout {key!r}: give one of {', '.join(SHIPPED)} or a .toml file")
        source = str(path)
        try:
            text = path.read_bytes().decode("utf-8")
        except UnicodeDecodeError:
            raise HandcapError(f"{source}: not a text file; a layout is TOML (see handcap layout new)") from None
        except OSError as err:
            raise HandcapError(f"{source}: cannot read the layout ({err.strerror})") from None
    try:
        table = tomllib.loads(text)
    except tomllib.TOMLDecodeError as err:
        raise HandcapError(f"{source}: not valid TOML ({err})") from None
    layout = _layout_from_table(table, source)
    return layout if side is None else layout.for_side(side)


__all__ = ["MARKER_KINDS", "SHIPPED", "LayoutMarker", "MarkerLayout", "load_layout", "toml_key", "toml_value"]
