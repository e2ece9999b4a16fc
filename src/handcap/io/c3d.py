"""C3D marker files, read and written with ezc3d.

Reading
-------
Before ezc3d sees a file, its header and parameter section are parsed here with
:mod:`struct` and checked, and the size of the data section they promise is
compared with the size of the file. ezc3d 1.7 crashes (segmentation fault),
hangs or runs out of memory on some corrupted parameter sections, and it reads a
truncated file without complaint, returning only the frames that are there
(``Vicon.c3d`` cut to 200000 bytes gives 48 of its 580 frames). Every such file
raises :class:`~handcap.HandcapError` here instead; ``read_c3d(path,
partial=True)`` keeps the complete frames of a file cut short. Where the header
and the parameters disagree, the parameters win (POINT:USED, POINT:FRAMES,
ANALOG:USED, ANALOG:RATE), as they do in ezc3d.

Big-endian files (processor type SGI/MIPS, which ezc3d refuses) are converted to
Intel byte order in a temporary copy and read from there.

Units come from POINT:UNITS (``mm``, ``cm``, ``m``); a file with no or an empty
POINT:UNITS is taken to be in millimetres, the C3D default that Vicon and
Qualisys write. Labels are kept as written, ``Subject:`` prefix included;
POINT:LABELS2, LABELS3, ... continue POINT:LABELS for files of more than 255
points, and labels beyond the number of points are ignored.

Missing data
------------
A sample is missing (NaN) where

* its residual is negative: the C3D convention (residual -1), used by the
  Vicon, Optotrak and c3d.org sample files; ezc3d turns these into NaN;
* the file stores NaN coordinates (the kineticstoolkit and auto_marker_label
  files do, with residual 0);
* it is exactly (0, 0, 0) with residual 0: some writers mark missing samples
  this way, and none of the real files in ``../shared/data/markers`` holds a
  sample there. A marker that really sits on the lab origin to the last bit in
  all three coordinates, with no residual, is read as missing.

Residuals are kept in ``MarkerSequence.residuals``, in metres. Coordinates
beyond 10 km are refused as garbage bytes read as floats.

Writing
-------
:func:`write_c3d` writes float storage in millimetres, missing samples as
(0, 0, 0) with residual -1, and the sequence's residuals (0 where it has none),
rounded to the POINT:SCALE step (0.01 mm, coarser if a residual exceeds 1.27 mm,
because C3D keeps residuals in 7 bits). The rate is stored as float32, as C3D
does; the reader gives back the shortest decimal with that float32 value.
"""

from __future__ import annotations

import math
import os
import struct
import tempfile
from dataclasses import dataclass
from pathlib import Path

import ezc3d
import numpy as np

from handcap.core.errors import HandcapError
from handcap.core.markers import MarkerSequence
from handcap.core.files import atomic_output, existing_file
from handcap.io._units import check_units, metres_per_unit, settle_marker_units, unit_name

_BLOCK = 512
_SIGNATURE = 0x50
_INTEL, _DEC, _MIPS = 84, 85, 86
_PROCESSORS = {_INTEL: "Intel", _DEC: "DEC", _MIPS: "SGI/MIPS"}
_CHAR, _BYTE, _INT, _FLOAT = -1, 1, 2, 4
# Coordinates beyond this (metres) cannot come from a capture volume; they come
# from garbage bytes read as floats.
_IMPLAUSIBLE = 1e4
# C3D keeps residuals in 7 bits of the fourth word, in steps of |POINT:SCALE|.
_RESIDUAL_LEVELS = 127
_RESIDUAL_STEP_MM = 0.01
# What ezc3d raises for the errors it reports (std::ios_base::failure arrives
# as OSError, std::bad_alloc as MemoryError or RuntimeError).
_EZC3D_ERRORS = (RuntimeError, OSError, ValueError, IndexError, MemoryError, OverflowError)


@dataclass(frozen=True)
class _Parameter:
    type: int               # -1 char, 1 byte, 2 int16, 4 float32
    dims: tuple[int, ...]
    start: int              # offset of the values in the file
    raw: bytes


@dataclass(frozen=True)
class _Layout:
    """What the header and parameter section of a C3D file promise."""

    path: Path
    processor: int
    param_start: int
    params: dict             # (group, name) -> _Parameter
    records: tuple           # (offset word position, offset, _Parameter or None), for byte swapping
    n_points: int
    n_frames: int
    is_float: bool
    frame_bytes: int
    data_start: int
    rate: float


# -- reading the header and parameter section ------------------------------------------

def _floats(raw: bytes, processor: int) -> np.ndarray:
    """float32 values in the processor's format, as float64."""
    if processor == _DEC:
        # A DEC float is an IEEE float with its 16-bit words swapped and an
        # exponent 2 higher; convert as ezc3d does (swap, then divide by 4).
        b = np.frombuffer(raw, np.uint8).reshape(-1, 4)[:, [2, 3, 0, 1]].astype(np.int16)
        b[:, 3] = np.where(b[:, 3] != 0, b[:, 3] - 1, 0)
        return np.ascontiguousarray(b.astype(np.uint8)).view("<f4").ravel().astype(np.float64)
    return np.frombuffer(raw, ">f4" if processor == _MIPS else "<f4").astype(np.float64)


def _numbers(param: _Parameter, processor: int) -> np.ndarray:
    """Values of a numeric parameter, flattened, as float64."""
    if param.type == _FLOAT:
        return _floats(param.raw, processor)
    if param.type == _INT:
        return np.frombuffer(param.raw, ">i2" if processor == _MIPS else "<i2").astype(np.float64)
    if param.type == _BYTE:
        return np.frombuffer(param.raw, np.int8).astype(np.float64)
    return np.zeros(0)


def _decode(raw: bytes) -> str:
    raw = raw.split(b"\0", 1)[0]
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError:
        text = raw.decode("latin-1")
    return text.rstrip()


def _strings(param: _Parameter) -> list[str]:
    """Values of a character parameter: one string per column of its first dimension."""
    if param.type != _CHAR:
        return []
    if len(param.dims) <= 1:
        return [_decode(param.raw)]
    length = param.dims[0]
    count = math.prod(param.dims[1:])
    return [_decode(param.raw[k * length:(k + 1) * length]) for k in range(count)]


def _walk_parameters(path, section: bytes, base: int, processor: int):
    """Parse the parameter records of ``section`` (which starts at file offset ``base``).

    Returns
    -------
    params : dict
        ``(group, name) -> _Parameter``.
    records : tuple
        ``(file offset of the offset word, offset, _Parameter or None)`` per record.
    groups : set of str
        Names of the groups.

    Raises
    ------
    HandcapError
        On a record that does not fit in the section, has an impossible type,
        dimension count or group id, or does not end where the next one begins
        (the rule ezc3d checks too; ezc3d crashes on some of the others).
    """
    order = ">" if processor == _MIPS else "<"
    end = len(section)
    groups, found, records = {}, [], []
    pos = 4
    for _ in range(100000):
        if pos + 2 > end:
            raise HandcapError(f"{path}: corrupt C3D parameter section (a record runs past its end); "
                               "the file is damaged, export it again")
        name_len, gid = struct.unpack_from("bb", section, pos)
        if name_len == 0:
            break
        name_end = pos + 2 + abs(name_len)
        if name_end + 2 > end:
            raise HandcapError(f"{path}: corrupt C3D parameter section (a record runs past its end); "
                               "the file is damaged, export it again")
        name = section[pos + 2:name_end].decode("latin-1")
        (offset,) = struct.unpack_from(order + "H", section, name_end)
        if gid == 0:
            raise HandcapError(f"{path}: corrupt C3D parameter section (record {name!r} has group id 0); "
                               "the file is damaged, export it again")
        if gid < 0:
            if name_end + 3 > end:
                raise HandcapError(f"{path}: corrupt C3D parameter section (group {name!r} runs past its end); "
                                   "the file is damaged, export it again")
            record_end = name_end + 3 + section[name_end + 2]
            groups[-gid] = name
            param = None
        else:
            if name_end + 4 > end:
                raise HandcapError(f"{path}: corrupt C3D parameter section (parameter {name!r} runs past its "
                                   "end); the file is damaged, export it again")
            ptype, ndims = struct.unpack_from("bB", section, name_end + 2)
            if ptype not in (_CHAR, _BYTE, _INT, _FLOAT) or ndims > 7:
                raise HandcapError(f"{path}: corrupt C3D parameter section (parameter {name!r} has type {ptype} "
                                   f"and {ndims} dimensions); the file is damaged, export it again")
            dims = tuple(section[name_end + 4:name_end + 4 + ndims])
            data_start = name_end + 4 + ndims
            data_end = data_start + math.prod(dims) * abs(ptype)
            if data_end + 1 > end or data_end + 1 + section[data_end] > end:
                raise HandcapError(f"{path}: corrupt C3D parameter section (parameter {name!r} runs past the end "
                                   "of the section); the file is damaged, export it again")
            record_end = data_end + 1 + section[data_end]
            param = _Parameter(ptype, dims, base + data_start, bytes(section[data_start:data_end]))
            found.append((gid, name, param))
        if offset and name_end + offset != record_end and processor == _MIPS:
            # Some SGI writers left an offset in Intel byte order (c3d.org's
            # sample sgi_int.c3d: POINT:LABELS); accept it when that fits.
            swapped = int.from_bytes(offset.to_bytes(2, "big"), "little")
            offset = swapped if name_end + swapped == record_end else offset
        records.append((base + name_end, offset, param))
        if offset == 0:
            break
        if name_end + offset != record_end:
            raise HandcapError(f"{path}: corrupt C3D parameter section (record {name!r} does not end where the "
                               "next one begins); the file is damaged, export it again")
        pos = record_end
    else:
        raise HandcapError(f"{path}: corrupt C3D parameter section (no end marker); the file is damaged")
    params = {}
    for gid, name, param in found:
        if gid in groups:
            params[(groups[gid], name)] = param
    return params, tuple(records), set(groups.values())


def _read_sections(path) -> tuple[bytes, bytes, int, int]:
    """The header block, the parameter section, its file offset and the processor type."""
    size = path.stat().st_size
    with open(path, "rb") as fh:
        header = fh.read(_BLOCK)
        if len(header) < _BLOCK:
            if len(header) >= 2 and header[1] == _SIGNATURE and header[0] >= 2:
                raise HandcapError(f"{path}: truncated C3D file ({size} bytes, shorter than its header); "
                                   "copy or export the file again")
            raise HandcapError(f"{path}: not a C3D file ({size} bytes, shorter than a C3D header)")
        if header[1] != _SIGNATURE or header[0] < 2:
            raise HandcapError(f"{path}: not a C3D file (no C3D signature in its first block); "
                               "check the file and its extension")
        param_start = (header[0] - 1) * _BLOCK
        fh.seek(param_start)
        head = fh.read(4)
        if len(head) < 4:
            raise HandcapError(f"{path}: truncated C3D file (ends before its parameter section); "
                               "copy or export the file again")
        n_blocks, processor = head[2], head[3]
        if processor not in _PROCESSORS:
            raise HandcapError(f"{path}: corrupt C3D file (unknown processor type {processor}, "
                               "expected 84 Intel, 85 DEC or 86 SGI/MIPS)")
        if n_blocks == 0:
            raise HandcapError(f"{path}: corrupt C3D file (its parameter section has 0 blocks)")
        fh.seek(param_start)
        section = fh.read(n_blocks * _BLOCK)
    param_end = param_start + n_blocks * _BLOCK
    if len(section) < n_blocks * _BLOCK:
        raise HandcapError(f"{path}: truncated C3D file (ends inside its parameter section, {size} of at least "
                           f"{param_end} bytes); copy or export the file again")
    return header, section, param_start, processor


def _inspect(path, partial: bool = False) -> _Layout:
    """Parse and check the header and parameter section of a C3D file.

    Where the two disagree, the numbers are those ezc3d will use. With
    ``partial``, a file shorter than its header promises keeps the frames it
    holds completely; otherwise it is refused.
    """
    size = path.stat().st_size
    header, section, param_start, processor = _read_sections(path)
    param_end = param_start + len(section)
    params, records, group_names = _walk_parameters(path, section, param_start, processor)
    order = ">" if processor == _MIPS else "<"
    # Header words are 1-based 16-bit words; 7-8 and 11-12 hold floats.
    first_word, last_word = struct.unpack_from(order + "2H", header, 6)
    data_block, header_samples = struct.unpack_from(order + "2H", header, 16)
    header_scale = _floats(header[12:16], processor)[0]
    header_rate = _floats(header[20:24], processor)[0]

    def number(group, name, default, *, minimum=None):
        # ezc3d gives absent parameters a default, but reads the first value of
        # present ones without checking that there is one.
        param = params.get((group, name))
        if param is None:
            return default
        values = _numbers(param, processor)
        if param.type == _CHAR or len(values) == 0 or not np.isfinite(values[0]):
            raise HandcapError(f"{path}: corrupt C3D file ({group}:{name} is empty or not a number)")
        if minimum is not None and values[0] < minimum:
            raise HandcapError(f"{path}: corrupt C3D file ({group}:{name} is {values[0]:g})")
        return float(values[0])

    def total(group, name):
        count, k = 0, 1
        while (group, name + (str(k) if k > 1 else "")) in params:
            count += len(_numbers(params[(group, name + (str(k) if k > 1 else ""))], processor))
            k += 1
        return count

    if "POINT" not in group_names:
        raise HandcapError(f"{path}: not a marker C3D file (it has no POINT group)")
    for group, name in (("POINT", "USED"), ("ANALOG", "USED")):
        if params.get((group, name), _Parameter(_INT, (), 0, b"")).type != _INT:
            raise HandcapError(f"{path}: corrupt C3D file ({group}:{name} is not an integer)")
    n_points = int(number("POINT", "USED", 0, minimum=0))
    point_scale = number("POINT", "SCALE", -1.0)
    point_rate = number("POINT", "RATE", 0.0, minimum=0)
    frames = number("POINT", "FRAMES", 0.0)
    for name in [n for (g, n) in params if g == "POINT" and n.startswith(("LABELS", "UNITS"))]:
        if params[("POINT", name)].type != _CHAR:
            raise HandcapError(f"{path}: corrupt C3D file (POINT:{name} is not text)")
    # Analog samples per frame and channels as ezc3d's updateHeader sets them.
    n_channels = int(number("ANALOG", "USED", 0, minimum=0))
    analog_rate = number("ANALOG", "RATE", 0.0, minimum=0)
    samples = header_samples
    if int(point_rate) != 0 and int(analog_rate / point_rate) != samples:
        if not (samples == 1 and "SHADOW" in group_names):
            samples = int(analog_rate / point_rate)
    if n_channels:
        number("ANALOG", "GEN_SCALE", 1.0)
        for name in ("SCALE", "OFFSET"):
            if total("ANALOG", name) < n_channels:
                raise HandcapError(f"{path}: corrupt C3D file (ANALOG:{name} has {total('ANALOG', name)} "
                                   f"values for {n_channels} channels)")
    if "ROTATION" in group_names and number("ROTATION", "USED", 0.0, minimum=0) > 0:
        start = number("ROTATION", "DATA_START", 0.0)
        number("ROTATION", "RATIO", 1.0, minimum=1)
        if not 1 <= start or (start - 1) * _BLOCK >= size:
            raise HandcapError(f"{path}: truncated or corrupt C3D file (ROTATION:DATA_START block {start:g} "
                               "is not inside the file)")

    # Frame count as ezc3d computes it: POINT:FRAMES wins over the header.
    first = first_word - 1 if first_word else 0
    last = last_word - 1 if last_word else 0
    if frames:
        frames = int(frames) % 65536 if frames < 0 else int(frames)  # int16 FRAMES past 32767
        last = frames + first - 1
        # The header and POINT:FRAMES must agree, unless the take is longer
        # than the header's 16-bit last frame can say.
        if frames != last_word - first_word + 1 and not (last_word == 0xFFFF and frames > 0xFFFF - first_word):
            raise HandcapError(f"{path}: inconsistent C3D file (its header holds frames {first_word} to "
                               f"{last_word}, POINT:FRAMES says {frames} frames); export it again")
    n_frames = 0 if n_points == 0 and n_channels == 0 else last - first + 1
    if n_points == 0:
        raise HandcapError(f"{path}: C3D file holds no 3D points (POINT:USED is 0)")
    if n_frames <= 0:
        raise HandcapError(f"{path}: C3D file holds no frames (first frame {first_word}, last {last_word}, "
                           f"POINT:FRAMES {frames})")
    is_float = header_scale < 0
    if (point_scale < 0) != is_float:
        raise HandcapError(f"{path}: corrupt C3D file (the header scale {header_scale:g} and POINT:SCALE "
                           f"{point_scale:g} disagree on integer or float storage)")
    if not is_float and point_scale == 0:
        raise HandcapError(f"{path}: corrupt C3D file (POINT:SCALE is 0 for integer storage)")
    rate = point_rate if point_rate else header_rate
    if not np.isfinite(rate) or rate <= 0:
        raise HandcapError(f"{path}: corrupt C3D file (frame rate {rate:g} Hz in POINT:RATE and the header)")
    data_start = (data_block - 1) * _BLOCK
    if data_block < 1 or data_start < param_end:
        raise HandcapError(f"{path}: corrupt C3D file (data start block {data_block} lies inside the header or "
                           "parameter section)")
    frame_bytes = (4 * n_points + n_channels * samples) * (4 if is_float else 2)
    needed = data_start + n_frames * frame_bytes
    if size < needed:
        complete = max(size - data_start, 0) // frame_bytes
        if not partial or complete == 0:
            raise HandcapError(f"{path}: truncated C3D file ({size} bytes, its header promises {n_frames} frames "
                               f"in {needed} bytes, only {complete} complete); copy or export the file again"
                               + (", or keep those with read_c3d(path, partial=True) (handcap convert --partial)"
                                  if complete else ""))
        n_frames = complete
    # Rates are float32 in C3D: keep the shortest decimal that gives the same
    # float32 (69.9, not 69.9000015258789).
    return _Layout(path, processor, param_start, params, records, n_points, n_frames, is_float,
                   frame_bytes, data_start, float(str(np.float32(rate))))


def _one_line(err: BaseException) -> str:
    """ezc3d's message on one line (some of them span several)."""
    return " ".join(str(err).split())[:200]


# -- big-endian files --------------------------------------------------------------------

def _swap(buf: bytearray, start: int, stop: int, width: int) -> None:
    """Reverse the byte order of the ``width``-byte values in ``buf[start:stop]``."""
    view = np.frombuffer(buf, np.uint8, count=stop - start, offset=start).reshape(-1, width)
    buf[start:stop] = view[:, ::-1].tobytes()


def _intel_copy(layout: _Layout, target: Path) -> None:
    """Write a copy of a big-endian (SGI/MIPS) C3D file in Intel byte order."""
    buf = bytearray(layout.path.read_bytes())
    _swap(buf, 2, 12, 2)            # words 2-6: points, analogs, first/last frame, gap
    _swap(buf, 12, 16, 4)           # words 7-8: scale
    _swap(buf, 16, 20, 2)           # words 9-10: data start, analog samples
    _swap(buf, 20, 24, 4)           # words 11-12: frame rate
    _swap(buf, 24, 304, 2)          # words 13-152: reserved, label and event keys
    _swap(buf, 304, 376, 4)         # words 153-188: 18 event times
    _swap(buf, 394, 396, 2)         # word 198: reserved (event flags and labels are bytes)
    buf[layout.param_start + 3] = _INTEL
    for offset_at, offset, param in layout.records:
        struct.pack_into("<H", buf, offset_at, offset)
        if param is not None and param.type in (_INT, _FLOAT) and param.raw:
            _swap(buf, param.start, param.start + len(param.raw), param.type)
    width = 4 if layout.is_float else 2
    _swap(buf, layout.data_start, layout.data_start + layout.n_frames * layout.frame_bytes, width)
    target.write_bytes(bytes(buf))


def _read_points(layout: _Layout) -> tuple[np.ndarray, np.ndarray]:
    """Points (4, M, T) and residuals (1, M, T) read by ezc3d, in file units."""
    with tempfile.TemporaryDirectory(prefix="handcap-c3d-") as tmp:
        source = layout.path
        if layout.processor == _MIPS:
            source = Path(tmp) / "intel.c3d"
            _intel_copy(layout, source)
        try:
            c3d = ezc3d.c3d(str(source))
            points = np.asarray(c3d["data"]["points"], dtype=np.float64)
            residuals = np.asarray(c3d["data"]["meta_points"]["residuals"], dtype=np.float64)
        except _EZC3D_ERRORS as err:
            raise HandcapError(f"{layout.path}: unreadable C3D file ({_one_line(err)}); export it again") from None
    # A file cut short (read with partial=True) may give one more, incomplete frame.
    points, residuals = points[:, :, :layout.n_frames], residuals[:, :, :layout.n_frames]
    expected = (4, layout.n_points, layout.n_frames)
    if points.shape != expected or residuals.shape != (1,) + expected[1:]:
        raise HandcapError(f"{layout.path}: inconsistent C3D file (read {points.shape[2]} frames of "
                           f"{points.shape[1]} points, its header promises {layout.n_frames} of "
                           f"{layout.n_points}); export it again")
    return points, residuals


def _labels(layout: _Layout) -> list[str]:
    """POINT:LABELS, LABELS2, ... cut to the number of points, made unique."""
    labels, k = [], 1
    while ("POINT", "LABELS" + (str(k) if k > 1 else "")) in layout.params:
        labels += _strings(layout.params[("POINT", "LABELS" + (str(k) if k > 1 else ""))])
        k += 1
    labels = labels[:layout.n_points]
    labels += [""] * (layout.n_points - len(labels))
    names, taken = [], set(labels)
    for i, label in enumerate(labels):
        name = label or f"point{i + 1}"
        if name in names:              # a repeated label: the later ones get a suffix
            k = 2
            while f"{name}~{k}" in taken:
                k += 1
            name = f"{name}~{k}"
        taken.add(name)
        names.append(name)
    return names


def read_c3d(path, *, partial: bool = False, units: str | None = None, hand=None) -> MarkerSequence:
    """Read the 3D points of a C3D file.

    Parameters
    ----------
    path : str or Path
        A ``.c3d`` file (Intel, DEC or SGI/MIPS byte order; integer or float storage).
    partial : bool, optional
        Read the complete frames of a file that is shorter than its header and
        POINT:FRAMES promise, instead of refusing it. Off by default, because
        such a file is almost always a cut copy. (``ezc3d/Optotrak.c3d`` is one:
        its header promises 1149 frames, it holds 29.)
    units : {"mm", "cm", "m"}, optional
        The unit of the coordinates, overriding POINT:UNITS.
    hand : sequence of str, optional
        Names of one hand's markers, whose spread tells the unit when the
        file's is implausible (see :mod:`handcap.io._units`).

    Returns
    -------
    MarkerSequence
        ``positions`` (T, M, 3) in metres, NaN where missing (see the module
        notes for the rule), ``names`` from POINT:LABELS (LABELS2, ... for more
        than 255 points), ``rate`` from POINT:RATE in Hz, ``residuals`` (T, M)
        in metres.

    Raises
    ------
    HandcapError
        If the file is not a C3D file, is truncated or corrupt, names an
        unknown unit, holds no points, or its coordinates fit no length unit.

    Notes
    -----
    Units come from POINT:UNITS; a missing or empty POINT:UNITS means
    millimetres. Empty labels become ``point<i>`` (1-based) and repeated labels
    get a ``~2``, ``~3`` suffix, so that names stay unique.
    """
    units = check_units(units)
    path = existing_file(path)
    layout = _inspect(path, partial)
    points, residuals = _read_points(layout)
    said = _strings(layout.params[("POINT", "UNITS")]) if ("POINT", "UNITS") in layout.params else []
    unit = said[0] if said and said[0] else "mm"
    metres_per_unit(unit, f"{path}: POINT:UNITS")
    scale = metres_per_unit(units or unit, "units")
    positions = points[:3].transpose(2, 1, 0) * scale
    residuals = residuals[0].T * scale
    zero = (positions == 0).all(axis=2) & (residuals == 0)
    positions[zero] = np.nan
    if np.isinf(positions).any() or (np.abs(positions) > _IMPLAUSIBLE).any():
        t, m = np.argwhere(np.isinf(positions) | (np.abs(positions) > _IMPLAUSIBLE))[0][:2]
        raise HandcapError(f"{path}: corrupt C3D data (coordinate beyond {_IMPLAUSIBLE:g} m at frame {t}, "
                           f"point {m}); export the file again")
    warnings = _strings(layout.params[("HANDCAP", "WARNINGS")]) if ("HANDCAP", "WARNINGS") in layout.params else []
    try:
        markers = MarkerSequence(positions, _labels(layout), layout.rate, residuals, tuple(w for w in warnings if w))
    except HandcapError as err:
        raise HandcapError(f"{path}: {err}") from None
    return settle_marker_units(markers, declared=unit_name(unit), units=units, where=path, hand=hand)


# -- writing -----------------------------------------------------------------------------

def _check_names(names, path) -> None:
    for name in names:
        if not name or name != name.rstrip() or "\0" in name:
            raise HandcapError(f"{path}: marker name {name!r} cannot be stored in C3D (empty, trailing "
                               "space or NUL); rename the marker")
        if len(name.encode("utf-8")) > 255:
            raise HandcapError(f"{path}: marker name {name[:40]!r}... is longer than the 255 bytes C3D allows; "
                               "rename the marker")


def write_c3d(markers: MarkerSequence, path) -> None:
    """Write markers as a C3D file (float storage, millimetres), atomically.

    Parameters
    ----------
    markers : MarkerSequence
        T >= 1 frames of M >= 1 markers; positions in metres, NaN where missing.
    path : str or Path
        Output file; written under a temporary name and renamed when complete.

    Raises
    ------
    HandcapError
        If there is nothing to write, a name cannot be stored in C3D, or the
        file cannot be written.

    Notes
    -----
    Missing samples are written as (0, 0, 0) with residual -1. Residuals are
    written in millimetres, rounded to the POINT:SCALE step (0.01 mm, or
    max residual / 127 if that is larger); without residuals they are 0. More
    than 255 markers go to POINT:LABELS, LABELS2, ...
    """
    if not isinstance(markers, MarkerSequence):
        raise HandcapError(f"write_c3d needs a MarkerSequence, got {type(markers).__name__}")
    if markers.n_frames == 0 or markers.n_markers == 0:
        raise HandcapError(f"{path}: nothing to write ({markers.n_frames} frames, {markers.n_markers} markers)")
    _check_names(markers.names, path)
    if (np.abs(np.nan_to_num(markers.positions)) > _IMPLAUSIBLE).any():
        raise HandcapError(f"{path}: coordinates beyond {_IMPLAUSIBLE:g} m cannot be written; "
                           "positions must be in metres")
    missing = markers.missing
    points = np.ones((4, markers.n_markers, markers.n_frames))
    points[:3] = np.nan_to_num(markers.positions * 1000.0, nan=0.0).transpose(2, 1, 0)
    residual_mm = np.zeros(missing.shape) if markers.residuals is None else markers.residuals * 1000.0
    residual_mm = np.clip(np.nan_to_num(residual_mm, nan=0.0), 0.0, None)
    step = max(_RESIDUAL_STEP_MM, float(residual_mm.max()) / _RESIDUAL_LEVELS)
    # ezc3d truncates residual / step to an integer: aim at the middle of the level.
    residual_mm = (np.rint(residual_mm / step) + 0.5) * step
    residual_mm[missing] = -1.0
    c3d = ezc3d.c3d()
    c3d["parameters"]["POINT"]["RATE"]["value"] = [markers.rate]
    c3d["parameters"]["POINT"]["LABELS"]["value"] = list(markers.names)
    c3d.add_parameter("POINT", "UNITS", "mm")
    c3d.add_parameter("POINT", "SCALE", -step)
    if markers.warnings:  # handcap's warnings about the data travel with it (File contracts)
        c3d.add_parameter("HANDCAP", "WARNINGS", list(markers.warnings))
    c3d["data"]["points"] = points
    c3d["data"]["meta_points"] = {"residuals": residual_mm.T[np.newaxis]}
    with atomic_output(path, mode=None) as tmp:
        # ezc3d appends ".c3d" to names that do not end with it (e.g. ".C3D").
        target = tmp if tmp.name.endswith(".c3d") else tmp.with_name(tmp.name + ".c3d")
        try:
            c3d.write(str(target))
            if target != tmp:
                os.replace(target, tmp)
        except _EZC3D_ERRORS + (TypeError,) as err:
            raise HandcapError(f"{path}: could not write the C3D file ({_one_line(err)})") from None
        finally:
            if target != tmp and target.exists():
                target.unlink()
