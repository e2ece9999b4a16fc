"""Make the shipped occlusion models: ``python -m handcap.occlusion.shipped`` (or ``make occlusion-weights``).

For every layout of :data:`~handcap.occlusion.model.SHIPPED_MODELS`: synthetic
takes of :data:`SUBJECTS` subjects doing every motion of
:data:`~handcap.occlusion.data.TRAIN_MOTIONS` (6 s each, 100 Hz, right hand),
then :func:`~handcap.occlusion.train.train_occlusion_model` with seed 0,
:data:`~handcap.occlusion.augment.SUBJECT_AUGMENTATION` (every training sample
another subject's scale and marker placement: the shipped models serve subjects
they never saw, issue 14) and its default offset-consistent pairs (the marker
predictor scored as the filler uses it over gaps up to a second). Both steps are deterministic, so the files come out
byte for byte the same; the SHA-256 of each is printed to compare with the
shipped one.
"""

from __future__ import annotations

import argparse
import hashlib
import sys
import time
from pathlib import Path

from handcap.occlusion.augment import SUBJECT_AUGMENTATION
from handcap.occlusion.data import synthetic_hand_takes
from handcap.occlusion.model import SHIPPED_MODELS
from handcap.occlusion.train import train_occlusion_model

SUBJECTS = 6
SECONDS_PER_MOTION = 6.0
EPOCHS = 40
SEED = 0
WEIGHTS = Path(__file__).parent / "weights"


def build(layout: str, out: Path, *, subjects: int = SUBJECTS, epochs: int = EPOCHS, seed: int = SEED) -> str:
    """Train and write one shipped model; returns its SHA-256."""
    start = time.perf_counter()
    takes = synthetic_hand_takes(layout, subjects=subjects, seconds_per_motion=SECONDS_PER_MOTION, seed=seed)
    frames = sum(len(t.positions) for t in takes)
    print(f"{layout}: {len(takes)} synthetic takes, {frames} frames ({time.perf_counter() - start:.0f} s)", flush=True)

    def progress(stage, epoch, loss):
        if epoch % 10 == 9:
            print(f"  {stage}: epoch {epoch + 1}, loss {loss:.4f}", flush=True)

    model = train_occlusion_model(takes, layout, seed=seed, epochs=epochs, regressor_epochs=epochs,
                                  augmentation=SUBJECT_AUGMENTATION, progress=progress)
    model.info["source"] = f"python -m handcap.occlusion.shipped (subjects={subjects}, seed={seed})"
    model.save(out)
    digest = hashlib.sha256(out.read_bytes()).hexdigest()
    print(f"{out}: {out.stat().st_size // 1024} kB, sha256 {digest}, {time.perf_counter() - start:.0f} s", flush=True)
    return digest


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="python -m handcap.occlusion.shipped", description=__doc__.splitlines()[0])
    parser.add_argument("--layout", action="append", choices=SHIPPED_MODELS, help="only this layout (repeatable)")
    parser.add_argument("--out", type=Path, default=WEIGHTS, help="folder for the .npz files (default: the package)")
    args = parser.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    for layout in args.layout or SHIPPED_MODELS:
        build(layout, args.out / f"{layout}.npz")
    return 0


if __name__ == "__main__":
    sys.exit(main())
