"""handcap's own ``.npz`` files for every container (see File contracts in DESIGN.md).

Every file carries a ``kind`` entry (``markers``, ``points``, ``hand_motion``,
``object_motion``) so that a reader can say what it got; files written by other
tools with the contract's keys but no ``kind`` are accepted too.
"""

from __future__ import annotations

import numpy as np

from handcap.core.errors import HandcapError
from handcap.core.checks import check_positions
from handcap.core.markers import MarkerSequence
from handcap.core.motion import HandMotion, ObjectMotion
from handcap.core.points import PointCloudSequence
from handcap.core.files import load_npz, read_warnings, save_npz, warnings_entry
from handcap.io._units import check_units, metres_per_unit, settle_marker_units


def _names(values) -> np.ndarray:
    return np.array([str(v) for v in values], dtype=str) if len(values) else np.zeros(0, dtype="<U1")


def _scalar(arrays, key, path, cast=float):
    try:
        return cast(np.asarray(arrays[key]).reshape(()))
    except (ValueError, TypeError):
        raise HandcapError(f"{path}: entry {key!r} must be a single value") from None


def _numeric(arrays, key, path):
    """Entry ``key`` as float64 (None when absent), refusing text, dates and the like."""
    if arrays.get(key) is None:
        return None
    value = np.asarray(arrays[key])
    if value.dtype.kind not in "biuf":
        raise HandcapError(f"{path}: entry {key!r} must hold numbers, got {value.dtype} values")
    return value.astype(np.float64)


def _name_list(arrays, key, path) -> list[str]:
    """Entry ``key`` as a list of names ([] when absent)."""
    if arrays.get(key) is None:
        return []
    value = np.asarray(arrays[key])
    if value.ndim == 1 and value.size == 0:
        return []
    if value.ndim != 1 or value.dtype.kind not in "US":
        raise HandcapError(f"{path}: entry {key!r} must be a list of names, got {value.dtype} of shape {value.shape}")
    return [str(v) for v in value]


def _text(arrays, key, path, default: str) -> str:
    """Entry ``key`` as one string (``default`` when absent)."""
    if arrays.get(key) is None:
        return default
    value = np.asarray(arrays[key])
    if value.shape != () or value.dtype.kind not in "US":
        raise HandcapError(f"{path}: entry {key!r} must be one text value, got {value.dtype} of shape {value.shape}")
    return str(value)


def _check_kind(arrays, path, kind):
    if "kind" in arrays and _text(arrays, "kind", path, kind) != kind:
        raise HandcapError(f"{path}: holds {_text(arrays, 'kind', path, kind)[:40]!r}, not {kind}")


def npz_kind(path) -> str:
    """Which container a handcap ``.npz`` holds, guessed from its keys if unlabeled."""
    arrays = load_npz(path)
    if "kind" in arrays:
        return str(arrays["kind"])
    for kind, key in (("markers", "positions"), ("points", "points"),
                      ("hand_motion", "hand_pose"), ("object_motion", "rotation")):
        if key in arrays:
            return kind
    raise HandcapError(f"{path}: not a handcap .npz (no positions, points, hand_pose or rotation)")


def write_markers_npz(markers: MarkerSequence, path) -> None:
    """Write a markers ``.npz``: ``positions`` (T, M, 3) metres, ``names``, ``rate`` (Hz), ``residuals`` if any.

    Parameters
    ----------
    markers : MarkerSequence
        Written as it is (metres, NaN where missing), warnings included.
    path : str or Path
    """
    arrays = {"kind": np.array("markers"), "positions": markers.positions,
              "names": _names(markers.names), "rate": np.array(markers.rate)}
    if markers.residuals is not None:
        arrays["residuals"] = markers.residuals
    save_npz(path, {**arrays, **warnings_entry(markers.warnings)})


def read_markers_npz(path, *, units: str | None = None, hand=None) -> MarkerSequence:
    """Read a markers ``.npz`` (``positions`` (T, M, 3) metres, ``names``, ``rate``).

    Parameters
    ----------
    path : str or Path
    units : {"mm", "cm", "m"}, optional
        The unit of ``positions`` when a tool other than handcap wrote them in
        another unit than the contract's metres.
    hand : sequence of str, optional
        Names of one hand's markers, whose spread tells the unit when metres
        are implausible (see :mod:`handcap.io._units`).

    Raises
    ------
    HandcapError
        Not a markers ``.npz``, entries of the wrong shape or type, or
        positions that fit no length unit.
    """
    units = check_units(units)
    arrays = load_npz(path, ("positions", "names", "rate"), "marker .npz file")
    _check_kind(arrays, path, "markers")
    try:
        markers = MarkerSequence(_numeric(arrays, "positions", path) * metres_per_unit(units or "m", "units"),
                                 _name_list(arrays, "names", path), _scalar(arrays, "rate", path),
                                 _numeric(arrays, "residuals", path), _warnings(arrays, path))
    except HandcapError as err:
        raise HandcapError(f"{path}: {err}") from None
    return settle_marker_units(markers, declared="m", units=units, where=path, hand=hand)


def write_points_npz(points: PointCloudSequence, path) -> None:
    """Write a points ``.npz``: NaN-padded ``points`` (T, K, 3) in metres and ``rate`` (Hz).

    Parameters
    ----------
    points : PointCloudSequence
    path : str or Path
    """
    save_npz(path, {"kind": np.array("points"), "points": points.padded(), "rate": np.array(points.rate)})


def read_points_npz(path, *, units: str | None = None) -> PointCloudSequence:
    """Read an unlabeled points ``.npz`` (``points`` (T, K, 3) metres NaN-padded, ``rate``).

    ``units`` gives the unit of ``points`` when it is not the contract's
    metres; the units are checked as for markers (:mod:`handcap.io._units`).

    Parameters
    ----------
    path : str or Path
    units : {"mm", "cm", "m"}, optional
        The unit of the stored points; metres by default.

    Returns
    -------
    PointCloudSequence
        Points (K_t, 3) per frame, metres (rows with any NaN dropped).

    Raises
    ------
    HandcapError
        Not a points ``.npz``, entries of the wrong shape or type, or points that fit no length unit.
    """
    units = check_units(units)
    arrays = load_npz(path, ("points", "rate"), "point-cloud .npz file")
    _check_kind(arrays, path, "points")
    try:
        padded = check_positions(_numeric(arrays, "points", path))
        rate = _scalar(arrays, "rate", path)
        points = PointCloudSequence.from_padded(padded * metres_per_unit(units or "m", "units"), rate)
        padded = points.padded()
        as_markers = MarkerSequence(padded, [f"p{k}" for k in range(padded.shape[1])], rate)
    except HandcapError as err:
        raise HandcapError(f"{path}: {err}") from None
    settled = settle_marker_units(as_markers, declared="m", units=units, where=path)
    return points if settled is as_markers else PointCloudSequence.from_markers(settled)


def write_hand_motion(motion: HandMotion, path) -> None:
    """Write a hand-motion ``.npz`` (File contract of DESIGN.md): every field of ``motion`` that is set.

    Parameters
    ----------
    motion : HandMotion
        Stored as it is: axis-angle in radians, ``transl``, ``joints`` and ``marker_fit`` in metres.
    path : str or Path
    """
    arrays = {"kind": np.array("hand_motion"), "betas": motion.betas,
              "global_orient": motion.global_orient, "hand_pose": motion.hand_pose,
              "transl": motion.transl, "rate": np.array(motion.rate), "side": np.array(motion.side),
              "model": np.array(motion.model), "marker_names": _names(motion.marker_names)}
    for key in ("phi", "joints", "marker_fit", "marker_residuals"):
        if getattr(motion, key) is not None:
            arrays[key] = getattr(motion, key)
    save_npz(path, {**arrays, **warnings_entry(motion.warnings)})


def read_hand_motion(path) -> HandMotion:
    """Read a hand-motion ``.npz`` written by :func:`write_hand_motion` (or with its keys).

    Parameters
    ----------
    path : str or Path
        Needs ``betas``, ``global_orient``, ``hand_pose``, ``transl`` and ``rate``.

    Returns
    -------
    HandMotion
        Radians and metres, as stored; ``side`` and ``model`` default to ``"right"`` and ``"openhand"``.

    Raises
    ------
    HandcapError
        Unreadable file, another ``kind``, missing entries, or entries of the wrong shape or type.
    """
    arrays = load_npz(path, ("betas", "global_orient", "hand_pose", "transl", "rate"), "hand-motion .npz file")
    _check_kind(arrays, path, "hand_motion")
    try:
        def number(key):
            return _numeric(arrays, key, path)
        return HandMotion(
            number("betas"), number("global_orient"), number("hand_pose"), number("transl"),
            _scalar(arrays, "rate", path), _text(arrays, "side", path, "right"), number("phi"),
            _text(arrays, "model", path, "openhand"), number("joints"),
            tuple(_name_list(arrays, "marker_names", path)), number("marker_fit"), number("marker_residuals"),
            _warnings(arrays, path))
    except HandcapError as err:
        raise HandcapError(f"{path}: {err}") from None


def write_object_motion(motion: ObjectMotion, path, extra: dict | None = None) -> None:
    """Write an object-motion ``.npz``: ``rotation`` (T, 3) radians, ``translation`` (T, 3) metres, and the rest.

    Articulation states are stored as ``state_<key>`` entries.

    Parameters
    ----------
    motion : ObjectMotion
    path : str or Path
    extra : dict, optional
        More entries (e.g. a cube's ``moves``), written as they are.
    """
    arrays = {"kind": np.array("object_motion"), "rotation": motion.rotation,
              "translation": motion.translation, "rate": np.array(motion.rate),
              "name": np.array(motion.name), "marker_names": _names(motion.marker_names)}
    if motion.canonical is not None:
        arrays["canonical"] = motion.canonical
    for key, value in motion.state.items():
        arrays[f"state_{key}"] = value
    save_npz(path, {**arrays, **(extra or {}), **warnings_entry(motion.warnings)})


def read_object_motion(path) -> ObjectMotion:
    """Read an object-motion ``.npz`` written by :func:`write_object_motion` (or with its keys).

    Parameters
    ----------
    path : str or Path
        Needs ``rotation``, ``translation`` and ``rate``.

    Returns
    -------
    ObjectMotion
        Rotation axis-angle in radians, translation and ``canonical`` in metres; ``state_<key>``
        entries become ``state[key]``, as float64.

    Raises
    ------
    HandcapError
        Unreadable file, another ``kind``, missing entries, or entries of the wrong shape or type.
    """
    arrays = load_npz(path, ("rotation", "translation", "rate"), "object-motion .npz file")
    _check_kind(arrays, path, "object_motion")
    try:
        state = {k[len("state_"):]: _numeric(arrays, k, path) for k in arrays if k.startswith("state_")}
        return ObjectMotion(_numeric(arrays, "rotation", path), _numeric(arrays, "translation", path),
                            _scalar(arrays, "rate", path), _text(arrays, "name", path, "object"),
                            tuple(_name_list(arrays, "marker_names", path)), _numeric(arrays, "canonical", path),
                            state, _warnings(arrays, path))
    except HandcapError as err:
        raise HandcapError(f"{path}: {err}") from None


def _warnings(arrays, path) -> tuple[str, ...]:
    """The ``warnings`` entry (one-line strings), checked to be text."""
    if arrays.get("warnings") is not None and np.asarray(arrays["warnings"]).dtype.kind not in "US":
        raise HandcapError(f"{path}: entry 'warnings' must be text, got {np.asarray(arrays['warnings']).dtype}")
    return read_warnings(arrays)
