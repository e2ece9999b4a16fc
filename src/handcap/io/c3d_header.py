"""The header and parameter section of a C3D file, parsed with :mod:`struct` and checked.

This module owns what a C3D file promises before its data: the header block, the parameter records and the
numbers ezc3d will take from them (points, frames, storage, rate, data start), checked against each other and
the size of the file. It never calls ezc3d, which crashes, hangs or runs out of memory on some corrupted
parameter sections; :mod:`handcap.io.c3d` reads the points and writes files.
"""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from handcap.core.errors import HandcapError

_BLOCK = 512
_SIGNATURE = 0x50
#: Processor types (fourth byte of the parameter section): Intel, DEC and SGI/MIPS byte order and floats.
INTEL, DEC, MIPS = 84, 85, 86
_PROCESSORS = {INTEL: "Intel", DEC: "DEC", MIPS: "SGI/MIPS"}
#: Parameter types, also their size in bytes: character, byte (int8), int16 and float32.
CHAR, BYTE, INT, FLOAT = -1, 1, 2, 4


@dataclass(frozen=True)
class C3DParameter:
    """One parameter of a C3D file's parameter section, as stored.

    Attributes
    ----------
    type : int
        :data:`CHAR` (-1), :data:`BYTE` (1), :data:`INT` (2, int16) or :data:`FLOAT` (4, float32); its
        absolute value is the size of one value in bytes.
    dims : tuple of int
        The dimensions, first varying fastest (for text, the first is one string's length); () for one value.
    start : int
        Offset of the values in the file, in bytes.
    raw : bytes
        The values as stored, ``prod(dims) * abs(type)`` bytes in the file's byte order.
    """

    type: int
    dims: tuple[int, ...]
    start: int
    raw: bytes


@dataclass(frozen=True)
class C3DLayout:
    """What the header and parameter section of a C3D file promise, as ezc3d will read them.

    Attributes
    ----------
    path : Path
        The file.
    processor : int
        :data:`INTEL`, :data:`DEC` or :data:`MIPS`.
    param_start : int
        Offset of the parameter section in the file, in bytes.
    params : dict
        ``(group, name) -> C3DParameter`` for every parameter of a named group.
    records : tuple
        ``(file offset of the offset word, offset, C3DParameter or None)`` per parameter record (None for a
        group), offsets in bytes; what a byte-order conversion must rewrite.
    n_points : int
        Number of 3D points (M), from POINT:USED.
    n_frames : int
        Number of frames (T) to read: POINT:FRAMES, or the complete ones of a file cut short (``partial``).
    is_float : bool
        Float storage (else int16 scaled by POINT:SCALE).
    frame_bytes : int
        Size of one frame of points and analog samples, in bytes.
    data_start : int
        Offset of the data section in the file, in bytes.
    rate : float
        Frame rate in Hz (POINT:RATE, else the header's), the shortest decimal with its float32 value.
    """

    path: Path
    processor: int
    param_start: int
    params: dict
    records: tuple
    n_points: int
    n_frames: int
    is_float: bool
    frame_bytes: int
    data_start: int
    rate: float


def _floats(raw: bytes, processor: int) -> np.ndarray:
    """float32 values in the processor's format, as float64."""
    if processor == DEC:
        # A DEC float is an IEEE float with its 16-bit words swapped and an
        # exponent 2 higher; convert as ezc3d does (swap, then divide by 4).
        b = np.frombuffer(raw, np.uint8).reshape(-1, 4)[:, [2, 3, 0, 1]].astype(np.int16)
        b[:, 3] = np.where(b[:, 3] != 0, b[:, 3] - 1, 0)
        return np.ascontiguousarray(b.astype(np.uint8)).view("<f4").ravel().astype(np.float64)
    return np.frombuffer(raw, ">f4" if processor == MIPS else "<f4").astype(np.float64)


def _numbers(param: C3DParameter, processor: int) -> np.ndarray:
    """Values of a numeric parameter, flattened, as float64."""
    if param.type == FLOAT:
        return _floats(param.raw, processor)
    if param.type == INT:
        return np.frombuffer(param.raw, ">i2" if processor == MIPS else "<i2").astype(np.float64)
    if param.type == BYTE:
        return np.frombuffer(param.raw, np.int8).astype(np.float64)
    return np.zeros(0)


def _decode(raw: bytes) -> str:
    raw = raw.split(b"\0", 1)[0]
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError:
        text = raw.decode("latin-1")
    return text.rstrip()


def parameter_strings(param: C3DParameter) -> list[str]:
    """Values of a character parameter: one string per column of its first dimension.

    Parameters
    ----------
    param : C3DParameter
        A parameter of dimensions (L,) or (L, N1, N2, ...): strings of L bytes.

    Returns
    -------
    list of str
        ``N1 * N2 * ...`` strings (one for at most one dimension), cut at the first NUL, trailing blanks
        stripped; UTF-8, else Latin-1. Empty for a parameter that is not text.
    """
    if param.type != CHAR:
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
        ``(group, name) -> C3DParameter``.
    records : tuple
        ``(file offset of the offset word, offset, C3DParameter or None)`` per record.
    groups : set of str
        Names of the groups.

    Raises
    ------
    HandcapError
        On a record that does not fit in the section, has an impossible type,
        dimension count or group id, or does not end where the next one begins
        (the rule ezc3d checks too; ezc3d crashes on some of the others).
    """
    order = ">" if processor == MIPS else "<"
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
            if ptype not in (CHAR, BYTE, INT, FLOAT) or ndims > 7:
                raise HandcapError(f"{path}: corrupt C3D parameter section (parameter {name!r} has type {ptype} "
                                   f"and {ndims} dimensions); the file is damaged, export it again")
            dims = tuple(section[name_end + 4:name_end + 4 + ndims])
            data_start = name_end + 4 + ndims
            data_end = data_start + math.prod(dims) * abs(ptype)
            if data_end + 1 > end or data_end + 1 + section[data_end] > end:
                raise HandcapError(f"{path}: corrupt C3D parameter section (parameter {name!r} runs past the end "
                                   "of the section); the file is damaged, export it again")
            record_end = data_end + 1 + section[data_end]
            param = C3DParameter(ptype, dims, base + data_start, bytes(section[data_start:data_end]))
            found.append((gid, name, param))
        if offset and name_end + offset != record_end and processor == MIPS:
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


def inspect_c3d(path: Path, partial: bool = False) -> C3DLayout:
    """Parse and check the header and parameter section of a C3D file.

    Where the two disagree, the numbers are those ezc3d will use. With
    ``partial``, a file shorter than its header promises keeps the frames it
    holds completely; otherwise it is refused.

    Parameters
    ----------
    path : Path
        An existing file.
    partial : bool, optional
        Keep the complete frames of a file cut short instead of refusing it.

    Returns
    -------
    C3DLayout
        Numbers of points (M) and frames (T), storage, rate in Hz, offsets in bytes, the parameters.

    Raises
    ------
    HandcapError
        If the file is not a C3D file, is truncated (and not ``partial``, or holds no complete frame), its
        parameters are corrupt or disagree with its header, or it holds no points or no frames.
    """
    size = path.stat().st_size
    header, section, param_start, processor = _read_sections(path)
    param_end = param_start + len(section)
    params, records, group_names = _walk_parameters(path, section, param_start, processor)
    order = ">" if processor == MIPS else "<"
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
        if param.type == CHAR or len(values) == 0 or not np.isfinite(values[0]):
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
        if params.get((group, name), C3DParameter(INT, (), 0, b"")).type != INT:
            raise HandcapError(f"{path}: corrupt C3D file ({group}:{name} is not an integer)")
    n_points = int(number("POINT", "USED", 0, minimum=0))
    point_scale = number("POINT", "SCALE", -1.0)
    point_rate = number("POINT", "RATE", 0.0, minimum=0)
    frames = number("POINT", "FRAMES", 0.0)
    for name in [n for (g, n) in params if g == "POINT" and n.startswith(("LABELS", "UNITS"))]:
        if params[("POINT", name)].type != CHAR:
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
    return C3DLayout(path, processor, param_start, params, records, n_points, n_frames, is_float,
                   frame_bytes, data_start, float(str(np.float32(rate))))
