"""Argument helpers shared by the verbs: units, frames, shape values, lengths, the hand model, progress."""

from __future__ import annotations

import sys

import numpy as np

from handcap.core.errors import HandcapError
from handcap.io import UNITS, load_npz
from handcap.solve import MEASUREMENTS


def add_units(parser, what: str = "the input's coordinates") -> None:
    """``--units mm|cm|m``: the unit of a file that says the wrong one (see handcap.io._units)."""
    parser.add_argument("--units", choices=UNITS, default=None,
                        help=f"unit of {what}, overriding what the file says (default: the file's; an implausible "
                             f"one is replaced by the only unit that fits, with a warning)")


def add_hand_model(p, default: str = "openhand") -> None:
    """``--hand-model`` and ``--mano-dir`` for a verb that uses the hand model."""
    p.add_argument("--hand-model", metavar="MODEL",
                   help=f"openhand (built in), mano (your MANO files: --mano-dir or HANDCAP_MANO_DIR) or mano:DIR "
                        f"(default: {default})")
    p.add_argument("--mano-dir", metavar="DIR", help="folder holding MANO_RIGHT.pkl/MANO_LEFT.pkl (implies "
                                                     "--hand-model mano; default: $HANDCAP_MANO_DIR)")


def sync_arg(a):
    """``--sync`` as the steps take it: None, 'auto', or the CAM=FRAMES items; 'auto' with offsets is refused."""
    if a.sync is not None and "auto" in a.sync and a.sync != ["auto"]:
        raise HandcapError("--sync auto finds every offset: give it alone, or give CAM=FRAMES offsets instead")
    return None if a.sync is None else "auto" if a.sync == ["auto"] else a.sync


def frames_arg(text: str | None):
    """``A:B`` (frames, either end optional) -> slice."""
    if text is None:
        return None
    try:
        a, b = text.split(":")
        return slice(int(a) if a else None, int(b) if b else None)
    except ValueError:
        raise HandcapError(f"--frames must be A:B with frame numbers (either may be left out), got {text!r}") from None


def betas_arg(text: str | None):
    """10 comma-separated numbers, or a .npz holding ``betas``."""
    if text is None:
        return None
    if text.endswith(".npz"):
        return np.asarray(load_npz(text, ("betas",), "file with betas")["betas"], dtype=float).reshape(10)
    try:
        values = [float(v) for v in text.split(",")]
    except ValueError:
        raise HandcapError(f"--betas must be 10 comma-separated numbers or a .npz file, got {text!r}") from None
    if len(values) != 10:
        raise HandcapError(f"--betas needs 10 values, got {len(values)}")
    return np.array(values)


def lengths_arg(text: str | None) -> dict | None:
    """``name=millimetres,...`` -> {name: metres}."""
    if text is None:
        return None
    lengths = {}
    for item in text.split(","):
        key, _, value = item.partition("=")
        try:
            lengths[key.strip()] = float(value) / 1000
        except ValueError:
            raise HandcapError(f"--lengths takes name=millimetres pairs ({', '.join(MEASUREMENTS)}), "
                               f"got {item!r}") from None
    return lengths


def names_arg(names):
    """Names given as several arguments, or as one comma-separated argument."""
    if names is not None and len(names) == 1 and "," in names[0]:
        return [n.strip() for n in names[0].split(",")]
    return names


def print_progress(stage: str, epoch: int, loss: float) -> None:
    """Training progress on stderr: the first epoch and every tenth."""
    if epoch % 10 == 9 or epoch == 0:
        print(f"  {stage}: epoch {epoch + 1}, loss {loss:.4f}", file=sys.stderr, flush=True)
