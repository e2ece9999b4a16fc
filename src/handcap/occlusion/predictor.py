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

**Offset-consistent training** (``pair_steps``, the default of
:func:`~handcap.occlusion.train.train_occlusion_model`): the filler never uses
the network's output as it is, but plus the offset that cancels the
discontinuity on the first frame of a gap. What must be right is therefore how
the output moves between the frame before a gap and a frame in it, and that is
what a sample scores (:func:`offset_consistent_loss`): two frames of one take up
to a second apart, the same markers hidden in both, the same subject
augmentation. A network trained on single frames learns where markers sit on the
subjects it saw, which on a new subject is partly wrong and then cancelled by
the offset anyway. Measured on the real glove with synthetic-only training
(every frame of 0.5 s gaps, NN/AC): 0.76 single frames, 0.70 pairs; trained on
the glove's own first 60 %: 0.57 and 0.52.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from handcap.core.errors import HandcapError
from handcap.occlusion.augment import augment_frames
from handcap.occlusion.network import Mlp, mlp_from_torch, torch_mlp, train_network, weighted_mse
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
        """Number of markers M."""
        return len(self.names)

    def inputs(self, local, visible) -> np.ndarray:
        """Network inputs (..., 3M [+ M]) from registered positions (..., M, 3) and visibility (..., M).

        Parameters
        ----------
        local : ndarray (..., M, 3)
            Positions in the template frame, metres (anything where hidden, NaN included).
        visible : ndarray (..., M) bool

        Returns
        -------
        ndarray (..., 3M) or (..., 4M)
            Standardised coordinates (no unit), 0 for hidden markers; then, with ``mask_input``,
            the visibility as 0.0 / 1.0.
        """
        x = np.where(visible[..., None], (local - self.mean) / self.scale, 0.0)
        x = x.reshape(x.shape[:-2] + (-1,))
        if self.mask_input:
            x = np.concatenate([x, visible.astype(np.float64)], axis=-1)
        return x

    def predict_local(self, local, visible) -> np.ndarray:
        """Every marker (..., M, 3) in the template frame from the visible ones (NaN allowed where hidden).

        Parameters
        ----------
        local : ndarray (..., M, 3)
            Registered positions, metres.
        visible : ndarray (..., M) bool

        Returns
        -------
        ndarray (..., M, 3)
            The network's output for every marker (visible ones included), metres, template frame.
        """
        out = self.net(self.inputs(local, visible))
        return out.reshape(out.shape[:-1] + (-1, 3)) * self.scale + self.mean

    def register(self, positions, visible):
        """(rotation, centre, template_centre) of each frame; see :mod:`handcap.occlusion.register`.

        Parameters
        ----------
        positions : ndarray (..., M, 3)
            Metres; ignored where not visible.
        visible : ndarray (..., M) bool

        Returns
        -------
        rotation : ndarray (..., 3, 3)
        centre : ndarray (..., 3)
            Metres.
        template_centre : ndarray (..., 3)
            Metres. All NaN-free only on frames with 3 or more visible markers (see
            :func:`~handcap.occlusion.register.fit_registration`).
        """
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
        """The predictor as ``.npz`` entries.

        Returns
        -------
        dict of str to ndarray
            ``ae_names`` (M,), ``ae_template`` (M, 3) metres, ``ae_weights`` (M,), ``ae_mean`` and
            ``ae_scale`` (M, 3) metres, ``ae_mask_input`` and the network's ``ae_w<i>``, ``ae_b<i>``.
        """
        return {"ae_names": np.array(self.names), "ae_template": self.template, "ae_weights": self.weights,
                "ae_mean": self.mean, "ae_scale": self.scale, "ae_mask_input": np.array(self.mask_input),
                **self.net.arrays("ae_")}

    @classmethod
    def from_arrays(cls, arrays) -> "MarkerPredictor":
        """The predictor stored by :meth:`arrays`.

        Parameters
        ----------
        arrays : mapping of str to ndarray
            The ``ae_*`` entries.

        Returns
        -------
        MarkerPredictor
        """
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
                           fingers=None, lengths=None, pair_steps=0, progress=None) -> MarkerPredictor:
    """Train a marker predictor on labeled frames.

    Parameters
    ----------
    positions : ndarray (T, M, 3)
        Training frames, metres, NaN where missing (a marker missing in a frame
        is neither an input nor a target there). Several takes one after the other
        (``lengths``).
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
    lengths : sequence of int, optional
        Frames of each take in ``positions`` (default: one take).
    pair_steps : int or sequence of int
        0: the paper's training, one frame per sample. Otherwise each sample is a
        frame before a gap and a frame up to this many frames later (per take, or one
        value for all), and the loss is on the prediction as the filler uses it: with
        the discontinuity offset of the first frame added (:func:`offset_consistent_loss`).
    progress : callable (epoch, loss), optional

    Returns
    -------
    MarkerPredictor
    """
    import torch

    positions = np.asarray(positions, dtype=np.float64)
    t, m = positions.shape[:2]
    lengths = np.array([t] if lengths is None else lengths, dtype=np.int64)
    if lengths.sum() != t or (lengths < 1).any():
        raise HandcapError(f"take lengths {lengths.tolist()} do not add up to the {t} training frames")
    steps = np.broadcast_to(np.asarray(pair_steps, dtype=np.int64), lengths.shape).copy()
    steps = np.minimum(steps, lengths - 1)
    pairs = bool(np.any(np.asarray(pair_steps) > 0))
    visible = ~np.isnan(positions).any(axis=-1)
    usable = np.count_nonzero(visible, axis=1) >= MIN_VISIBLE + 1
    if usable.sum() < 10:
        raise HandcapError(f"only {usable.sum()} training frames have {MIN_VISIBLE + 1} or more markers; "
                           "a marker predictor needs at least 10")
    never = [str(names[i]) for i in np.flatnonzero(~visible[usable].any(axis=0))]
    if never:
        raise HandcapError(f"marker(s) {', '.join(never)} never seen in the training frames")
    weights = np.ones(m) if weights is None else np.asarray(weights, dtype=np.float64)
    template = (canonical_from_markers(positions[usable]) if template is None
                else np.asarray(template, dtype=np.float64))
    pose = fit_registration(positions, visible & usable[:, None], template, weights)
    local = apply_registration(positions, *pose)  # NaN in frames that cannot be registered
    mean = np.nanmean(local[usable], axis=0)
    scale = np.maximum(np.nanstd(local[usable], axis=0), 0.005)
    sizes = (3 * m + (m if mask_input else 0),) + tuple(hidden) + (3 * m,)
    torch.manual_seed(seed)
    module = torch_mlp(sizes)
    predictor = MarkerPredictor(tuple(names), template, weights, mean, scale, mlp_from_torch(module), mask_input)
    augment = augmentation is not None and augmentation.per_sample
    # Augmented in the hand's frame, where scale and placement have a meaning.
    clean = np.where(visible[..., None], local if augment else positions, 0.0)
    rigid = np.zeros(m, bool) if rigid is None else np.asarray(rigid, dtype=bool)
    centre = template.mean(axis=0)
    frame_ok = usable & ~np.isnan(pose[1][:, 0])

    def draw(rng):
        """Frame indices (S, F) of the samples: one frame, or (before, later) pairs within a take."""
        if not pairs:
            return np.flatnonzero(frame_ok)[rng.integers(0, frame_ok.sum(), samples_per_epoch)][:, None]
        picked = draw_pairs(lengths, steps, samples_per_epoch, rng)
        return picked[frame_ok[picked].all(axis=1)]

    def make_batches(epoch, rng):
        pick = draw(rng)
        n = len(pick)
        frames, seen = clean[pick], visible[pick].all(axis=1)  # (n, F, M, 3); markers seen in every frame
        if augment:
            frames = augment_frames(frames, centre, rigid, augmentation, rng, fingers)
        if jitter > 0:
            frames = frames + rng.normal(0.0, jitter, frames.shape)
        hidden_now = knock_out(seen, rng)
        shown = seen & ~hidden_now
        x, y = [], []
        for f in range(frames.shape[1]):
            sample_local = apply_registration(frames[:, f], *fit_registration(frames[:, f], shown, template, weights))
            x.append(predictor.inputs(sample_local, shown))
            y.append(np.where(seen[..., None], (sample_local - mean) / scale, 0.0).reshape(n, -1))
        # The error that matters is on the hidden markers; the visible ones keep the code honest.
        w = np.repeat(np.where(hidden_now, 1.0, np.where(seen, 0.1, 0.0)), 3, axis=1)
        arrays = (x[-1], y[-1], w) if not pairs else (x[0], x[1], y[0], y[1], w,
                                                      np.repeat(hidden_now, 3, axis=1).astype(np.float64))
        tensors = [torch.from_numpy(a.astype(np.float32)) for a in arrays]
        for start in range(0, n, batch_size):
            yield tuple(a[start:start + batch_size] for a in tensors)

    train_network(module, make_batches, epochs=epochs, seed=seed, progress=progress,
                  loss=offset_consistent_loss if pairs else weighted_mse)
    return MarkerPredictor(tuple(names), template, weights, mean, scale, mlp_from_torch(module), mask_input)


def draw_pairs(lengths, steps, n: int, rng) -> np.ndarray:
    """Random (before, later) frame pairs of takes laid end to end, never spanning two takes.

    Parameters
    ----------
    lengths : ndarray (K,) int
        Frames of each take.
    steps : ndarray (K,) int
        Largest distance of a pair in each take (at most its length - 1).
    n : int
    rng : numpy Generator

    Returns
    -------
    ndarray (n, 2) int
        Indices into the frames of all takes; frames uniform over the takes, distances
        log-uniform from 1 to the take's ``steps`` (short gaps are the common ones, long ones
        still seen), 0 where ``steps`` is 0.
    """
    first = np.concatenate([[0], np.cumsum(lengths)[:-1]])
    take = rng.choice(len(lengths), n, p=lengths / lengths.sum())
    gap = np.floor(np.exp(rng.uniform(0.0, np.log(steps[take] + 1.0)))).astype(np.int64)
    gap = np.minimum(gap, steps[take])
    later = first[take] + gap + (rng.random(n) * (lengths[take] - gap)).astype(np.int64)
    return np.stack([later - gap, later], axis=1)


#: Weight of the plain error of every output in :func:`offset_consistent_loss` (it keeps the raw predictions
#: right for a marker hidden from the start of a take, where no offset exists).
ABSOLUTE_WEIGHT = 0.1


def offset_consistent_loss(module, batch):
    """Error of the hidden markers as the filler predicts them, over a gap (section 3.2.2 and beyond).

    The filler adds to every prediction in a gap the offset that cancels the
    discontinuity on its first frame: the truth there minus the network's output
    there. So what matters is how the output *moves* from the frame before the gap
    to a frame in it, not where it sits; a network trained only on single frames
    learns where markers sit on the subjects it saw.
    Plus :data:`ABSOLUTE_WEIGHT` times the paper's weighted error on the later frame.

    Parameters
    ----------
    module : torch.nn.Module
    batch : tuple of 6 float32 Tensors
        ``(inputs before, inputs later, targets before, targets later, weights, hidden)``: inputs
        (B, n_in), the others (B, 3M), standardised (no unit); ``hidden`` is 1 on the coordinates
        of the hidden markers.

    Returns
    -------
    Tensor ()
        Mean squared standardised error over the hidden coordinates, plus the weighted term.
    """
    x0, x1, y0, y1, w, hidden = batch
    out0, out1 = module(x0), module(x1)
    filled = out1 + (y0 - out0) * hidden
    gap = ((filled - y1) ** 2 * hidden).sum() / hidden.sum().clamp(min=1.0)
    return gap + ABSOLUTE_WEIGHT * ((out1 - y1) ** 2 * w).sum() / w.sum().clamp(min=1.0)
