"""Length units as marker files name them, and their size in metres."""

from __future__ import annotations

from handcap.core.errors import HandcapError

_METRES_PER_UNIT = {
    "mm": 1e-3, "millimeter": 1e-3, "millimeters": 1e-3, "millimetre": 1e-3, "millimetres": 1e-3,
    "cm": 1e-2, "centimeter": 1e-2, "centimeters": 1e-2, "centimetre": 1e-2, "centimetres": 1e-2,
    "m": 1.0, "meter": 1.0, "meters": 1.0, "metre": 1.0, "metres": 1.0,
}


def metres_per_unit(unit: str, where: str) -> float:
    """Size in metres of one ``unit`` (``mm``, ``cm``, ``m`` or spelled out, any case).

    Parameters
    ----------
    unit : str
        The unit as written in the file.
    where : str
        File and field the unit came from, for the error message.

    Raises
    ------
    HandcapError
        If the unit is not a length unit handcap knows.
    """
    try:
        return _METRES_PER_UNIT[unit.strip().lower()]
    except KeyError:
        raise HandcapError(f"{where}: unknown length unit {unit!r}; expected mm, cm or m") from None
