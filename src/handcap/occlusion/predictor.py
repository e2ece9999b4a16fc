"""The marker predictor (section 3.2.2): an autoencoder that fills in occluded markers.

Registration of the visible markers to the hand template (Kabsch), a fully
connected autoencoder ``3M -> 200 -> 150 -> 200 -> 3M`` (ReLU) whose inputs for
occluded markers are zero, and de-registration of its outputs. It is trained
on complete frames with 1-4 markers knocked out at random after registration,
the paper's input dropout.

Beyond the paper: the registration of a training sample uses only the markers
left after the knock-out, exactly as at run time (the paper registers before
knocking out), and the network also gets the visibility of each marker as an
input (``mask_input``), so a marker that sits at its mean place is not mistaken
for a hidden one.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from handcap.core.errors import HandcapError
from handcap.occlusion.augment import augment_frames
from handcap.occlusion.network import Mlp, mlp_from_torch, torch_mlp, train_network
from handcap.objects.rigid import canonical_from_markers
from handcap.occlusion.register import apply_registration, fit_registration, undo_registration

HIDDEN = (200, 150, 200)
# How many markers a training sample loses (1-4), after the paper's Fig. 13: most occlusions are single.
DROP_PROBABILITY = (0.4, 0.3, 0.2, 0.1)
MIN_VISIBLE = 3


@dataclass(frozen=True, eq=False)
class MarkerPredictor:
    """A trained marker predictor.

    Attributes
    ----------
    names : tuple of str (M,)
    template : ndarray (M, 3)
        Mean shape of the hand's markers, metres (the registration target).
    weights : ndarray (M,)
        Weight of each marker in the registration.
    mean, scale : ndarray (M, 3)
        Standardisation of the registered positions, metres.
    net : Mlp
    mask_input : bool
        The network takes the visibility of each marker as M extra inputs.
    """

    names: tuple
    template: np.ndarray
    weights: np.ndarray
    mean: np.ndarray
    scale: np.ndarray
    net: Mlp
    mask_input: bool = True

    @property
    def n_markers(self) -> int:
        return len(self.names)

    def inputs(self, local, visible) -> np.ndarray:
        """Network inputs (..., 3M [+ M]) from registered positions (..., M, 3) and visibility (..., M)."""
        x = np.where(visible[..., None], (local - self.mean) / self.scale, 0.0)
        x = x.reshape(x.shape[:-2] + (-1,))
        if self.mask_input:
            x = np.concatenate([x, visible.astype(np.float64)], axis=-1)
        return x

    def predict_local(self, local, visible) -> np.ndarray:
        """Every marker (..., M, 3) in the template frame from the visible ones (NaN allowed where hidden)."""
        out = self.net(self.inputs(local, visible))
        return out.reshape(out.shape[:-1] + (-1, 3)) * self.scale + self.mean

    def register(self, positions, visible):
        """(rotation, centre, template_centre) of each frame; see :mod:`handcap.occlusion.register`."""
        return fit_registration(positions, visible, self.template, self.weights)

    def predict(self, positions, visible=None) -> np.ndarray:
        """Every marker (..., M, 3) in the world from the visible ones, metres.

        Parameters
        ----------
        positions : ndarray (..., M, 3)
            Metres, NaN where missing.
        visible : ndarray (..., M) bool, optional
            Default: not NaN. Frames with fewer than 3 visible markers give NaN.
        """
        positions = np.asarray(positions, dtype=np.float64)
        if visible is None:
            visible = ~np.isnan(positions).any(axis=-1)
        pose = self.register(positions, visible)
        local = apply_registration(positions, *pose)
        return undo_registration(self.predict_local(local, visible), *pose)

    def arrays(self) -> dict:
        return {"ae_names": np.array(self.names), "ae_template": self.template, "ae_weights": self.weights,
                "ae_mean": self.mean, "ae_scale": self.scale, "ae_mask_input": np.array(self.mask_input),
                **self.net.arrays("ae_")}

    @classmethod
    def from_arrays(cls, arrays) -> "MarkerPredictor":
        return cls(tuple(str(n) for n in arrays["ae_names"]), np.asarray(arrays["ae_template"], float),
                   np.asarray(arrays["ae_weights"], float), np.asarray(arrays["ae_mean"], float),
                   np.asarray(arrays["ae_scale"], float), Mlp.from_arrays(arrays, "ae_"),
                   bool(arrays["ae_mask_input"]))


def knock_out(visible, rng, probability=DROP_PROBABILITY) -> np.ndarray:
    """Hide 1..len(probability) random visible markers of every frame, keeping at least 3 visible.

    Parameters
    ----------
    visible : ndarray (N, M) bool
    rng : numpy Generator
    probability : sequence of float
        Probability of hiding 1, 2, ... markers.

    Returns
    -------
    hidden : ndarray (N, M) bool
        The markers knocked out (a subset of ``visible``).
    """
    n, m = visible.shape
    p = np.asarray(probability, dtype=np.float64)
    k = rng.choice(np.arange(1, len(p) + 1), size=n, p=p / p.sum())
    k = np.minimum(k, np.count_nonzero(visible, axis=1) - MIN_VISIBLE)
    keys = np.where(visible, rng.random((n, m)), np.inf)
    rank = np.argsort(np.argsort(keys, axis=1), axis=1)
    return visible & (rank < k[:, None])


def train_marker_predictor(positions, names, *, seed: int = 0, epochs: int = 60, samples_per_epoch: int = 50_000,
                           batch_size: int = 256, hidden=HIDDEN, weights=None, template=None,
                           mask_input: bool = True, jitter: float = 0.0, augmentation=None, rigid=None,
                           fingers=None, progress=None) -> MarkerPredictor:
    """Train a marker predictor on labeled frames.

    Parameters
    ----------
    positions : ndarray (T, M, 3)
        Training frames, metres, NaN where missing (a marker missing in a frame
        is neither an input nor a target there).
    names : sequence of str (M,)
    seed : int
        Training is deterministic for a seed (same data, same weights).
    epochs, samples_per_epoch, batch_size : int
    hidden : tuple of int
        Hidden layer sizes (the paper's 200, 150, 200).
    weights : ndarray (M,), optional
        Registration weight of each marker (default 1).
    template : ndarray (M, 3), optional
        Registration target (default: the mean shape of the training frames,
        :func:`handcap.objects.rigid.canonical_from_markers`).
    mask_input : bool
        Give the network the visibility of each marker as well.
    jitter : float
        Standard deviation of noise added to the inputs during training, metres.
    augmentation : Augmentation, optional
        Per-sample augmentation (:func:`handcap.occlusion.augment.augment_frames`): each
        training sample becomes another subject's hand with another marker placement.
    rigid : ndarray (M,) bool, optional
        The layout's rigid set (for the augmentation's rigid-set placement).
    fingers : ndarray (M,) int, optional
        Finger of each marker, -1 for none (for the augmentation's finger rest pose).
    progress : callable (epoch, loss), optional

    Returns
    -------
    MarkerPredictor
    """
    import torch

    positions = np.asarray(positions, dtype=np.float64)
    t, m = positions.shape[:2]
    visible = ~np.isnan(positions).any(axis=-1)
    usable = np.count_nonzero(visible, axis=1) >= MIN_VISIBLE + 1
    if usable.sum() < 10:
        raise HandcapError(f"only {usable.sum()} training frames have {MIN_VISIBLE + 1} or more markers; "
                           "a marker predictor needs at least 10")
    positions, visible = positions[usable], visible[usable]
    never = [str(names[i]) for i in np.flatnonzero(~visible.any(axis=0))]
    if never:
        raise HandcapError(f"marker(s) {', '.join(never)} never seen in the training frames")
    weights = np.ones(m) if weights is None else np.asarray(weights, dtype=np.float64)
    template = canonical_from_markers(positions) if template is None else np.asarray(template, dtype=np.float64)
    pose = fit_registration(positions, visible, template, weights)
    local = apply_registration(positions, *pose)
    mean = np.nanmean(local, axis=0)
    scale = np.maximum(np.nanstd(local, axis=0), 0.005)
    sizes = (3 * m + (m if mask_input else 0),) + tuple(hidden) + (3 * m,)
    torch.manual_seed(seed)
    module = torch_mlp(sizes)
    predictor = MarkerPredictor(tuple(names), template, weights, mean, scale, mlp_from_torch(module), mask_input)
    clean = np.where(visible[..., None], positions, 0.0)
    augment = augmentation is not None and augmentation.per_sample
    if augment:  # augmented in the hand's frame, where scale and placement have a meaning
        clean = np.where(visible[..., None], local, 0.0)
        rigid = np.zeros(m, bool) if rigid is None else np.asarray(rigid, dtype=bool)
        centre = template.mean(axis=0)

    def make_batches(epoch, rng):
        pick = rng.integers(0, len(clean), samples_per_epoch)
        frames, seen = clean[pick], visible[pick]
        if augment:
            frames = augment_frames(frames, centre, rigid, augmentation, rng, fingers)
        if jitter > 0:
            frames = frames + rng.normal(0.0, jitter, frames.shape)
        hidden_now = knock_out(seen, rng)
        shown = seen & ~hidden_now
        sample_pose = fit_registration(frames, shown, template, weights)
        sample_local = apply_registration(frames, *sample_pose)
        x = predictor.inputs(sample_local, shown)
        y = np.where(seen[..., None], (sample_local - mean) / scale, 0.0).reshape(len(pick), -1)
        # The error that matters is on the hidden markers; the visible ones keep the code honest.
        w = np.repeat(np.where(hidden_now, 1.0, np.where(seen, 0.1, 0.0)), 3, axis=1)
        x, y, w = (torch.from_numpy(a.astype(np.float32)) for a in (x, y, w))
        for start in range(0, len(pick), batch_size):
            s = slice(start, start + batch_size)
            yield x[s], y[s], w[s]

    train_network(module, make_batches, epochs=epochs, seed=seed, progress=progress)
    return MarkerPredictor(tuple(names), template, weights, mean, scale, mlp_from_torch(module), mask_input)
