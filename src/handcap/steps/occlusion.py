"""Step ``train_occlusion``: the occluded-marker predictor (and joint regressor) trained on takes."""

from __future__ import annotations

import time
from dataclasses import replace

from handcap.core.errors import HandcapError
from handcap.io import check_not_input
from handcap.layouts import load_layout
from handcap.occlusion import read_take, train_occlusion_model
from handcap.occlusion.augment import NO_AUGMENTATION, SUBJECT_AUGMENTATION
from handcap.occlusion.data import synthetic_hand_takes
from handcap.occlusion.train import PAIR_SECONDS, SAMPLES_PER_EPOCH
from handcap.steps.step import Step


def train_occlusion(takes, out, *, layout: str, poses=None, seed: int = 0, epochs: int = 60,
                    samples_per_epoch: int = SAMPLES_PER_EPOCH, synthetic: int = 0, augment: bool = False,
                    speed_copies: int = 0, pair_seconds: float = PAIR_SECONDS, progress=None) -> Step:
    """Train an occlusion model (see :func:`handcap.occlusion.train_occlusion_model`) and save it.

    Parameters
    ----------
    takes : sequence of str or Path
        Labeled takes holding the layout's markers (any marker format, or handcap synth folders); may be empty
        with ``synthetic``.
    out : str or Path
        Model .npz to write.
    layout : str
        Marker layout: a shipped name or a .toml file.
    poses : sequence of str or Path, or None
        One hand motion .npz per take, to train the joint regressor.
    seed : int
        Deterministic for a seed.
    epochs : int
        Training epochs of each network.
    samples_per_epoch : int
        Knocked-out samples the marker predictor sees per epoch.
    synthetic : int
        Also train on synthetic takes of this many subjects (each doing every synthetic motion).
    augment : bool
        Augment every sample as another subject.
    speed_copies : int
        Time-warped copies of every take.
    pair_seconds : float
        Score the predictor over gaps up to this long, seconds (0: single frames, as the paper).
    progress : callable (stage: str, epoch: int, loss: float) or None
        Called after every epoch.
    """
    takes = list(takes)
    check_not_input(out, *takes, *(poses or []))
    if poses and len(poses) != len(takes):
        raise HandcapError(f"--poses needs one hand motion per take: {len(takes)} takes, {len(poses)} poses")
    if synthetic < 0 or speed_copies < 0:
        raise HandcapError("--synthetic and --speed-copies take a number >= 0")
    if epochs < 1 or samples_per_epoch < 1:
        raise HandcapError(f"--epochs and --samples-per-epoch take a number >= 1, got {epochs} and {samples_per_epoch}")
    if not takes and not synthetic:
        raise HandcapError("give takes to train on, or --synthetic SUBJECTS, or both")
    augmentation = replace(SUBJECT_AUGMENTATION if augment else NO_AUGMENTATION, copies=speed_copies)
    data = [read_take(path, poses=pose) for path, pose in zip(takes, poses or [None] * len(takes))]
    start = time.perf_counter()
    if synthetic:
        data += synthetic_hand_takes(layout, subjects=synthetic, seed=seed, side=load_layout(layout).side)
    model = train_occlusion_model(data, layout, seed=seed, epochs=epochs, regressor_epochs=epochs, progress=progress,
                                  samples_per_epoch=samples_per_epoch, augmentation=augmentation,
                                  pair_seconds=pair_seconds)
    model.save(out)
    first, _, rest = model.summary().partition("\n")
    line = f"{out}: {first}, {time.perf_counter() - start:.0f} s\n{rest}"
    return Step((line,), model.warnings, (str(out),), model)
