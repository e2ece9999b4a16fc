"""Small fully connected networks: numpy inference, torch training.

A trained network is a list of dense layers ``(weight (n_in, n_out), bias
(n_out,))`` with ReLU between them and a linear output, stored as plain
arrays. Inference is numpy only (a few matrix products), so a VR application
that loads a model never imports torch; torch is needed only to train.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from handcap.core.errors import HandcapError


@dataclass(frozen=True)
class Mlp:
    """A ReLU multilayer perceptron with a linear output layer (numpy inference).

    Attributes
    ----------
    weights : tuple of ndarray (n_in, n_out)
    biases : tuple of ndarray (n_out,)
    """

    weights: tuple
    biases: tuple

    def __post_init__(self):
        if len(self.weights) != len(self.biases) or not self.weights:
            raise HandcapError("a network needs as many bias vectors as weight matrices, at least one")
        for i, (w, b) in enumerate(zip(self.weights, self.biases)):
            if w.ndim != 2 or b.shape != (w.shape[1],):
                raise HandcapError(f"network layer {i}: weight {w.shape} and bias {b.shape} do not fit")
            if i and w.shape[0] != self.weights[i - 1].shape[1]:
                raise HandcapError(f"network layer {i} takes {w.shape[0]} inputs, the layer before gives "
                                   f"{self.weights[i - 1].shape[1]}")
            if not (np.isfinite(w).all() and np.isfinite(b).all()):
                raise HandcapError(f"network layer {i} holds NaN or infinite weights")
        object.__setattr__(self, "_hidden", tuple(zip(self.weights[:-1], self.biases[:-1])))

    @property
    def sizes(self) -> tuple[int, ...]:
        """Widths of the layers: inputs, then each layer's outputs."""
        return (self.weights[0].shape[0],) + tuple(w.shape[1] for w in self.weights)

    def __call__(self, x: np.ndarray) -> np.ndarray:
        """Outputs (..., n_out) for inputs (..., n_in)."""
        x = np.asarray(x, dtype=self.weights[0].dtype)  # float32 weights: float32 arithmetic
        for w, b in self._hidden:
            x = x @ w
            x += b
            np.maximum(x, 0.0, out=x)
        return x @ self.weights[-1] + self.biases[-1]

    def arrays(self, prefix: str) -> dict:
        """The layers as ``{prefix}w0, {prefix}b0, ...`` (for ``np.savez``)."""
        out = {}
        for i, (w, b) in enumerate(zip(self.weights, self.biases)):
            out[f"{prefix}w{i}"] = _compact(w)
            out[f"{prefix}b{i}"] = _compact(b)
        return out

    @classmethod
    def from_arrays(cls, arrays, prefix: str) -> "Mlp":
        """The network stored by :meth:`arrays` (``{prefix}w0, {prefix}b0, ...``, read until a ``w`` is missing).

        Parameters
        ----------
        arrays : mapping of str to ndarray
            Weights (n_in, n_out) and biases (n_out,), kept in their stored precision.
        prefix : str

        Returns
        -------
        Mlp

        Raises
        ------
        HandcapError
            No layer under ``prefix``, layers that do not fit, or non-finite weights.
        """
        weights, biases = [], []
        while f"{prefix}w{len(weights)}" in arrays:
            i = len(weights)
            # Kept in the stored precision (float32 for trained networks): faster, and exact.
            weights.append(np.asarray(arrays[f"{prefix}w{i}"]))
            biases.append(np.asarray(arrays[f"{prefix}b{i}"]))
        return cls(tuple(weights), tuple(biases))


def _compact(a: np.ndarray) -> np.ndarray:
    """float32 when that loses nothing (weights trained in float32), else as is: half the file."""
    small = a.astype(np.float32)
    return small if np.array_equal(small, a) else a


def torch_mlp(sizes, dropout: float = 0.0):
    """A torch ``Sequential`` with the layout of :class:`Mlp` (dropout after hidden layers).

    Parameters
    ----------
    sizes : sequence of int
        Widths: inputs, hidden layers, outputs (ReLU after each hidden layer, the last linear).
    dropout : float
        Dropout probability after each hidden ReLU; 0 adds none.

    Returns
    -------
    torch.nn.Sequential
        Freshly initialised, float32.
    """
    import torch

    layers = []
    for i in range(len(sizes) - 1):
        layers.append(torch.nn.Linear(sizes[i], sizes[i + 1]))
        if i < len(sizes) - 2:
            layers.append(torch.nn.ReLU())
            if dropout > 0:
                layers.append(torch.nn.Dropout(dropout))
    return torch.nn.Sequential(*layers)


def mlp_from_torch(module) -> Mlp:
    """The numpy :class:`Mlp` of a trained torch ``Sequential`` from :func:`torch_mlp`."""
    import torch

    linear = [m for m in module if isinstance(m, torch.nn.Linear)]
    return Mlp(tuple(m.weight.detach().numpy().T.copy() for m in linear),
               tuple(m.bias.detach().numpy().copy() for m in linear))


def weighted_mse(module, batch):
    """Weighted mean squared error of ``module`` on a batch ``(inputs, targets, weights)`` of float32 tensors.

    ``weights`` multiplies the squared error element by element (zero where there is no target).

    Parameters
    ----------
    module : torch.nn.Module
    batch : (Tensor (B, n_in), Tensor (B, n_out), Tensor (B, n_out))
        Inputs, targets and weights.

    Returns
    -------
    Tensor ()
        Sum of weighted squared errors over the sum of the weights (at least 1), in the targets'
        unit squared.
    """
    inputs, targets, weights = batch
    return ((module(inputs) - targets) ** 2 * weights).sum() / weights.sum().clamp(min=1.0)


def train_network(module, make_batches, *, epochs: int, seed: int, lr: float = 1e-3, patience: int = 5,
                  validate=None, progress=None, loss=weighted_mse) -> list[float]:
    """Train with Adam, halving the learning rate on plateaus (section 3.3).

    Parameters
    ----------
    module : torch.nn.Module
    make_batches : callable (epoch, numpy Generator) -> iterable of batches
        Each a tuple of float32 tensors whose first has one row per sample, as ``loss`` takes it.
    epochs : int
    seed : int
        Seeds torch and the batch generator: training is deterministic for a seed.
    lr : float
        Initial learning rate (the paper's 1e-3).
    patience : int
        Epochs without improvement before the learning rate is halved (the paper's 5).
    validate : callable (module) -> float, optional
        Validation loss per epoch; the training loss is used when omitted.
    progress : callable (epoch, loss) -> None, optional
    loss : callable (module, batch) -> scalar tensor
        Default :func:`weighted_mse` (the paper's loss).

    Returns
    -------
    losses : list of float
        The loss that drove the schedule, per epoch.
    """
    import torch

    torch.manual_seed(seed)
    rng = np.random.default_rng(seed)
    optimiser = torch.optim.Adam(module.parameters(), lr=lr)
    schedule = torch.optim.lr_scheduler.ReduceLROnPlateau(optimiser, factor=0.5, patience=patience)
    losses = []
    for epoch in range(epochs):
        module.train()
        total, count = 0.0, 0
        for batch in make_batches(epoch, rng):
            optimiser.zero_grad()
            value = loss(module, batch)
            value.backward()
            optimiser.step()
            total += float(value.detach()) * len(batch[0])
            count += len(batch[0])
        module.eval()
        with torch.no_grad():
            value = validate(module) if validate is not None else total / max(count, 1)
        schedule.step(value)
        losses.append(value)
        if progress is not None:
            progress(epoch, value)
    return losses
