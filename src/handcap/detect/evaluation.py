"""How well the detector's networks do on rendered scenes with truth: corners matched, tags read.

Used by the training command (:mod:`handcap.detect.train`) to score held-out scenes, and by
``benchmarks/detect.py``.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from handcap.detect.corners import CornerNet
from handcap.detect.refine import locate_corners
from handcap.detect.reader import BlockReader, read_blocks


@dataclass(frozen=True)
class CornerScore:
    """How well corners are found, against the truth of rendered images.

    Attributes
    ----------
    recall : float
        Share of visible corners with a detection within ``match_px``.
    precision : float
        Share of detections within ``match_px`` of a visible corner.
    median_px, rms_px : float
        Error of the matched detections, pixels.
    found, truth : int
        Detections and visible corners.
    """

    recall: float
    precision: float
    median_px: float
    rms_px: float
    found: int
    truth: int

    def summary(self) -> str:
        """One line of the figures."""
        return (f"corners: recall {100 * self.recall:.1f} %, precision {100 * self.precision:.1f} % "
                f"(within 2 px), error median {self.median_px:.3f} px, RMS {self.rms_px:.3f} px "
                f"({self.found} found, {self.truth} visible)")


def score_corners(found: np.ndarray, truth: np.ndarray, match_px: float = 2.0) -> tuple[np.ndarray, np.ndarray]:
    """Match detections to true corners one to one (nearest first, within ``match_px``).

    Parameters
    ----------
    found : ndarray (K, 2)
    truth : ndarray (N, 2)
    match_px : float

    Returns
    -------
    pairs : ndarray (P, 2) int
        (detection, truth) index pairs.
    error : ndarray (P,)
        Pixels.
    """
    if len(found) == 0 or len(truth) == 0:
        return np.zeros((0, 2), int), np.zeros(0)
    d = np.linalg.norm(found[:, None] - truth[None], axis=-1)
    order = np.argsort(d, axis=None)
    used_f, used_t, pairs = set(), set(), []
    for flat in order:
        i, j = divmod(int(flat), d.shape[1])
        if d[i, j] > match_px:
            break
        if i in used_f or j in used_t:
            continue
        used_f.add(i)
        used_t.add(j)
        pairs.append((i, j))
    pairs = np.array(pairs, dtype=int).reshape(-1, 2)
    return pairs, d[pairs[:, 0], pairs[:, 1]]


def evaluate_corners(net: CornerNet, scenes, threshold: float | None = None, refiner=None) -> CornerScore:
    """Detect the corners of rendered ``scenes`` and score them against their truth.

    Parameters
    ----------
    net : CornerNet
    scenes : sequence of Scene
    threshold : float, optional
        Least corner probability: the refiner's when there is one (default 0.5), else the corner
        network's (default 0.3).
    refiner : CornerRefiner, optional
        Refine the corner network's candidates (:func:`~handcap.detect.refine.locate_corners`).

    Returns
    -------
    CornerScore
    """
    errors, found, truth = [], 0, 0
    for scene in scenes:
        xy, _ = locate_corners(net, refiner, scene.image, threshold)
        _, err = score_corners(xy, scene.corners)
        errors.append(err)
        found += len(xy)
        truth += len(scene.corners)
    err = np.concatenate(errors) if errors else np.zeros(0)
    matched = len(err)
    return CornerScore(matched / max(truth, 1), matched / max(found, 1),
                       float(np.median(err)) if matched else float("nan"),
                       float(np.sqrt(np.mean(err ** 2))) if matched else float("nan"), found, truth)


def reader_outcomes(net: BlockReader, scenes, alphabet: str | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Read the true blocks of ``scenes`` (their corners given in a random turn): right or not, and score.

    Parameters
    ----------
    net : BlockReader
    scenes : sequence of Scene
    alphabet : str, optional
        Glyphs to read (default: each scene's own alphabet).

    Returns
    -------
    outcome : ndarray (B,) int
        1 read right (tag and turn), -1 read wrong, 0 not read.
    score : ndarray (B,)
        The reader's confidence.
    """
    rng = np.random.default_rng(0)
    outcome, scores = [np.zeros(0, int)], [np.zeros(0)]
    for scene in scenes:
        if not len(scene.blocks):
            continue
        shifts = rng.integers(4, size=len(scene.blocks))
        quads = np.array([np.roll(b, -s, axis=0) for b, s in zip(scene.blocks, shifts)])
        text, corners, _, score = read_blocks(net, scene.image, quads, alphabet or scene.alphabet)
        ok_turn = np.abs(corners - scene.blocks).max(axis=(1, 2)) < 1e-9
        read = text != ""
        good = read & ok_turn & (text == scene.block_text)
        outcome.append(np.where(good, 1, np.where(read, -1, 0)))
        scores.append(score)
    return np.concatenate(outcome), np.concatenate(scores)


def evaluate_reader(net: BlockReader, scenes, alphabet: str | None = None, min_score: float = 0.0) -> dict:
    """Read the true blocks of ``scenes``: share right, wrong, unread (below ``min_score`` counts as unread).

    Parameters
    ----------
    net : BlockReader
    scenes : sequence of Scene
    alphabet : str, optional
        Glyphs to read (default: each scene's own alphabet).
    min_score : float
        Least confidence of a reading that counts.

    Returns
    -------
    dict
        ``right``, ``wrong``, ``unread`` (shares of the blocks), ``blocks`` (count).
    """
    outcome, score = reader_outcomes(net, scenes, alphabet)
    outcome = np.where(score >= min_score, outcome, 0)
    total = max(len(outcome), 1)
    return {"right": float((outcome == 1).sum() / total), "wrong": float((outcome == -1).sum() / total),
            "unread": float((outcome == 0).sum() / total), "blocks": len(outcome)}


def reader_gate(net: BlockReader, scenes, max_wrong: float = 0.001) -> float:
    """The least confidence at which at most ``max_wrong`` of the readings kept are wrong.

    Parameters
    ----------
    net : BlockReader
    scenes : sequence of Scene
        Validation scenes (not the training ones).
    max_wrong : float
        Share of wrong readings allowed among those kept.

    Returns
    -------
    float
        A score threshold in 0..1 (1.0 when no threshold keeps the wrong share that low).
    """
    return gate_for(*reader_outcomes(net, scenes), max_wrong=max_wrong)


def gate_for(outcome: np.ndarray, score: np.ndarray, max_wrong: float = 0.001) -> float:
    """The least score at which at most ``max_wrong`` of the readings at or above it are wrong.

    Parameters
    ----------
    outcome : ndarray (B,) int
        1 right, -1 wrong, 0 not read (:func:`reader_outcomes`).
    score : ndarray (B,)
    max_wrong : float

    Returns
    -------
    float
        1.0 when no score keeps the wrong share that low.
    """
    read = np.asarray(outcome) != 0
    outcome, score = np.asarray(outcome)[read], np.asarray(score, dtype=float)[read]
    order = np.argsort(-score, kind="stable")
    wrong = np.cumsum(outcome[order] == -1) / np.arange(1, len(order) + 1)
    # Cut only between different scores: all readings at the threshold are kept.
    last_of_score = np.r_[score[order][1:] != score[order][:-1], True]
    ok = np.flatnonzero((wrong <= max_wrong) & last_of_score)
    return float(score[order][ok[-1]]) if len(ok) else 1.0


def reader_line(score: dict, font) -> str:
    """One line of :func:`evaluate_reader` figures per alphabet, on the held-out ``font``.

    Parameters
    ----------
    score : dict
        Alphabet name -> :func:`evaluate_reader`'s dict.
    font : str or None
        The held-out font file (None: the default font).

    Returns
    -------
    str
    """
    parts = [f"{name} alphabet {100 * s['right']:.1f} % right, {100 * s['wrong']:.1f} % wrong, "
             f"{100 * s['unread']:.1f} % unread of {s['blocks']} tags" for name, s in score.items()]
    return (f"reader on a font it never saw ({Path(font).stem if font else 'default'}), readings below its "
            f"trusted confidence counted unread: " + "; ".join(parts))


@dataclass(frozen=True)
class DetectorScore:
    """How well the whole detector reads rendered scenes, against their truth.

    Attributes
    ----------
    blocks : int
        Visible tags (all four corners visible).
    read, wrong : int
        Tags the detector reported, and those of them that are not at that tag's true corners (2 px).
    right : int
        Visible tags reported at their true corners (a tag with a corner the truth calls hidden, read
        right, is neither wrong nor counted here).
    named, misnamed : int
        Corners the detector named, and those whose true position under that name is over 2 px away.
    named_right : int
        Visible corners named right.
    corners : int
        Visible corners.
    named_px : ndarray (N,)
        Distance of each corner named right (within ``match_px`` of its truth) from its true position, pixels:
        the accuracy of what the detector reports.
    """

    blocks: int
    read: int
    wrong: int
    right: int
    named: int
    misnamed: int
    named_right: int
    corners: int
    named_px: np.ndarray = field(default_factory=lambda: np.zeros(0))

    def summary(self) -> str:
        """One line of the figures."""
        return (f"tags: {100 * self.right / max(self.blocks, 1):.1f} % of {self.blocks} visible read right, "
                f"{100 * self.wrong / max(self.read, 1):.2f} % of {self.read} read wrong; corners: "
                f"{100 * self.named_right / max(self.corners, 1):.1f} % of {self.corners} visible "
                f"named, {100 * self.misnamed / max(self.named, 1):.2f} % of {self.named} named wrong")


def evaluate_detector(detector, scenes, match_px: float = 2.0, pattern=None) -> DetectorScore:
    """Run a :class:`~handcap.detect.pipeline.Detector` and score its tags and corner names against the truth.

    With a template, a tag is right where the template's corners of it lie within ``match_px`` of the truth;
    without one (tags and their corners only), where a visible tag of that text has its corners, in reading
    order, within ``match_px`` (a tag that is not visible whole counts wrong), or, given ``pattern``, as with a
    template; no corner is named then.

    Parameters
    ----------
    detector : Detector
        With the scenes' template, or without one.
    scenes : sequence of Scene
    match_px : float
        Largest distance of a right tag's corners, or a right name's corner, from the truth, pixels.
    pattern : Pattern, optional
        The printed patches, to score the tags of a detector without a template (default: the detector's).

    Returns
    -------
    DetectorScore
    """
    pattern = detector.pattern if pattern is None else pattern
    counts, named_px = np.zeros(8, int), []
    for scene in scenes:
        found = detector.image(scene.image)
        truth = scene.projected if scene.projected is not None else dict(zip(scene.corner_names, scene.corners))
        visible = set(scene.block_text)
        wrong = right = 0
        if pattern is None:  # tags and their corners only: each must be a visible tag's, in reading order
            at = dict(zip(scene.block_text, scene.blocks))
            for tag, xy in zip(found.block_text, found.block_xy):
                ok = str(tag) in at and np.linalg.norm(at[str(tag)] - xy, axis=1).max() <= match_px
                right, wrong = right + ok, wrong + (not ok)
            counts += (len(scene.blocks), len(found.block_text), wrong, right, 0, 0, 0, len(scene.corners))
            continue
        for tag, xy in zip(found.block_text, found.block_xy):
            bad = not tag_is_right(pattern, str(tag), xy, truth, match_px)
            wrong += bad
            right += not bad and str(tag) in visible
        named = [(n, xy) for n, xy in zip(found.names, found.corners) if n is not None]
        off = [np.linalg.norm(truth[n] - xy) if n in truth else np.inf for n, xy in named]
        bad = [d > match_px for d in off]
        named_px += [d for d in off if d <= match_px]
        seen = set(scene.corner_names)
        named_right = sum(1 for (n, _), b in zip(named, bad) if not b and n in seen)
        counts += (len(scene.blocks), len(found.block_text), wrong, right, len(named), sum(bad), named_right,
                   len(scene.corners))
    return DetectorScore(*map(int, counts), named_px=np.array(named_px, dtype=float))


def tag_is_right(pattern, tag: str, corners: np.ndarray, truth: dict, match_px: float = 2.0) -> bool:
    """Whether a tag read at these corners is right: the template's corners of that tag lie within ``match_px``
    of where the truth puts them.

    Parameters
    ----------
    pattern : Pattern
    tag : str
    corners : ndarray (4, 2)
        The block's corners in reading order, pixels.
    truth : dict
        Corner name -> its true pixel (hidden corners too, where the scene projects them).
    match_px : float

    Returns
    -------
    bool
        False too for a tag the template lacks, or a corner the truth does not know.
    """
    place = pattern.locate(tag)
    if place is None:
        return False
    patch, row, col = place
    return all(name in truth and np.linalg.norm(truth[name] - p) <= match_px
               for name, p in zip((patch.corner_name(*v) for v in patch.block_vertices(row, col)), corners))
