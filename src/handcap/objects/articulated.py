"""Articulated objects: rigid parts carrying markers, joined by joints, described by a TOML file (issue 18).

A description names the parts, each with its markers' positions in the object's frame at rest, and the
joints between them::

    name = "hinge"
    units = "mm"                      # of every position: m (default), cm or mm

    [[parts]]
    name = "base"
    markers = { b1 = [0, 0, 0], b2 = [60, 0, 0], b3 = [0, 40, 5] }

    [[parts]]
    name = "lid"
    markers = { l1 = [0, 0, 30], l2 = [60, 0, 30], l3 = [0, -40, 35] }

    [[joints]]
    type = "revolute"                 # the child turns about an axis through a point of the parent
    parent = "base"
    child = "lid"
    axis = [1, 0, 0]
    origin = [0, 0, 15]
    limits_deg = [-5, 185]            # optional

A puzzle cube's layers are one joint of type ``layers``: a turn about one of its named axes moves the
parts whose centres lie on that axis' side (which parts those are changes with every turn)::

    [[joints]]
    type = "layers"
    axes = { R = [1, 0, 0], L = [-1, 0, 0], U = [0, 1, 0], D = [0, -1, 0], F = [0, 0, 1], B = [0, 0, -1] }

``cube2x2`` names the shipped 2x2x2 cube (:file:`objects/data/cube2x2.toml`: three markers on each of the
eight cubies, one on each of its outer faces); ``cube2x2-patches`` the same cube with a coded patch on every
facelet, each patch corner a marker named as ``handcap detect`` names it (:mod:`handcap.objects.cube_patches`).
"""

from __future__ import annotations

import tomllib
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from handcap.core.errors import HandcapError

SHIPPED = {name: Path(__file__).resolve().parent / "data" / f"{name}.toml" for name in ("cube2x2", "cube2x2-patches")}
_METRES = {"m": 1.0, "cm": 0.01, "mm": 0.001}
#: Fewest markers a part needs to be tracked on its own (Kabsch).
MIN_MARKERS = 3


@dataclass(frozen=True)
class Part:
    """A rigid part.

    Attributes
    ----------
    name : str
    marker_names : tuple of str
    markers : ndarray (M, 3)
        Positions in the object's frame at rest, metres.
    """

    name: str
    marker_names: tuple
    markers: np.ndarray

    @property
    def centre(self) -> np.ndarray:
        """Mean marker position at rest (3,), metres."""
        return self.markers.mean(axis=0)


@dataclass(frozen=True)
class Joint:
    """A joint: ``revolute`` (``parent``, ``child``, ``axis``, ``origin``, optional ``limits`` in radians) or
    ``layers`` (``axes``: name -> unit axis; parts move with the side they sit on)."""

    kind: str
    parent: str | None = None
    child: str | None = None
    axis: np.ndarray | None = None
    origin: np.ndarray | None = None
    limits: tuple | None = None
    axes: dict | None = None


@dataclass(frozen=True)
class ArticulatedObject:
    """Parts and joints of an articulated object (see the module docstring for its file).

    Attributes
    ----------
    name : str
    parts : tuple of Part
    joints : tuple of Joint
    """

    name: str
    parts: tuple
    joints: tuple

    @property
    def marker_names(self) -> tuple:
        """Every marker's name, part by part."""
        return tuple(n for p in self.parts for n in p.marker_names)

    @property
    def markers(self) -> np.ndarray:
        """Every marker at rest (M, 3), object frame, metres, in :attr:`marker_names` order."""
        return np.concatenate([p.markers for p in self.parts])

    def part(self, name: str) -> Part:
        """The part called ``name``."""
        for p in self.parts:
            if p.name == name:
                return p
        raise HandcapError(f"{self.name}: no part {name!r} (it has {', '.join(p.name for p in self.parts)})")

    @property
    def layers(self) -> Joint | None:
        """The ``layers`` joint, if the object has one."""
        return next((j for j in self.joints if j.kind == "layers"), None)


def _vector(value, where: str, factor: float = 1.0) -> np.ndarray:
    try:
        v = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise HandcapError(f"{where}: expected three numbers, got {value!r}") from None
    if v.shape != (3,) or not np.isfinite(v).all():
        raise HandcapError(f"{where}: expected three finite numbers, got {value!r}")
    return v * factor


def _unit(value, where: str) -> np.ndarray:
    v = _vector(value, where)
    if np.linalg.norm(v) < 1e-9:
        raise HandcapError(f"{where}: the axis has no length")
    return v / np.linalg.norm(v)


def articulated_from_table(table: dict, where: str = "articulated object") -> ArticulatedObject:
    """An :class:`ArticulatedObject` from a parsed description (see the module docstring).

    Parameters
    ----------
    table : dict
        The parsed TOML.
    where : str
        The file's name, for messages.

    Returns
    -------
    ArticulatedObject
        Positions in metres.

    Raises
    ------
    HandcapError
        One line naming what is wrong: a missing name, an unknown unit, a part with fewer than
        :data:`MIN_MARKERS` markers, a repeated marker, a joint naming an unknown part, an axis without
        length, an object larger than 2 m (units).
    """
    if not isinstance(table, dict):
        raise HandcapError(f"{where}: not a description table")
    name = table.get("name")
    if not isinstance(name, str) or not name:
        raise HandcapError(f"{where}: give the object's name (name = \"...\")")
    units = table.get("units", "m")
    if not isinstance(units, str) or units not in _METRES:
        raise HandcapError(f"{where}: units {units!r}: choose m, cm or mm")
    factor = _METRES[units]
    raw_parts = table.get("parts")
    if not isinstance(raw_parts, list) or not raw_parts:
        raise HandcapError(f"{where}: no [[parts]]")
    parts, seen = [], set()
    for k, raw in enumerate(raw_parts):
        label = raw.get("name") if isinstance(raw, dict) else None
        if not isinstance(label, str) or not label:
            raise HandcapError(f"{where}: part {k + 1} has no name")
        markers = raw.get("markers")
        if not isinstance(markers, dict) or len(markers) < MIN_MARKERS:
            count = len(markers) if isinstance(markers, dict) else 0
            raise HandcapError(f"{where}: part {label!r} has {count} markers; a part needs at least {MIN_MARKERS} "
                               f"(markers = {{ name = [x, y, z], ... }})")
        for m in markers:
            if m in seen:
                raise HandcapError(f"{where}: marker {m!r} is named twice")
            seen.add(m)
        if label in {p.name for p in parts}:
            raise HandcapError(f"{where}: part {label!r} is named twice")
        positions = np.array([_vector(v, f"{where}: part {label!r} marker {m!r}", factor) for m, v in markers.items()])
        parts.append(Part(label, tuple(markers), positions))
    every = np.concatenate([p.markers for p in parts])
    if np.ptp(every, axis=0).max() > 2.0:
        raise HandcapError(f"{where}: the object is {np.ptp(every, axis=0).max():.3g} m across: is units right?")
    names = {p.name for p in parts}
    joints = []
    raw_joints = table.get("joints", [])
    if not isinstance(raw_joints, list):
        raise HandcapError(f"{where}: joints must be [[joints]] tables")
    for k, raw in enumerate(raw_joints):
        at = f"{where}: joint {k + 1}"
        kind = raw.get("type") if isinstance(raw, dict) else None
        if kind == "revolute":
            for key in ("parent", "child"):
                if not isinstance(raw.get(key), str) or raw.get(key) not in names:
                    raise HandcapError(f"{at}: {key} {raw.get(key)!r} is not a part ({', '.join(sorted(names))})")
            limits = raw.get("limits_deg")
            if limits is not None:
                lim = np.asarray(limits, dtype=np.float64) if isinstance(limits, list) else np.zeros(0)
                if lim.shape != (2,) or not lim[0] < lim[1]:
                    raise HandcapError(f"{at}: limits_deg must be [low, high] degrees, low below high")
                limits = tuple(np.deg2rad(lim))
            joints.append(Joint("revolute", raw["parent"], raw["child"], _unit(raw.get("axis"), f"{at} axis"),
                                _vector(raw.get("origin", [0, 0, 0]), f"{at} origin", factor), limits))
        elif kind == "layers":
            axes = raw.get("axes")
            if not isinstance(axes, dict) or not axes:
                raise HandcapError(f"{at}: a layers joint needs axes = {{ R = [1, 0, 0], ... }}")
            joints.append(Joint("layers", axes={a: _unit(v, f"{at} axis {a}") for a, v in axes.items()}))
        else:
            raise HandcapError(f"{at}: type {kind!r}: choose revolute or layers")
    return ArticulatedObject(name, tuple(parts), tuple(joints))


def load_articulated(name_or_path) -> ArticulatedObject:
    """A shipped description (``cube2x2``) or a user's TOML file.

    Raises
    ------
    HandcapError
        A missing or unreadable file, bad TOML, or a description :func:`articulated_from_table` refuses.
    """
    path = SHIPPED.get(str(name_or_path), Path(name_or_path))
    if not path.is_file():
        raise HandcapError(f"{name_or_path}: no such articulated object file (shipped: {', '.join(SHIPPED)})")
    try:
        table = tomllib.loads(path.read_text(encoding="utf-8"))
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as err:
        raise HandcapError(f"{path}: not a TOML description ({' '.join(str(err).split())[:100]})") from None
    return articulated_from_table(table, str(path))
