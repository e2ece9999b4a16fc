"""Rebuild the shipped occlusion models (src/handcap/occlusion/weights/*.npz)::

    .venv/bin/python tools/occlusion_weights.py [--layout glove-13] [--out FOLDER]

(or ``make occlusion-weights``). See :mod:`handcap.occlusion.shipped` for what is trained; deterministic, so the
files come out byte for byte the same, and the SHA-256 of each is printed to compare with the shipped one.
"""

import argparse
import sys
from pathlib import Path

from handcap.occlusion.model import SHIPPED_MODELS
from handcap.occlusion.shipped import WEIGHTS, build


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="tools/occlusion_weights.py", description=__doc__.splitlines()[0])
    parser.add_argument("--layout", action="append", choices=SHIPPED_MODELS, help="only this layout (repeatable)")
    parser.add_argument("--out", type=Path, default=WEIGHTS, help="folder for the .npz files (default: the package)")
    args = parser.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    for layout in args.layout or SHIPPED_MODELS:
        build(layout, args.out / f"{layout}.npz")
    return 0


if __name__ == "__main__":
    sys.exit(main())
