"""How the shipped occlusion models are made: :func:`build` (run by ``make occlusion-weights``, that is
``python tools/occlusion_weights.py``).

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

import hashlib
import time
from pathlib import Path

from handcap.occlusion.augment import SUBJECT_AUGMENTATION
from handcap.occlusion.data import synthetic_hand_takes
from handcap.occlusion.train import train_occlusion_model

SUBJECTS = 6
SECONDS_PER_MOTION = 6.0
EPOCHS = 40
SEED = 0
WEIGHTS = Path(__file__).parent / "weights"


def build(layout: str, out: Path, *, subjects: int = SUBJECTS, epochs: int = EPOCHS, seed: int = SEED) -> str:
    """Train and write one shipped model; returns its SHA-256.

    Prints progress (takes, every tenth epoch, the file's size and digest) to standard output.

    Parameters
    ----------
    layout : str
        A shipped layout name.
    out : Path
        The model ``.npz`` to write.
    subjects : int
        Synthetic subjects; each does every motion of ``TRAIN_MOTIONS`` for
        :data:`SECONDS_PER_MOTION` seconds.
    epochs : int
        Training epochs of the marker predictor and of the joint regressor.
    seed : int
        Seeds the synthetic takes and the training.

    Returns
    -------
    str
        SHA-256 of the file written, hexadecimal.
    """
    start = time.perf_counter()
    takes = synthetic_hand_takes(layout, subjects=subjects, seconds_per_motion=SECONDS_PER_MOTION, seed=seed)
    frames = sum(len(t.positions) for t in takes)
    print(f"{layout}: {len(takes)} synthetic takes, {frames} frames ({time.perf_counter() - start:.0f} s)", flush=True)

    def progress(stage, epoch, loss):
        if epoch % 10 == 9:
            print(f"  {stage}: epoch {epoch + 1}, loss {loss:.4f}", flush=True)

    model = train_occlusion_model(takes, layout, seed=seed, epochs=epochs, regressor_epochs=epochs,
                                  augmentation=SUBJECT_AUGMENTATION, progress=progress)
    model.info["source"] = f"handcap.occlusion.shipped.build (subjects={subjects}, seed={seed})"
    model.save(out)
    digest = hashlib.sha256(out.read_bytes()).hexdigest()
    print(f"{out}: {out.stat().st_size // 1024} kB, sha256 {digest}, {time.perf_counter() - start:.0f} s", flush=True)
    return digest
