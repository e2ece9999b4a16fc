"""File plumbing shared by every writer: atomic outputs, deterministic archives.

Writers never leave a half-written file behind: they write to a temporary name
in the target folder and rename it when complete, so an interrupted run keeps
whatever was there before. Archives are written with fixed timestamps so the
same data gives the same bytes (``numpy.savez`` stamps the current time).
"""

from __future__ import annotations

import contextlib
import io
import os
import tempfile
import zipfile
from pathlib import Path

import numpy as np

from handcap.core.errors import HandcapError

_ZIP_EPOCH = (1980, 1, 1, 0, 0, 0)


def existing_file(path) -> Path:
    """``path`` as a Path, checked to be an existing, readable file."""
    path = Path(path)
    if not path.exists():
        raise HandcapError(f"{path}: no such file")
    if path.is_dir():
        raise HandcapError(f"{path}: is a folder, expected a file")
    if not os.access(path, os.R_OK):
        raise HandcapError(f"{path}: not readable (check its permissions)")
    return path


def check_not_input(output, *inputs) -> None:
    """Refuse to write ``output`` over any of ``inputs``."""
    out = Path(output)
    for inp in inputs:
        inp = Path(inp)
        if out.exists() and inp.exists() and os.path.samefile(out, inp):
            raise HandcapError(f"{out}: output would overwrite the input file; choose another name")
        if out.resolve() == inp.resolve():
            raise HandcapError(f"{out}: output would overwrite the input file; choose another name")


@contextlib.contextmanager
def atomic_output(path, mode: str = "wb"):
    """Open a temporary file beside ``path``; rename it onto ``path`` on success.

    Yields the open file object (``mode`` ``"wb"`` or ``"w"``), or, with
    ``mode=None``, the temporary path for libraries that write by file name.
    """
    path = Path(path)
    folder = path.parent if str(path.parent) else Path(".")
    if not folder.is_dir():
        raise HandcapError(f"{path}: folder {folder} does not exist")
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".part" + path.suffix, dir=folder)
    try:
        if mode is None:
            os.close(fd)
            yield Path(tmp)
        else:
            with os.fdopen(fd, mode, **({} if "b" in mode else {"encoding": "utf-8", "newline": ""})) as fh:
                yield fh
        # mkstemp makes the file private; give it the mode a plain open() would.
        os.chmod(tmp, path.stat().st_mode & 0o777 if path.exists() else 0o666 & ~_umask())
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise


def _umask() -> int:
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def save_npz(path, arrays: dict) -> None:
    """Write ``arrays`` as an uncompressed-compatible ``.npz`` with fixed timestamps.

    Readable with :func:`numpy.load`; identical inputs give identical bytes.
    """
    with atomic_output(path) as fh, zipfile.ZipFile(fh, "w", compression=zipfile.ZIP_DEFLATED) as zf:
        for key in sorted(arrays):
            buf = io.BytesIO()
            np.lib.format.write_array(buf, np.asanyarray(arrays[key]), allow_pickle=False)
            info = zipfile.ZipInfo(f"{key}.npy", date_time=_ZIP_EPOCH)
            info.compress_type = zipfile.ZIP_DEFLATED
            info.external_attr = 0o644 << 16
            zf.writestr(info, buf.getvalue())


def warnings_entry(warnings) -> dict:
    """``{"warnings": array of str}`` for a result's warnings, or ``{}`` when it has none (File contract)."""
    return {"warnings": np.array(list(warnings), dtype=str)} if len(warnings) else {}


def read_warnings(arrays: dict) -> tuple[str, ...]:
    """The ``warnings`` entry of a loaded ``.npz`` as a tuple of one-line strings (empty when absent)."""
    value = arrays.get("warnings")
    return () if value is None else tuple(str(w) for w in np.atleast_1d(value))


def load_npz(path, required=(), what: str = "handcap .npz file") -> dict:
    """Read a ``.npz`` into a dict of arrays, refusing pickled objects.

    Raises
    ------
    HandcapError
        If the file is not a readable npz, or lacks one of ``required``.
    """
    path = existing_file(path)
    try:
        with np.load(path, allow_pickle=False) as data:
            arrays = {key: data[key] for key in data.files}
    except (ValueError, OSError, zipfile.BadZipFile, EOFError, KeyError) as err:
        raise HandcapError(f"{path}: not a readable {what} ({err})") from None
    missing = [key for key in required if key not in arrays]
    if missing:
        raise HandcapError(f"{path}: not a {what}, missing {', '.join(missing)}")
    return arrays
