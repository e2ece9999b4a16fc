"""File plumbing shared by every writer: checked and atomic outputs, deterministic archives.

No input is ever overwritten. Every command checks its output paths with
:func:`check_output` before any work (not an input, not a folder, in a folder
that exists and can be written), and every writer goes through
:func:`atomic_output`: it writes to a temporary name in the target folder and
renames it when complete, so an interrupted run keeps whatever was there
before, and a failure to write is one :class:`~handcap.HandcapError` line.
Archives are written with fixed timestamps so the same data gives the same
bytes (``numpy.savez`` stamps the current time).
"""

from __future__ import annotations

import contextlib
import io
import os
import re
import tempfile
import tomllib
import zipfile
import zlib
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


def natural_key(path) -> tuple:
    """Sort key of a file by its name, runs of digits compared as numbers (``img2`` before ``img10``).

    Parameters
    ----------
    path : str or Path

    Returns
    -------
    tuple
        The name's text parts (lower case) and numbers in turn, then the name itself to break ties.
    """
    name = Path(path).name
    return [int(t) if k % 2 else t.lower() for k, t in enumerate(re.split(r"(\d+)", name))], name


def _same(a: Path, b: Path) -> bool:
    try:
        if a.exists() and b.exists() and os.path.samefile(a, b):
            return True
        return a.resolve() == b.resolve()
    except (OSError, RuntimeError):  # a loop of links, a name the system refuses
        return False


def _folder(path: Path) -> Path:
    return path.parent if str(path.parent) else Path(".")


def _check_target(path: Path) -> Path:
    """The folder ``path`` will be written in, checked: ``path`` no folder or device, its folder a writable one."""
    if not str(path) or path.name in ("", ".", ".."):
        raise HandcapError(f"{str(path) or 'an empty name'}: not a file name; give the output a file name")
    if path.is_dir():
        raise HandcapError(f"{path}: is a folder; give the output a file name inside it")
    if path.exists() and not path.is_file():
        raise HandcapError(f"{path}: exists and is not a regular file; choose another output name")
    folder = _folder(path)
    if folder.exists() and not folder.is_dir():
        raise HandcapError(f"{path}: {folder} is a file, not a folder")
    if not folder.is_dir():
        raise HandcapError(f"{path}: folder {folder} does not exist; create it first")
    return folder


def _probe(folder: Path, path) -> None:
    """Refuse a folder in which no file can be created (permissions, read-only file system)."""
    try:
        with tempfile.TemporaryFile(dir=folder):
            pass
    except OSError as err:
        raise HandcapError(f"{path}: cannot write in folder {folder} ({err.strerror or err}); "
                           "choose a folder you can write in") from None


def check_output(output, *inputs) -> Path:
    """Check an output path before any work is done; the one check every writing command uses.

    Parameters
    ----------
    output : str or Path
        The file a command will write.
    *inputs : str or Path or None
        Files the command reads (None entries are skipped).

    Returns
    -------
    Path
        ``output`` as a Path.

    Raises
    ------
    HandcapError
        If ``output`` is one of ``inputs`` (also through a link), a folder or
        a device, or its folder is missing or cannot be written in.
    """
    out = Path(output)
    for inp in inputs:
        if inp is not None and _same(out, Path(inp)):
            raise HandcapError(f"{out}: output would overwrite the input file {inp}; choose another name")
    _probe(_check_target(out), out)
    return out


def check_not_input(output, *inputs) -> None:
    """Refuse to write ``output`` over any of ``inputs``, or where it cannot be written (:func:`check_output`)."""
    check_output(output, *inputs)


def check_output_folder(folder, *inputs, force: bool = False) -> Path:
    """Check a folder a command fills with files: new, or empty, or ``force``; never holding an input.

    Parameters
    ----------
    folder : str or Path
    *inputs : str or Path or None
        Files the command reads; none may lie in ``folder`` when it is written over.
    force : bool
        Allow writing into a folder that already holds files.

    Raises
    ------
    HandcapError
        If ``folder`` is a file, holds files and ``force`` is not given, holds
        one of ``inputs``, or it (or the folder it would be made in) cannot
        be written in.
    """
    folder = Path(folder)
    if folder.exists() and not folder.is_dir():
        raise HandcapError(f"{folder}: is a file, not a folder; give a folder for the output")
    if folder.is_dir():
        held = [Path(inp) for inp in inputs if inp is not None and _same(_folder(Path(inp)), folder)]
        if held:
            raise HandcapError(f"{folder}: holds the input {held[0]}; write the output to another folder")
        if any(folder.iterdir()) and not force:
            raise HandcapError(f"{folder}: folder is not empty; give a new or empty folder, or --force to write "
                               "over its files")
        _probe(folder, folder)
        return folder
    parent = folder.parent
    while not parent.exists() and parent != parent.parent:
        parent = parent.parent
    if not parent.is_dir():
        raise HandcapError(f"{folder}: {parent} is a file, not a folder")
    _probe(parent, folder)
    return folder


@contextlib.contextmanager
def atomic_output(path, mode: str = "wb"):
    """Open a temporary file beside ``path``; rename it onto ``path`` on success.

    Yields the open file object (``mode`` ``"wb"`` or ``"w"``), or, with
    ``mode=None``, the temporary path for libraries that write by file name.

    Parameters
    ----------
    path : str or Path
        The file to write; its folder is checked first (not a folder, writable).
    mode : str or None
        ``"wb"`` for bytes, ``"w"`` for UTF-8 text (no newline translation), or
        None to yield the temporary path instead of an open file.

    Yields
    ------
    file object or Path
        The open temporary file, or its path when ``mode`` is None.

    Raises
    ------
    HandcapError
        The folder cannot be written in, or writing or renaming fails; the
        temporary file is removed and ``path`` is left as it was.
    """
    path = Path(path)
    folder = _check_target(path)
    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".part" + path.suffix, dir=folder)
    except OSError as err:
        raise HandcapError(f"{path}: cannot write in folder {folder} ({err.strerror or err}); "
                           "choose a folder you can write in") from None
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
    except OSError as err:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise HandcapError(f"{path}: could not be written ({err.strerror or err}); nothing was changed") from None
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise


def _umask() -> int:
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def save_npz(path, arrays: dict) -> None:
    """Write ``arrays`` as a deflate-compressed ``.npz`` with fixed timestamps.

    Readable with :func:`numpy.load`; identical inputs give identical bytes.
    Written through :func:`atomic_output`, entries sorted by key.

    Parameters
    ----------
    path : str or Path
        The ``.npz`` file to write.
    arrays : dict of str to array_like
        One ``<key>.npy`` entry each, any shape and dtype that needs no pickling.

    Raises
    ------
    HandcapError
        The file cannot be written.
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


def read_toml(path) -> dict:
    """The document of a TOML file, with one clear line for a missing file, invalid TOML or text not in UTF-8."""
    path = existing_file(path)
    try:
        with open(path, "rb") as fh:
            return tomllib.load(fh)
    except tomllib.TOMLDecodeError as err:
        raise HandcapError(f"{path}: not valid TOML ({err})") from None
    except UnicodeDecodeError:
        raise HandcapError(f"{path}: not valid TOML (not UTF-8 text)") from None


def load_npz(path, required=(), what: str = "handcap .npz file") -> dict:
    """Read a ``.npz`` into a dict of arrays, refusing pickled objects.

    Parameters
    ----------
    path : str or Path
        An existing, readable file.
    required : sequence of str
        Keys the file must hold.
    what : str
        Name of the file kind for the error messages.

    Returns
    -------
    dict of str to ndarray
        Every array in the file, loaded into memory, with the shapes and units it was written with.

    Raises
    ------
    HandcapError
        If the file is not a readable npz, or lacks one of ``required``.
    """
    path = existing_file(path)
    try:
        with np.load(path, allow_pickle=False) as data:
            arrays = {key: data[key] for key in data.files}
    except (ValueError, OSError, zipfile.BadZipFile, EOFError, KeyError, zlib.error, NotImplementedError,
            RuntimeError, OverflowError, MemoryError) as err:
        # zlib.error: a damaged deflate stream; NotImplementedError: an unknown compression; RuntimeError:
        # an encrypted member; OverflowError, MemoryError: an array header promising an impossible size.
        reason = " ".join(str(err).split())[:160]
        raise HandcapError(f"{path}: not a readable {what} ({type(err).__name__}: {reason})") from None
    missing = [key for key in required if key not in arrays]
    if missing:
        raise HandcapError(f"{path}: not a {what}, missing {', '.join(missing)}")
    return arrays


def file_stamps(folder) -> dict:
    """Path -> (inode, modification time in ns) of every file under ``folder`` (empty if it does not exist).

    Parameters
    ----------
    folder : str or Path
    """
    folder = Path(folder)
    if not folder.is_dir():
        return {}
    return {p: (p.stat().st_ino, p.stat().st_mtime_ns) for p in folder.rglob("*") if p.is_file()}


def written_since(folder, before: dict) -> list[str]:
    """Files under ``folder`` that are new or rewritten since ``before`` (:func:`file_stamps`), sorted.

    Every handcap write renames a new file into place, so a rewritten file has a new inode or time.

    Parameters
    ----------
    folder : str or Path
        Folder searched recursively.
    before : dict
        Earlier :func:`file_stamps` of the same folder.

    Returns
    -------
    list of str
        Paths, sorted.
    """
    return sorted(str(p) for p, stamp in file_stamps(folder).items() if before.get(p) != stamp)
