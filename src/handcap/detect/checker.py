"""A learned check of the blocks the template's vote places: is each the square its tag names?

The vote over the template (:mod:`handcap.detect.voting`) gives a tag to every block some reading's walk
reaches. Most are right; a few are not the square they are named for: a quad with a false corner on an
occluder's edge or a finger's outline, a lone misreading no neighbour confirms, a square one over that the
walk placed through two shared corners. The hand-set rules (:mod:`handcap.detect.checks`) test one measure
at a time, each against a threshold chosen on a few rendered scenes. The checker weighs all of them at
once: a small network (or a logistic regression) over :data:`FEATURES`, fitted on the blocks the vote
names in rendered hands and photographed sheets that the networks never saw, with the least probability
to keep a block (its gate) set on cross-fitted scores where it keeps as many wrong blocks as the hand-set
rules keep of the same blocks (:func:`train_checker`). The shipped one (``checker.npz`` beside the
networks' weights; ``python -m handcap.detect.train --what checker`` remakes it) has 8 hidden units; on
held-out hand scenes it reads 2-3 points more tags right than the rules, with fewer wrong (README).
"""

from __future__ import annotations

import numpy as np
import torch
from torch import nn
from torch.nn import functional as F

from handcap.core.errors import HandcapError
from handcap.detect.blocks import candidate_quads, white_blocks
from handcap.detect.checks import corner_uses, cross_margin
from handcap.detect.evaluation import gate_for, tag_is_right
from handcap.detect.reader import BlockReader, read_blocks, tag_probability
from handcap.detect.refine import locate_corners
from handcap.detect.voting import MAJORITY, tally, unique_tags
from handcap.patterns.pattern import Pattern

#: What the checker knows of each voted block, in the order of its weights.
FEATURES = (
    "reading",  # the reader's confidence in its own reading, -log10(1 - p) (0 where it read no tag)
    "agreed",  # 1 where the reader read the voted tag and turn
    "voted",  # log10 of the reader's probability of the voted tag and turn
    "share",  # the voted (tag, turn)'s share of the block's votes
    "support",  # log10 of the voted (tag, turn)'s votes (each weighs its reading's confidence)
    "readers",  # log2(1 + readings that placed it so)
    "against",  # log2(1 + readings that placed it otherwise)
    "defect",  # the fourth corner's distance from the parallelogram of the other three, in sides
    "lone",  # corners no other voted block uses (0-4)
    "lone_corner",  # the weakest lone corner's probability, -log10(1 - p) (6 where none is lone)
    "weakest_corner",  # the weakest corner's probability, -log10(1 - p)
    "cross",  # :func:`~handcap.detect.checks.cross_margin`, clipped to -1..1.5 (1.5 where none is checked)
    "side",  # log2 of the mean side, pixels
    "sides",  # log2 of the longest side over the shortest
)
#: Probabilities are measured to this many nines (-log10(1 - p) is clipped there).
NINES = 6.0


def _nines(p) -> np.ndarray:
    """-log10(1 - p), clipped to 0..:data:`NINES`."""
    return np.clip(-np.log10(np.maximum(1.0 - np.asarray(p, dtype=np.float64), 10.0 ** -NINES)), 0.0, NINES)


def block_features(pattern: Pattern, reader: BlockReader, alphabet: str, image: np.ndarray, xy: np.ndarray,
                   corner_score: np.ndarray, quads: np.ndarray, text, rotation, score, heads=None):
    """The vote's tag of every block (no check yet: the winner of its votes, a tag two blocks hold dropped)
    and the checker's :data:`FEATURES` of each.

    Parameters
    ----------
    pattern : Pattern
    reader : BlockReader
        The reader that read the blocks (it also gives its probability of each voted tag it did not read).
    alphabet : str
        Glyphs of the printed tags.
    image : ndarray (H, W)
        Grey image.
    xy : ndarray (K, 2)
        Corners, pixels.
    corner_score : ndarray (K,)
        Corner probabilities.
    quads : ndarray (B, 4) int
        The white squares' corner indices in image order.
    text, rotation, score : ndarrays (B,)
        :func:`~handcap.detect.reader.read_blocks`'s readings of them.
    heads : tuple of ndarrays, optional
        :func:`~handcap.detect.reader.reader_heads` of the blocks in one turn, as they were read; without them the
        reader looks again at the blocks whose voted tag it did not read.

    Returns
    -------
    tags : ndarray (B,) str
        The voted tag of each block, "" where none.
    turns : ndarray (B,) int
        Index of the tag's top-left among the block's corners (-1 where none).
    features : ndarray (B, len(FEATURES))
        Zeros where no tag is voted.
    """
    quads = np.asarray(quads, dtype=int).reshape(-1, 4)
    xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
    text, rotation = np.asarray(text, dtype="<U2").reshape(-1), np.asarray(rotation, dtype=int).reshape(-1)
    score = np.asarray(score, dtype=np.float64).reshape(-1)
    n = len(quads)
    weights, counts = tally(pattern, quads, text, rotation, score, xy)
    tags, turns = np.full(n, "", dtype="<U2"), np.full(n, -1)
    share, support, readers, against = np.zeros(n), np.zeros(n), np.zeros(n), np.zeros(n)
    for b, counter in enumerate(weights):
        if not counter:
            continue
        (tag, turn), weight = counter.most_common(1)[0]
        tags[b], turns[b] = tag, turn
        share[b], support[b] = weight / max(sum(counter.values()), 1e-12), weight
        readers[b] = counts[b][(tag, turn)]
        against[b] = sum(counts[b].values()) - readers[b]
    tags, turns = unique_tags(tags, turns)
    voted = tags != ""
    features = np.zeros((n, len(FEATURES)))
    if not voted.any():
        return tags, turns, features
    agreed = voted & (text == tags) & (rotation == turns)
    probability = np.where(agreed, score, 1.0)
    other = np.flatnonzero(voted & ~agreed)
    if len(other):
        probability[other] = tag_probability(reader, image, xy[quads[other]], alphabet, tags[other], turns[other],
                                             heads=None if heads is None else tuple(h[other] for h in heads))
    _, _, uses = corner_uses(quads, tags, len(xy))
    pts = xy[quads]
    sides = np.linalg.norm(np.roll(pts, -1, axis=1) - pts, axis=2)
    side = np.maximum(sides.mean(axis=1), 1e-9)
    lone = uses[quads] <= 1
    corner = np.asarray(corner_score, dtype=np.float64)[quads]
    columns = {
        "reading": np.where(text != "", _nines(score), 0.0),
        "agreed": agreed.astype(float),
        "voted": np.log10(np.clip(probability, 1e-12, 1.0)),
        "share": share,
        "support": np.log10(np.maximum(support, 1e-3)),
        "readers": np.log2(1.0 + readers),
        "against": np.log2(1.0 + against),
        "defect": np.linalg.norm(pts[:, 0] - pts[:, 1] + pts[:, 2] - pts[:, 3], axis=1) / side,
        "lone": lone.sum(axis=1).astype(float),
        "lone_corner": _nines(np.where(lone, corner, 1.0).min(axis=1)),
        "weakest_corner": _nines(corner.min(axis=1)),
        "cross": np.clip(cross_margin(pattern, image, quads, tags, turns, xy), -1.0, 1.5),
        "side": np.log2(side),
        "sides": np.log2(sides.max(axis=1) / np.maximum(sides.min(axis=1), 1e-9)),
    }
    features[voted] = np.column_stack([columns[name] for name in FEATURES])[voted]
    return tags, turns, features


class BlockChecker(nn.Module):
    """The checker's model: a logistic regression over the standardised :data:`FEATURES`, or, with ``hidden``
    units, a network of one hidden layer.

    Parameters
    ----------
    hidden : int
        Units of the hidden layer (0: logistic regression).
    gate : float
        The least probability of a block to keep; :func:`train_checker` sets it on cross-fitted scores, and
        it is saved with the weights.
    floor : bool
        Keep the vote's own rules first (:meth:`keeps`): the voted tag and turn must hold two thirds of the
        block's votes and weigh the reader's gate (a lone reading the reader is unsure of is not trusted).
    """

    def __init__(self, hidden: int = 0, gate: float = 0.5, floor: bool = False):
        super().__init__()
        self.hidden, self.gate, self.floor = int(hidden), float(gate), bool(floor)
        n = len(FEATURES)
        self.register_buffer("mean", torch.zeros(n, dtype=torch.float64))
        self.register_buffer("scale", torch.ones(n, dtype=torch.float64))
        layers = [nn.Linear(n, hidden), nn.Tanh(), nn.Linear(hidden, 1)] if hidden else [nn.Linear(n, 1)]
        self.model = nn.Sequential(*layers).double()

    def forward(self, features: torch.Tensor) -> torch.Tensor:
        """Logits (B,) of the blocks being right, from their features (B, len(FEATURES))."""
        return self.model((features - self.mean) / self.scale)[:, 0]

    def config(self) -> dict:
        """Arguments that rebuild this checker (saved with its weights)."""
        return {"hidden": self.hidden, "gate": self.gate, "floor": self.floor}

    def floored(self, features: np.ndarray, min_support: float) -> np.ndarray:
        """The blocks (B,) the vote's own rules keep (all of them without :attr:`floor`).

        Parameters
        ----------
        features : ndarray (B, len(FEATURES))
        min_support : float
            Least weight of the voted tag and turn (the reader's gate).

        Returns
        -------
        ndarray (B,) bool
        """
        features = np.asarray(features, dtype=np.float64).reshape(-1, len(FEATURES))
        if not self.floor:
            return np.ones(len(features), bool)
        support, share = features[:, FEATURES.index("support")], features[:, FEATURES.index("share")]
        return (support >= np.log10(max(min_support, 1e-3)) - 1e-12) & (share >= MAJORITY - 1e-12)

    def keeps(self, features: np.ndarray, min_support: float) -> np.ndarray:
        """The blocks (B,) to keep: :meth:`floored`, with a probability at the gate or above.

        Parameters
        ----------
        features : ndarray (B, len(FEATURES))
        min_support : float
            Least weight of the voted tag and turn (the reader's gate).

        Returns
        -------
        ndarray (B,) bool
        """
        return self.floored(features, min_support) & (self.probability(features) >= self.gate)

    def probability(self, features: np.ndarray) -> np.ndarray:
        """The probability (B,) that each block is the square its tag names.

        Parameters
        ----------
        features : ndarray (B, len(FEATURES))
            :func:`block_features`'s.

        Returns
        -------
        ndarray (B,)
        """
        with torch.inference_mode():
            return torch.sigmoid(self(torch.as_tensor(np.asarray(features, dtype=np.float64)))).numpy()


def fit_checker(features: np.ndarray, right: np.ndarray, *, hidden: int = 0, steps: int = 300, seed: int = 0,
                decay: float = 1e-3) -> BlockChecker:
    """Fit the checker to labelled blocks: full-batch L-BFGS on the mean log-loss plus ``decay`` times the
    squared weights, deterministic for a seed.

    Parameters
    ----------
    features : ndarray (B, len(FEATURES))
    right : ndarray (B,) bool
        Whether each block is the square its voted tag names.
    hidden : int
        Hidden units (0: logistic regression).
    steps : int
        L-BFGS iterations.
    seed : int
        Seeds a hidden layer's initial weights.
    decay : float
        Weight decay.

    Returns
    -------
    BlockChecker
        Its gate still 0.5.
    """
    x = torch.as_tensor(np.asarray(features, dtype=np.float64))
    y = torch.as_tensor(np.asarray(right, dtype=np.float64))
    if x.ndim != 2 or x.shape[1] != len(FEATURES) or len(y) != len(x) or len(x) == 0:
        raise HandcapError(f"fit_checker needs (B, {len(FEATURES)}) features and B labels, B > 0")
    if y.min() == y.max():
        raise HandcapError("fit_checker needs right and wrong blocks both")
    torch.manual_seed(seed)
    checker = BlockChecker(hidden)
    checker.mean.copy_(x.mean(dim=0))
    checker.scale.copy_(x.std(dim=0).clamp_min(1e-6))
    params = list(checker.model.parameters())
    optimiser = torch.optim.LBFGS(params, max_iter=steps, history_size=20, line_search_fn="strong_wolfe")

    def closure():
        optimiser.zero_grad()
        loss = F.binary_cross_entropy_with_logits(checker(x), y)
        loss = loss + decay * sum((p ** 2).sum() for p in params if p.ndim == 2)
        loss.backward()
        return loss

    optimiser.step(closure)
    checker.eval()
    return checker


def checker_samples(detectors, scenes, match_px: float = 2.0):
    """Labelled blocks for the checker: every block the vote gives a tag in ``scenes``, right or not, and
    whether the hand-set checks keep it.

    A block is right where its tag's template corners all lie within ``match_px`` of where the scene's truth
    projects them (:func:`handcap.detect.evaluation.tag_is_right`, as the detector's scores count a tag).

    Parameters
    ----------
    detectors : sequence of Detector
        For each scene, a :class:`~handcap.detect.pipeline.Detector` with its template and no checker: its
        networks read the scene, its :meth:`~handcap.detect.pipeline.Detector.vote` gives the hand-set checks'
        verdict.
    scenes : sequence of Scene
        Rendered scenes the networks never trained on.
    match_px : float

    Returns
    -------
    features : ndarray (B, len(FEATURES))
    right : ndarray (B,) bool
    ruled : ndarray (B,) bool
        The hand-set checks keep the block, with the same tag.
    """
    features, right, ruled = [np.zeros((0, len(FEATURES)))], [np.zeros(0, bool)], [np.zeros(0, bool)]
    for detector, scene in zip(detectors, scenes):
        pattern, reader = detector.pattern, detector.reader
        xy, corner_score = locate_corners(detector.corner_net, detector.refiner, scene.image)
        quads, _ = white_blocks(scene.image, xy, candidate_quads(xy, score=corner_score))
        if not len(quads):
            continue
        text, _, rotation, score = read_blocks(reader, scene.image, xy[quads], detector.alphabet)
        tags, turns, found = block_features(pattern, reader, detector.alphabet, scene.image, xy, corner_score, quads,
                                            text, rotation, score)
        kept, _, _ = detector.vote(scene.image, xy, corner_score, quads, text, rotation, score)
        truth = scene.projected if scene.projected is not None else dict(zip(scene.corner_names, scene.corners))
        for b in np.flatnonzero(tags != ""):
            corners = xy[quads[b][(np.arange(4) + turns[b]) % 4]]
            right.append(np.array([tag_is_right(pattern, str(tags[b]), corners, truth, match_px)]))
            ruled.append(np.array([kept[b] == tags[b]]))
            features.append(found[b][None])
    return np.concatenate(features), np.concatenate(right), np.concatenate(ruled)


def gate_at_count(outcome: np.ndarray, score: np.ndarray, max_count: int) -> float:
    """The least score at which at most ``max_count`` of the readings at or above it are wrong.

    Parameters
    ----------
    outcome : ndarray (B,) int
        1 right, -1 wrong.
    score : ndarray (B,)
    max_count : int

    Returns
    -------
    float
        1.0 when no score keeps so few wrong.
    """
    outcome, score = np.asarray(outcome), np.asarray(score, dtype=np.float64)
    order = np.argsort(-score, kind="stable")
    wrong = np.cumsum(outcome[order] == -1)
    last_of_score = np.r_[score[order][1:] != score[order][:-1], True]  # cut only between different scores
    ok = np.flatnonzero((wrong <= max_count) & last_of_score)
    return float(score[order][ok[-1]]) if len(ok) else 1.0


def train_checker(folds, *, min_support: float, hidden: int = 0, floor: bool = False, max_wrong: float | None = None,
                  seed: int = 0) -> tuple[BlockChecker, str]:
    """Fit the checker on labelled blocks and set its gate by cross-fitting (deterministic for a seed).

    Each fold's blocks are scored by a checker fitted on the other folds, the gate is set on all those
    scores, and the checker returned is fitted on every fold. By default the gate keeps no more wrong blocks
    than the hand-set checks keep of the same blocks (so the checker is as safe as they are where it was
    measured, and reads what more it can); ``max_wrong`` sets a share instead. (Wrong blocks are rare: a
    gate set on one held-out part alone rests on a few of them.)

    Parameters
    ----------
    folds : sequence of (features, right, ruled)
        Two or more groups of labelled blocks (:func:`checker_samples`), each from scenes of its own.
    min_support : float
        The reader's gate (the vote's own rule, with ``floor``).
    hidden : int
        Hidden units (0: logistic regression).
    floor : bool
        Fit and gate only the blocks the vote's own rules keep (:attr:`BlockChecker.floor`).
    max_wrong : float, optional
        Share of wrong blocks allowed among those kept, over the folds' cross-fitted scores.
    seed : int

    Returns
    -------
    checker : BlockChecker
    line : str
        The cross-fitted figures: right and wrong blocks kept by the gate, and by the hand-set checks.
    """
    if len(folds) < 2:
        raise HandcapError("train_checker needs two folds of blocks or more")
    probe = BlockChecker(floor=floor)
    parts, rules_right, rules_wrong = [], 0, 0
    for features, right, ruled in folds:
        features, right, ruled = np.asarray(features, np.float64), np.asarray(right, bool), np.asarray(ruled, bool)
        rules_right, rules_wrong = rules_right + int((ruled & right).sum()), rules_wrong + int((ruled & ~right).sum())
        kept = probe.floored(features, min_support)
        parts.append((features[kept], right[kept]))
    outcome, scores = [], []
    for k, (features, right) in enumerate(parts):
        others = [part for j, part in enumerate(parts) if j != k]
        fitted = fit_checker(np.concatenate([f for f, _ in others]), np.concatenate([r for _, r in others]),
                             hidden=hidden, seed=seed)
        outcome.append(np.where(right, 1, -1))
        scores.append(fitted.probability(features))
    checker = fit_checker(np.concatenate([f for f, _ in parts]), np.concatenate([r for _, r in parts]),
                          hidden=hidden, seed=seed)
    checker.floor = floor
    outcome, scores = np.concatenate(outcome), np.concatenate(scores)
    right = outcome > 0
    if max_wrong is None:
        checker.gate = gate_at_count(outcome, scores, rules_wrong)
        how = "as many wrong blocks as the hand-set checks keep"
    else:
        checker.gate = gate_for(outcome, scores, max_wrong)
        how = f"at most {100 * max_wrong:g} % wrong"
    kept = scores >= checker.gate
    line = (f"checker: gate {checker.gate:.4f} ({how}); cross-fitted on {len(right)} blocks it keeps "
            f"{int((kept & right).sum())} right and {int((kept & ~right).sum())} wrong ones, the hand-set checks "
            f"{rules_right} and {rules_wrong}")
    return checker, line
