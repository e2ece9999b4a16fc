"""How well the detector's networks do on rendered scenes with truth: corners matched, tags read.

Used by the training command (:mod:`handcap.detect.train`) to score held-out scenes, and by
``benchmarks/detect.py``.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from handcap.detect.corners import CornerNet, detect_corners
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


def evaluate_corners(net: CornerNet, scenes, threshold: float = 0.3) -> CornerScore:
    """Detect the corners of rendered ``scenes`` and score them against their truth.

    Parameters
    ----------
    net : CornerNet
    scenes : sequence of Scene
    threshold : float

    Returns
    -------
    CornerScore
    """
    errors, found, truth = [], 0, 0
    for scene in scenes:
        xy, _ = detect_corners(net, scene.image, threshold=threshold)
        _, err = score_corners(xy, scene.corners)
        errors.append(err)
        found += len(xy)
        truth += len(scene.corners)
    err = np.concatenate(errors) if errors else np.zeros(0)
    matched = len(err)
    return CornerScore(matched / max(truth, 1), matched / max(found, 1),
                       float(np.median(err)) if matched else float("nan"),
                       float(np.sqrt(np.mean(err ** 2))) if matched else float("nan"), found, truth)


def evaluate_reader(net: BlockReader, scenes, alphabet: str | None = None) -> dict:
    """Read the true blocks of ``scenes`` (their corners given in a random turn): share right, wrong, unread.

    Parameters
    ----------
    net : BlockReader
    scenes : sequence of Scene
    alphabet : str, optional
        Glyphs to read (default: each scene's own alphabet).

    Returns
    -------
    dict
        ``right``, ``wrong``, ``unread`` (shares of the blocks), ``blocks`` (count).
    """
    rng = np.random.default_rng(0)
    right = wrong = unread = 0
    for scene in scenes:
        if not len(scene.blocks):
            continue
        shifts = rng.integers(4, size=len(scene.blocks))
        quads = np.array([np.roll(b, -s, axis=0) for b, s in zip(scene.blocks, shifts)])
        text, corners, _, _ = read_blocks(net, scene.image, quads, alphabet or scene.alphabet)
        ok_turn = np.abs(corners - scene.blocks).max(axis=(1, 2)) < 1e-9
        read = text != ""
        good = read & ok_turn & (text == scene.block_text)
        right += int(good.sum())
        wrong += int((read & ~good).sum())
        unread += int((~read).sum())
    total = max(right + wrong + unread, 1)
    return {"right": right / total, "wrong": wrong / total, "unread": unread / total, "blocks": total}


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
    return f"reader on a font it never saw ({Path(font).stem if font else 'default'}): " + "; ".join(parts)


