"""Make a labeling test from any labeled take: strip labels, shuffle, add ghosts and dropouts.

The unlabeled result is a :class:`MarkerSequence` whose columns (``point0``,
``point1``, ...) mean nothing: in every frame the surviving markers and the
ghosts are shuffled into the first slots. The truth is the labeled take with
the same dropouts (so a gap the labeler reports there is correct).

:func:`move_rigid_set` makes a take of "another day" from a labeled one: the
back-of-hand markers put on again elsewhere relative to the fingers (issue 14).
"""

from __future__ import annotations

import numpy as np

from handcap.core.errors import HandcapError
from handcap.core.markers import MarkerSequence
from handcap.objects.rigid import canonical_from_markers, kabsch
from handcap.synth.faults import burst_dropouts, ghost_markers


def corrupt(markers: MarkerSequence, *, ghost_rate: float = 2.0, dropout: float = 0.05, seed: int = 0,
            names=None, ghost_distance=(0.005, 0.025), ghost_frames=(1, 10),
            dropout_burst: float = 1.0) -> tuple[MarkerSequence, MarkerSequence]:
    """Unlabeled points and their truth from a labeled take.

    Parameters
    ----------
    markers : MarkerSequence
        A labeled take, metres.
    ghost_rate : float
        New ghost markers per second. Each follows a random visible marker at
        a fixed offset of ``ghost_distance`` metres for ``ghost_frames`` frames,
        like wrong camera correspondences near the hand.
    dropout : float
        Extra fraction of marker samples removed, 0 <= dropout < 1.
    seed : int
    names : sequence of str, optional
        Markers to keep (default all).
    dropout_burst : float
        Mean length of a dropout in frames (1: independent samples).

    Returns
    -------
    unlabeled : MarkerSequence
        Columns ``point0..`` with the points of each frame in random order, NaN after them.
    truth : MarkerSequence
        The kept markers, labeled, with the dropouts applied.
    """
    if not (np.isfinite(ghost_rate) and ghost_rate >= 0):
        raise HandcapError(f"ghost rate must be >= 0, got {ghost_rate}")
    if not (0.0 <= dropout < 1.0):
        raise HandcapError(f"dropout must be a fraction from 0 up to (not including) 1, got {dropout}")
    truth = markers if names is None else markers.select(list(names))
    rng = np.random.default_rng(seed)
    positions = truth.positions.copy()
    dropped = burst_dropouts(rng, positions.shape[:2], dropout, dropout_burst)
    positions[dropped] = np.nan
    ghosts, _ = ghost_markers(rng, positions, ghost_rate / truth.rate, distance=ghost_distance, length=ghost_frames)
    everything = np.concatenate([positions, ghosts], axis=1)
    present = ~np.isnan(everything[..., 0])
    width = int(present.sum(axis=1).max(initial=0))
    out = np.full((truth.n_frames, max(width, 1), 3), np.nan)
    for t in range(truth.n_frames):
        pts = everything[t, present[t]]
        out[t, :len(pts)] = pts[rng.permutation(len(pts))]
    unlabeled = MarkerSequence(out, [f"point{i}" for i in range(out.shape[1])], truth.rate)
    return unlabeled, MarkerSequence(positions, truth.names, truth.rate)


def move_rigid_set(markers: MarkerSequence, names, rotation, shift, *, scale: float = 1.0) -> MarkerSequence:
    """The take with its rigid marker set put on again elsewhere, as on another day.

    Each frame's rigid set is fitted to its mean shape (Kabsch); in that set's own
    frame the mean shape is turned by ``rotation`` about its centre, scaled by
    ``scale`` and moved by ``shift``, and each marker's own deviation (noise,
    skin motion) is kept. The other markers stay where they were. Frames without
    the whole set lose it (NaN).

    Parameters
    ----------
    markers : MarkerSequence
        A labeled take, metres.
    names : sequence of str
        The rigid set (three or more markers of ``markers``).
    rotation : ndarray (3, 3)
        Turn of the set in its own frame.
    shift : ndarray (3,)
        Move of the set in its own frame, metres.
    scale : float
        Size of the set relative to now (1.08: distances 8 % longer).

    Returns
    -------
    MarkerSequence
        A new take (the input is not changed).
    """
    idx = [markers.index(n) for n in names]
    if len(set(idx)) < 3:
        raise HandcapError(f"a rigid set needs 3 or more markers, got {list(names)}")
    rotation = np.asarray(rotation, dtype=np.float64)
    shift = np.asarray(shift, dtype=np.float64)
    if rotation.shape != (3, 3) or shift.shape != (3,) or not (np.isfinite(scale) and scale > 0):
        raise HandcapError("move_rigid_set needs a (3, 3) rotation, a (3,) shift and a positive scale")
    rigid = markers.positions[:, idx]
    canon = canonical_from_markers(rigid)
    whole = ~np.isnan(rigid[..., 0]).any(axis=1)
    rot, trans = kabsch(np.broadcast_to(canon, rigid[whole].shape), rigid[whole])  # rigid ~ rot @ canon + trans
    local = np.einsum("tji,tmj->tmi", rot, rigid[whole] - trans[:, None])
    moved = scale * canon @ rotation.T + shift
    out = np.full(rigid.shape, np.nan)
    out[whole] = np.einsum("tij,tmj->tmi", rot, local - canon + moved) + trans[:, None]
    positions = markers.positions.copy()
    positions[:, idx] = out
    return MarkerSequence(positions, markers.names, markers.rate)
