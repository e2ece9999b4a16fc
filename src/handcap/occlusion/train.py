"""Train an occlusion model (marker predictor, and joint regressor when poses are known) on takes.

    takes = [read_take("session1.c3d"), read_take("capture_folder/")]
    model = train_occlusion_model(takes, "glove-13", seed=0)
    model.save("glove-13-mine.npz")

This is what ``handcap train-occlusion`` runs. Training is deterministic for a
seed: same takes and settings, same weights (torch runs on one thread here).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from handcap.core.errors import HandcapError, warn
from handcap.core.files import load_npz
from handcap.io import read_markers
from handcap.layouts import MarkerLayout, load_layout
from handcap.occlusion.augment import Augmentation, NO_AUGMENTATION, finger_groups, warped_copies
from handcap.occlusion.takes import PosedTake, marker_columns
from handcap.occlusion.model import OcclusionModel
from handcap.occlusion.predictor import train_marker_predictor
from handcap.occlusion.regressor import train_joint_regressor

RIGID_WEIGHT, OTHER_WEIGHT = 1.0, 0.1
#: Longest gap the marker predictor is trained for, seconds: each sample is a frame before a gap and one up to
#: this much later, scored as the filler fills (offset-consistent training, :mod:`handcap.occlusion.predictor`).
#: Measured on the real glove (every frame of 0.5 s gaps, NN/AC, 108 synthetic takes, augmented, 40 epochs):
#: single frames 0.75, pairs up to 1 s 0.68, up to 2 s 0.68.
PAIR_SECONDS = 1.0


def registration_weights(layout, names) -> np.ndarray:
    """Registration weight per marker: the layout's rigid back-of-hand markers count ten times more.

    The rigid markers do not move with the fingers, so a frame registered mostly on
    them is the hand's own frame; the finger markers still hold it when rigid ones
    are hidden. (Measured on the real glove: the 0.1 s cells of Table 3 improve by
    about 5 % over equal weights.)

    Parameters
    ----------
    layout : MarkerLayout or None
        Its ``rigid`` markers; None weighs every marker the same.
    names : sequence of str (M,)
        The model's markers.

    Returns
    -------
    ndarray (M,)
        :data:`RIGID_WEIGHT` for rigid markers, :data:`OTHER_WEIGHT` for the others; all ones when
        fewer than 3 rigid markers are among ``names``.
    """
    rigid = set(layout.rigid) if layout is not None else set()
    if len(rigid & set(names)) < 3:
        return np.ones(len(names))
    return np.array([RIGID_WEIGHT if n in rigid else OTHER_WEIGHT for n in names])


def read_take(path, *, poses=None, rate=None) -> PosedTake:
    """A labeled take for training: a marker file, or a ``handcap synth`` capture folder (with its poses).

    Parameters
    ----------
    path : path
        Marker file (C3D, TRC, TSV, CSV, npz) or a folder holding ``markers.npz`` and ``truth.npz``.
    poses : path, optional
        A hand motion ``.npz`` (``phi``, ``global_orient``, ``transl``) for the take, e.g. from ``handcap solve``.
    """

    path = Path(path)
    truth = None
    if path.is_dir():
        if not (path / "markers.npz").is_file():
            raise HandcapError(f"{path}: a take folder needs markers.npz (as handcap synth writes it)")
        markers = read_markers(path / "markers.npz")
        if (path / "truth.npz").is_file() and poses is None:
            truth = load_npz(path / "truth.npz", required=("phi", "global_orient", "transl", "marker_names"),
                             what="synthetic truth")
    else:
        markers = read_markers(path)
    if poses is not None:
        truth = load_npz(poses, required=("phi", "global_orient", "transl"), what="hand motion")
    take = PosedTake(markers.positions, tuple(markers.names), markers.rate)
    if truth is None:
        return take
    if len(truth["phi"]) != markers.n_frames:
        raise HandcapError(f"{path}: {markers.n_frames} frames of markers but {len(truth['phi'])} of poses")
    return PosedTake(markers.positions, tuple(markers.names), markers.rate, np.asarray(truth["phi"], float),
                     np.asarray(truth["global_orient"], float), np.asarray(truth["transl"], float),
                     np.asarray(truth["betas"], float) if "betas" in truth else None, None,
                     str(truth["side"]) if "side" in truth else "right")


def _columns(take: PosedTake, names, source: str) -> np.ndarray:
    return take.positions[:, marker_columns(take.names, names, source)]


#: Knocked-out samples the marker predictor sees per epoch, by default.
SAMPLES_PER_EPOCH = 50_000


def train_occlusion_model(takes, layout, *, seed: int = 0, epochs: int = 60, regressor_epochs: int = 60,
                          samples_per_epoch: int = SAMPLES_PER_EPOCH, side: str | None = None,
                          augmentation: Augmentation | None = None, pair_seconds: float = PAIR_SECONDS,
                          progress=None) -> OcclusionModel:
    """Train the marker predictor on every take and the joint regressor on the takes with poses.

    Parameters
    ----------
    takes : sequence of PosedTake
        Labeled takes of one hand side (recorded, or synthetic from
        :func:`~handcap.occlusion.data.synthetic_hand_takes`); each must hold the
        layout's hand markers (a ``Subject:`` prefix is allowed).
    layout : str or MarkerLayout
        Which markers the model serves (its hand markers, in layout order).
    seed : int
    epochs, regressor_epochs : int
        Passes over ``samples_per_epoch`` knocked-out samples / over the posed frames.
    side : {"right", "left"}, optional
        The hand in the takes (default: the layout's side).
    augmentation : Augmentation or None
        Time-warped copies of the takes (both networks) and per-sample subject scale and
        marker placement (the marker predictor); None for the paper's training. Use
        :data:`~handcap.occlusion.augment.SUBJECT_AUGMENTATION` for a model that must serve
        subjects it never saw (it costs where the subject is the training one).
    pair_seconds : float
        The marker predictor learns how its output moves over gaps up to this long (its
        error scored with the filler's discontinuity offset); 0 for the paper's training
        on single frames.
    progress : callable (stage, epoch, loss), optional

    Returns
    -------
    OcclusionModel
        Its ``info`` says how much data it saw: takes (recorded and synthetic), subjects,
        frames, augmented copies and their frames, samples drawn, the augmentation.
        Its ``warnings`` say when that is too little to trust.
    """
    import torch

    layout = layout if isinstance(layout, MarkerLayout) else load_layout(layout)
    side = side or layout.side
    names = tuple(m.name for m in layout.hand_markers)
    takes = list(takes)
    if not takes:
        raise HandcapError("give at least one take to train on")
    columns = [_columns(t, names, f"take {i}") for i, t in enumerate(takes)]
    augmentation = augmentation or NO_AUGMENTATION
    copies = warped_copies(takes, augmentation, seed=seed)
    copy_columns = [_columns(t, names, "augmented take") for t in copies]
    positions = np.concatenate(columns + copy_columns)
    if not (np.isfinite(pair_seconds) and pair_seconds >= 0):
        raise HandcapError(f"pair_seconds must be >= 0, got {pair_seconds}")
    every = takes + copies
    pair_steps = [int(round(pair_seconds * t.rate)) for t in every]
    weights = registration_weights(layout, names)
    rigid = np.array([n in set(layout.rigid) for n in names])
    report = (lambda stage: (lambda e, loss: progress(stage, e, loss))) if progress else (lambda stage: None)
    threads = torch.get_num_threads()
    torch.set_num_threads(1)  # determinism: one summation order
    try:
        predictor = train_marker_predictor(positions, names, seed=seed, epochs=epochs, weights=weights,
                                           samples_per_epoch=samples_per_epoch, augmentation=augmentation,
                                           rigid=rigid, fingers=finger_groups(layout, names),
                                           lengths=[len(t.positions) for t in every], pair_steps=pair_steps,
                                           progress=report("markers"))
        posed = [t for t in takes + copies if t.has_poses]
        regressor = None
        if posed:
            regressor = train_joint_regressor(
                np.concatenate([_columns(t, names, "posed take") for t in posed]),
                np.concatenate([t.phi for t in posed]), np.concatenate([t.global_orient for t in posed]),
                np.concatenate([t.transl for t in posed]), names, template=predictor.template,
                weights=predictor.weights, seed=seed, epochs=regressor_epochs, progress=report("joints"))
    finally:
        torch.set_num_threads(threads)
    info = training_summary(takes, copies, augmentation)
    info.update({"seed": seed, "epochs": epochs, "regressor_epochs": regressor_epochs, "pair_seconds": pair_seconds,
                 "samples": epochs * samples_per_epoch, "posed_frames": sum(len(t.positions) for t in posed)})
    return OcclusionModel(predictor, regressor, side, layout.name, info, data_warnings(info))


#: Fewer complete training frames than this (10 s at 100 Hz) and the network has too little to learn from.
MIN_FRAMES = 1000


def training_summary(takes, copies, augmentation: Augmentation) -> dict:
    """How much data a model saw: takes, subjects, frames, augmented copies (for ``OcclusionModel.info``).

    A take's subject is its ``subject`` label; takes without one count as a subject each.

    Parameters
    ----------
    takes : sequence of PosedTake
        The training takes.
    copies : sequence of PosedTake
        Their time-warped copies.
    augmentation : Augmentation

    Returns
    -------
    dict
        ``takes``, ``recorded_takes``, ``synthetic_takes``, ``subjects``, ``frames``, ``augmented_copies``,
        ``augmented_frames`` (counts; frames are frames) and ``augmentation`` (one line of text).
    """
    labels = {t.subject if t.subject is not None else f"take {i}" for i, t in enumerate(takes)}
    synthetic = sum(t.synthetic for t in takes)
    return {"takes": len(takes), "recorded_takes": len(takes) - synthetic, "synthetic_takes": synthetic,
            "subjects": len(labels), "frames": sum(len(t.positions) for t in takes),
            "augmented_copies": len(copies), "augmented_frames": sum(len(t.positions) for t in copies),
            "augmentation": augmentation.describe()}


def data_warnings(info: dict) -> tuple[str, ...]:
    """Warnings about training data too scarce to trust (stored on the model, printed by the CLI)."""
    out = []
    frames = int(info["frames"]) + int(info["augmented_frames"])
    if frames < MIN_FRAMES:
        out.append(warn(f"the occlusion model was trained on {frames} frames (fewer than {MIN_FRAMES}): expect "
                        "poor fills; train on longer takes, or add synthetic ones (train-occlusion --synthetic)",
                        stacklevel=3))
    return tuple(out)
