"""Length units of marker and camera files, and which of them the data make plausible.

Files say their unit in many ways (C3D ``POINT:UNITS``, TRC ``Units``, Motive
``Length Units``), some say nothing (Qualisys TSV is millimetres, handcap's
``.npz`` metres), and some say the wrong thing: a TRC in millimetres declared as
metres, an anipose rig calibrated with a board measured in millimetres. Read
at face value, such a file runs to the end with a hand two hundred metres wide.

So every reader hands what it read to :func:`settle_marker_units` (or
:func:`settle_rig_units`), which measures figures that no unit choice can hide:

* **coordinates**: no capture volume reaches :data:`MAX_COORDINATE` from its
  origin (10 km); a coordinate beyond it in every unit is garbage (``1e30``);
* **spread**: the median over frames of the largest distance between two
  markers seen in the same frame. A hand's markers span :data:`HAND_SPREAD`
  (3-35 cm: a fist's back triad to an open adult hand with a wrist marker,
  with margin); anything captured spans less than :data:`SCENE_SPREAD` (50 m);
* **speed**: the median speed of the markers between consecutive frames is
  below :data:`MAX_SPEED` (50 m/s) for anything a person moves. Random test
  data move that fast too, so speed only decides between units that the
  figures above leave open, never alone;
* **cameras** of a rig that films hands lie less than :data:`RIG_SPREAD` apart
  (a hand 20 cm wide seen from further than 20 m is a few pixels wide in any
  camera of a capture system), and more than 1 cm when they are not one spot.

The rules, in order:

1. The unit given by the user (``units=``, ``--units``) is used as given; if the
   data look implausible in it, a warning says so (an error if no unit fits).
2. Otherwise, if the file's own (or the format's) unit makes the data plausible,
   it is kept: an honest file is never rescaled.
3. Otherwise, if exactly one of mm, cm and m makes them plausible, the data are
   converted to it and a :class:`~handcap.core.errors.HandcapWarning` says so
   (stored in the result's ``warnings``).
4. Otherwise one :class:`~handcap.core.errors.HandcapError` says what was found:
   no unit fits (the file is damaged), or several do (give the unit).
"""

from __future__ import annotations

import numpy as np

from handcap.core.errors import HandcapError, warn
from handcap.core.markers import MarkerSequence

UNITS = ("mm", "cm", "m")
_METRES_PER_UNIT = {
    "mm": 1e-3, "millimeter": 1e-3, "millimeters": 1e-3, "millimetre": 1e-3, "millimetres": 1e-3,
    "cm": 1e-2, "centimeter": 1e-2, "centimeters": 1e-2, "centimetre": 1e-2, "centimetres": 1e-2,
    "m": 1.0, "meter": 1.0, "meters": 1.0, "metre": 1.0, "metres": 1.0,
}
_UNIT_WORDS = {"mm": "millimetres", "cm": "centimetres", "m": "metres"}

MAX_COORDINATE = 1e4          # metres from the origin of any capture volume
HAND_SPREAD = (0.03, 0.35)    # metres between the two furthest markers of one hand in a frame
SCENE_SPREAD = 50.0           # metres between the two furthest markers of any capture in a frame
MAX_SPEED = 50.0              # median marker speed, metres per second
RIG_SPREAD = (0.01, 20.0)     # metres between the two furthest cameras of a rig (when not all at one spot)

# Frames sampled for the spread (the figure is a median, a few hundred frames settle it).
_SPREAD_FRAMES = 200
_SPREAD_PAIRS = 4_000_000


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
    except (KeyError, AttributeError):
        raise HandcapError(f"{where}: unknown length unit {unit!r}; expected mm, cm or m") from None


def unit_name(unit: str) -> str:
    """The short name (``mm``, ``cm``, ``m``) of a unit as files spell it."""
    scale = metres_per_unit(unit, "unit")
    return next(short for short in UNITS if _METRES_PER_UNIT[short] == scale)


def check_units(units) -> str | None:
    """``units`` checked to be None, ``"mm"``, ``"cm"`` or ``"m"`` (spelled out accepted), short form.

    Raises
    ------
    HandcapError
        For any other value.
    """
    if units is None:
        return None
    if not isinstance(units, str) or units.strip().lower() not in _METRES_PER_UNIT:
        raise HandcapError(f"units must be mm, cm or m, got {units!r}")
    return unit_name(units)


# -- figures --------------------------------------------------------------------------------------------

def marker_spread(positions: np.ndarray) -> float:
    """Median over frames of the largest distance between two markers seen in the same frame.

    Parameters
    ----------
    positions : ndarray of shape (T, M, 3)
        NaN where missing; any unit (the result has the same).

    Returns
    -------
    float
        NaN when no frame sees two markers. Frames are sampled evenly so that
        at most a few million pairs are measured.
    """
    T, M = positions.shape[:2]
    if T == 0 or M < 2:
        return float("nan")
    seen = ~np.isnan(positions[..., 0])
    frames = np.flatnonzero(seen.sum(axis=1) >= 2)
    if len(frames) == 0:
        return float("nan")
    keep = max(1, min(_SPREAD_FRAMES, _SPREAD_PAIRS // (M * M)))
    frames = frames[np.linspace(0, len(frames) - 1, min(keep, len(frames))).round().astype(int)]
    return float(np.median(np.sqrt(_largest_squared_distances(positions[frames], positions[frames]))))


def _largest_squared_distances(a: np.ndarray, b: np.ndarray, *, nearest: bool = False) -> np.ndarray:
    """Per frame, the largest (or, per point of ``a``, the nearest) squared distance between seen points.

    ``a`` (F, M, 3) and ``b`` (F, N, 3), NaN where missing; the squared distances come from one batched
    matrix product (|x|^2 + |y|^2 - 2 x.y), without the (F, M, N, 3) array of differences.
    """
    seen_a, seen_b = ~np.isnan(a[..., 0]), ~np.isnan(b[..., 0])
    a, b = np.nan_to_num(a), np.nan_to_num(b)
    centre = a.sum(axis=1, keepdims=True) / np.maximum(seen_a.sum(axis=1), 1)[:, None, None]
    a, b = np.where(seen_a[..., None], a - centre, 0.0), np.where(seen_b[..., None], b - centre, 0.0)
    d2 = (a * a).sum(-1)[:, :, None] + (b * b).sum(-1)[:, None, :] - 2.0 * a @ b.transpose(0, 2, 1)
    d2 = np.maximum(d2, 0.0)
    both = seen_a[:, :, None] & seen_b[:, None, :]
    if nearest:
        return np.where(both, d2, np.inf).min(axis=2)
    return np.where(both, d2, -np.inf).max(axis=(1, 2))


def median_speed(positions: np.ndarray, rate: float) -> float:
    """Median distance from a point to the nearest point of the next frame, times the rate (unit per second).

    The nearest point rather than the same column, so that unlabeled points,
    whose columns are no tracks, give a speed that is never too high: for
    labeled tracks it is at most each marker's own speed.

    Parameters
    ----------
    positions : ndarray of shape (T, M, 3)
        NaN where missing.
    rate : float
        Frames per second.

    Returns
    -------
    float
        NaN when no two consecutive frames both see a point.
    """
    T, M = positions.shape[:2]
    if T < 2 or M == 0:
        return float("nan")
    seen = ~np.isnan(positions[..., 0])
    pairs = np.flatnonzero(seen[:-1].any(axis=1) & seen[1:].any(axis=1))
    if len(pairs) == 0:
        return float("nan")
    keep = max(1, min(_SPREAD_FRAMES, _SPREAD_PAIRS // (M * M)))
    pairs = pairs[np.linspace(0, len(pairs) - 1, min(keep, len(pairs))).round().astype(int)]
    nearest = _largest_squared_distances(positions[pairs], positions[pairs + 1], nearest=True)
    nearest = np.sqrt(nearest[np.isfinite(nearest)])
    return float(np.median(nearest) * rate) if nearest.size else float("nan")


def _largest(positions: np.ndarray) -> float:
    finite = np.abs(positions[~np.isnan(positions)])
    return float(finite.max()) if finite.size else 0.0


def _hand_columns(names, hand) -> list[int]:
    """Columns of one hand's markers: those named in ``hand``, of the ``Subject:`` prefix that has most of them.

    A file of two hands (``Left:index_tip``, ``Right:index_tip``) must not be
    measured as one hand half a metre wide.
    """
    if not hand:
        return []
    wanted = {str(n) for n in hand} | {str(n).rsplit(":", 1)[-1] for n in hand}
    groups: dict[str, list[int]] = {}
    for i, name in enumerate(names):
        prefix, _, short = name.rpartition(":")
        if name in wanted or short in wanted:
            groups.setdefault(prefix, []).append(i)
    return max(groups.values(), key=len) if groups else []


def _problems(largest: float, spread: float, hand_spread: float) -> list[str]:
    """What is impossible about figures in metres (empty: plausible)."""
    found = []
    if largest > MAX_COORDINATE:
        found.append(f"a coordinate {largest:.3g} m from the origin (a capture volume is within "
                     f"{MAX_COORDINATE:g} m)")
    if spread > SCENE_SPREAD:
        found.append(f"markers {spread:.3g} m apart in one frame (median; a capture is within {SCENE_SPREAD:g} m)")
    if not (HAND_SPREAD[0] <= hand_spread <= HAND_SPREAD[1]) and not np.isnan(hand_spread):
        found.append(f"a hand {100 * hand_spread:.3g} cm across (median; hands span "
                     f"{100 * HAND_SPREAD[0]:g}-{100 * HAND_SPREAD[1]:g} cm)")
    return found


# -- markers --------------------------------------------------------------------------------------------

def settle_marker_units(markers, *, declared: str, units: str | None, where, hand=None):
    """Check that marker positions are plausible in their unit; convert when only one unit fits.

    Parameters
    ----------
    markers : MarkerSequence
        As read, positions in metres computed with ``units`` if given, else
        with ``declared``.
    declared : str
        The unit the file says (or its format implies): ``mm``, ``cm``, ``m``.
    units : str or None
        The unit the user gave (overrides ``declared``), or None.
    where : str or Path
        The file, for messages.
    hand : sequence of str, optional
        Names of one hand's markers (``Subject:`` prefixes ignored); when three
        or more are in the file, their spread must be that of a hand.

    Returns
    -------
    MarkerSequence
        ``markers`` unchanged when plausible (or when the user gave the
        unit, with a warning if implausible), else converted to the one
        unit that fits, with a warning saying so in its ``warnings``.

    Raises
    ------
    HandcapError
        If no unit fits the data, or several do and the file's own does not.
    """
    positions = markers.positions
    columns = _hand_columns(markers.names, hand)
    raw = (_largest(positions), marker_spread(positions),
           marker_spread(positions[:, columns]) if len(columns) >= 3 else float("nan"))
    used = units or unit_name(declared)

    def problems(unit: str) -> list[str]:
        factor = _METRES_PER_UNIT[unit] / _METRES_PER_UNIT[used]
        return _problems(*(value * factor for value in raw))

    found = problems(used)
    if not found:
        return markers
    fits = [u for u in UNITS if not problems(u)]
    if not fits:
        raise HandcapError(f"{where}: the data fit no length unit (in {used}: {found[0]}); "
                           "the file is damaged or not a capture")
    if units is not None:
        return markers.with_warnings(warn(f"{where}: read in {units} as asked, the data show {found[0]}; "
                                          "check the unit"))
    if len(fits) > 1:
        # Speed breaks a tie: it is a soft cue (random test data move fast in any unit), never a reason alone.
        speed = median_speed(positions, markers.rate)
        fits = [u for u in fits if not speed * _METRES_PER_UNIT[u] / _METRES_PER_UNIT[used] > MAX_SPEED] or fits
    if len(fits) > 1:
        raise HandcapError(f"{where}: in {_UNIT_WORDS[used]}, its own unit, the file shows {found[0]}; the data fit "
                           f"{' or '.join(fits)}: give the unit (--units {'|'.join(fits)})")
    factor = _METRES_PER_UNIT[fits[0]] / _METRES_PER_UNIT[used]
    residuals = None if markers.residuals is None else markers.residuals * factor
    converted = MarkerSequence(positions * factor, markers.names, markers.rate, residuals, markers.warnings)
    return converted.with_warnings(warn(
        f"{where}: in {_UNIT_WORDS[used]}, its own unit, the file shows {found[0]}; read as "
        f"{_UNIT_WORDS[fits[0]]}, the only unit that fits (give --units to choose)"))


# -- cameras --------------------------------------------------------------------------------------------

def rig_spread(centers: np.ndarray) -> float:
    """Largest distance between two camera centres (C, 3); 0 for one camera."""
    if len(centers) < 2:
        return 0.0
    return float(np.linalg.norm(centers[:, None] - centers[None], axis=-1).max())


def _rig_problem(spread: float) -> str | None:
    if spread == 0.0:
        return None
    if spread > RIG_SPREAD[1]:
        return f"cameras {spread:.3g} m apart (a rig that films hands is within {RIG_SPREAD[1]:g} m)"
    if spread < RIG_SPREAD[0]:
        return (f"cameras {1000 * spread:.3g} mm apart (cameras that are not at one spot are "
                f"{100 * RIG_SPREAD[0]:g} cm or more apart)")
    return None


def settle_rig_units(rig, *, declared: str, units: str | None, where):
    """Check that a rig's camera positions are plausible in their unit; convert when only one unit fits.

    Parameters
    ----------
    rig : CameraRig
        As read, translations in metres computed with ``units`` if given, else
        with ``declared``.
    declared : str
        The unit the file says or its format implies (``mm``, ``cm``, ``m``).
    units : str or None
        The unit the user gave, or None.
    where : str or Path
        The file, for messages.

    Returns
    -------
    CameraRig
        ``rig``, or a copy with translations scaled to the one unit that fits
        (a warning says so, in its ``warnings``).

    Raises
    ------
    HandcapError
        If no unit fits, or several do and the file's own does not.
    """
    spread = rig_spread(rig.centers)
    used = units or unit_name(declared)

    def problem(unit: str) -> str | None:
        return _rig_problem(spread * _METRES_PER_UNIT[unit] / _METRES_PER_UNIT[used])

    found = problem(used)
    if found is None:
        return rig
    if units is not None:
        return rig.with_warnings(warn(f"{where}: read in {units} as asked, the rig shows {found}; check the unit"))
    fits = [u for u in UNITS if problem(u) is None]
    if not fits:
        raise HandcapError(f"{where}: the camera positions fit no length unit (in {used}: {found}); "
                           "the file is damaged")
    if len(fits) > 1:
        raise HandcapError(f"{where}: the file is read in {_UNIT_WORDS[used]} but shows {found}; its positions fit "
                           f"{' or '.join(fits)}: give the unit (--units {'|'.join(fits)})")
    factor = _METRES_PER_UNIT[fits[0]] / _METRES_PER_UNIT[used]
    return rig.scaled(factor).with_warnings(warn(
        f"{where}: the file is read in {_UNIT_WORDS[used]}, which puts {found}; read as {_UNIT_WORDS[fits[0]]}, "
        f"the only unit that fits (give --units to choose)"))
