"""Adapting the block reader to one take, for patches read without a template.

Without a template nothing corrects a reading, so the detector reports only the readings sure enough to stand
alone in a font the reader never saw (:data:`~handcap.detect.pipeline.UNSEEN_FONT_GATE`). On another generator's
printed sheets (another bold monospace font, another glyph layout) that is a third to a half of the tags the reader
reads. The readings it does report are themselves examples of the take's font and layout: :func:`take_views`
collects them (and quads of the take's corners that are no white square, as "no tag"), and
:func:`adapt_reader` fine-tunes a copy of the reader on them for a few hundred steps, each view shrunk, blurred,
noised or JPEG-compressed at random so that it learns the take's glyphs as the small and blurred squares show them.

The adapted reader learns from the shipped reader's readings, and it inherits the shipped reader's confusions: in a
font that draws 7 like a T for the reader, it reads T there too, and surer. So it never reads alone: a reading the
shipped reader does not report is reported where the adapted reader makes the same reading at :data:`GATE` or more,
the shipped reader gave that reading its own gate or more (set in its training fonts), and no glyph of it is one the
shipped reader confuses with another printed glyph in this take (:func:`confused_glyphs`) or a look-alike of the
alphabet. Even so, on rendered sheets in fonts the reader never saw it adds readings that are a little more often
wrong than those the reader reports alone, so it is used only when asked (``handcap detect --adapt-steps``). See
:class:`~handcap.detect.pipeline.Detector`'s ``adapted`` and the README for the figures.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass

import cv2
import numpy as np
import torch
from tqdm import tqdm

from handcap.core.errors import HandcapError
from handcap.detect.blocks import candidate_quads, white_blocks
from handcap.detect.corners import grey_levels
from handcap.detect.reader import GLYPHS, NONE, BlockReader, block_views, glyph_probabilities, reader_loss

#: Fine-tuning steps of 128 views that the README measured (about 80 s on 2 cores).
STEPS = 200
#: Least sure readings in a take to adapt the reader on.
MIN_READINGS = 30
#: At most this many of a take's images are searched for readings to adapt on (evenly spread over its frames).
MAX_IMAGES = 40
#: Least confidence of the adapted reader in a reading it vouches for: the reader's own gate for readings with a
#: look-alike glyph (:data:`handcap.detect.pipeline.LOOKALIKE_GATE`).
GATE = 0.999
#: Mean probability the shipped reader gives one printed glyph where it reads another, in a take, from which the two
#: count as confused there (:func:`confused_glyphs`).
CONFUSED = 0.08


@dataclass(frozen=True)
class TakeViews:
    """What a take teaches the reader: its sure readings and quads that are no white square.

    Attributes
    ----------
    images : list of ndarray (H, W) uint8
    blocks : ndarray (N, 4, 2)
        Corners of the sure readings in reading order (top-left, top-right, bottom-right, bottom-left), pixels.
    first, second : ndarray (N,) int
        Their glyphs, as indices in :data:`~handcap.detect.reader.GLYPHS`.
    block_image : ndarray (N,) int
        Index of each reading's image.
    others : ndarray (K, 4, 2)
        Quads of detected corners that are not white squares (black squares, odd shapes), pixels.
    other_image : ndarray (K,) int
    confused : str
        Printed glyphs the shipped reader confuses with another in these images: :func:`confused_glyphs` over both
        glyph heads of every white square found, read or not.
    """

    images: list
    blocks: np.ndarray
    first: np.ndarray
    second: np.ndarray
    block_image: np.ndarray
    others: np.ndarray
    other_image: np.ndarray
    confused: str = ""


def take_views(detector, images, *, progress: bool | None = None) -> TakeViews:
    """Collect the readings a detector without a template reports in ``images``, and what is no tag there.

    Parameters
    ----------
    detector : Detector
        Without a template and without an adapted reader.
    images : sequence of ndarray (H, W) uint8
    progress : bool, optional
        Progress bar over the images (default: on a terminal).

    Returns
    -------
    TakeViews
    """
    if detector.pattern is not None or detector.adapted is not None:
        raise HandcapError("the reader is adapted to a take read without a template, by the shipped reader")
    images = list(images)
    blocks, texts, block_image, others, other_image, heads = [], [], [], [], [], []
    hidden = None if progress is None else not progress
    for k, image in enumerate(tqdm(images, desc="readings to adapt on", unit="image", disable=hidden, leave=False)):
        found = detector.image(image)
        blocks.append(found.block_xy)
        texts += [str(t) for t in found.block_text]
        block_image += [k] * len(found.block_text)
        xy = found.corners
        quads = candidate_quads(xy, score=found.corner_score)
        white, _ = white_blocks(image, xy, quads, grey_levels(image)) if len(quads) else (quads, None)
        whites = {frozenset(q) for q in white.tolist()}
        rest = np.array([q for q in quads.tolist() if frozenset(q) not in whites], dtype=int).reshape(-1, 4)
        others.append(xy[rest])
        other_image += [k] * len(rest)
        if len(white):
            heads.append(glyph_probabilities(detector.reader, image, xy[white], detector.alphabet))
    first = np.array([GLYPHS.index(t[0]) for t in texts], dtype=int)
    second = np.array([GLYPHS.index(t[1]) for t in texts], dtype=int)
    both = np.concatenate([np.concatenate(h) for h in heads]) if heads else np.zeros((0, len(detector.alphabet)))
    return TakeViews(images, np.concatenate(blocks).reshape(-1, 4, 2), first, second, np.array(block_image, int),
                     np.concatenate(others).reshape(-1, 4, 2), np.array(other_image, int),
                     confused_glyphs(both, detector.alphabet))


def confused_glyphs(probabilities: np.ndarray, alphabet: str) -> str:
    """The printed glyphs a reader confuses with another in a take.

    Glyphs a and b are confused where, over the glyphs the reader reads as a (its first choice), it gives b
    :data:`CONFUSED` or more on average, or the other way round: a pair the take's font draws alike for it.

    Parameters
    ----------
    probabilities : ndarray (N, L)
        A glyph head's probabilities over the L glyphs of ``alphabet``, one row per glyph read (both heads' rows).
    alphabet : str

    Returns
    -------
    str
        The glyphs of the confused pairs, in the alphabet's order.
    """
    p = np.asarray(probabilities, dtype=np.float64).reshape(-1, len(alphabet))
    top = p.argmax(axis=1)
    mass = np.zeros((len(alphabet), len(alphabet)))
    np.add.at(mass, top, p)
    mean = mass / np.maximum(np.bincount(top, minlength=len(alphabet)), 1)[:, None]
    np.fill_diagonal(mean, 0.0)
    bad = (np.maximum(mean, mean.T) >= CONFUSED).any(axis=1)
    return "".join(ch for ch, b in zip(alphabet, bad) if b)


def adapt_reader(reader: BlockReader, views: TakeViews, *, steps: int = STEPS, batch: int = 128, lr: float = 3e-4,
                 seed: int = 0, progress: bool | None = None) -> BlockReader:
    """A copy of ``reader`` fine-tuned on a take's readings (deterministic for a seed and thread count).

    Parameters
    ----------
    reader : BlockReader
        Left as it is.
    views : TakeViews
    steps, batch : int
        Steps of AdamW, and views in each.
    lr : float
    seed : int
    progress : bool, optional
        Progress bar over the steps (default: on a terminal).

    Returns
    -------
    BlockReader
        In evaluation mode; its batch-norm statistics are the shipped reader's.

    Raises
    ------
    HandcapError
        Fewer than :data:`MIN_READINGS` readings to learn from.
    """
    if len(views.blocks) < MIN_READINGS:
        raise HandcapError(f"{len(views.blocks)} sure readings in the take; the reader is adapted on "
                           f"{MIN_READINGS} or more")
    torch.manual_seed(seed)
    rng = np.random.default_rng(seed)
    net = copy.deepcopy(reader).to(memory_format=torch.contiguous_format)
    net.train()
    for module in net.modules():  # a take's few views would skew the statistics the reader learned
        if isinstance(module, torch.nn.BatchNorm2d):
            module.eval()
    opt = torch.optim.AdamW(net.parameters(), lr=lr, weight_decay=1e-4)
    for _ in tqdm(range(steps), desc="adapt reader", unit="step", disable=None if progress is None else not progress,
                  leave=False):
        image, first, second, turn = (torch.from_numpy(a) for a in _draw(views, batch, rng))
        loss = reader_loss(net(image[:, None]), first, second, turn)
        opt.zero_grad()
        loss.backward()
        opt.step()
    return net.eval()


def _draw(views: TakeViews, count: int, rng):
    """``count`` training views of a take: 60 % its readings turned at random, else quads that are no tag."""
    out = np.zeros((count, 32, 32), np.float32)
    labels = np.zeros((3, count), np.int64)
    for k in range(count):
        if rng.random() < 0.6 or not len(views.others):
            b = int(rng.integers(len(views.blocks)))
            shift = int(rng.integers(4))
            quad, image = np.roll(views.blocks[b], -shift, axis=0), views.images[views.block_image[b]]
            labels[:, k] = (views.first[b], views.second[b], (-shift) % 4)
        else:
            b = int(rng.integers(len(views.others)))
            quad = np.roll(views.others[b], -int(rng.integers(4)), axis=0)
            image = views.images[views.other_image[b]]
            labels[:, k] = (NONE, NONE, 4)
        part, quad, side = _degraded(image, quad, rng)
        out[k] = block_views(part, (quad + rng.normal(0.0, 0.04 * side, quad.shape))[None])[0]
    return out, labels[0], labels[1], labels[2]


def _degraded(image: np.ndarray, quad: np.ndarray, rng):
    """The image around ``quad`` (4, 2), at random shrunk and enlarged again (a smaller square), blurred, noised or
    JPEG-compressed; returns the part (float32), the quad in its pixels and the quad's mean side."""
    side = float(np.linalg.norm(np.roll(quad, -1, axis=0) - quad, axis=1).mean())
    lo = np.clip(np.floor(quad.min(axis=0)).astype(int) - 16, 0, None)
    hi = np.clip(np.ceil(quad.max(axis=0)).astype(int) + 16, 0, image.shape[::-1])
    part = image[lo[1]:hi[1], lo[0]:hi[0]].astype(np.float32)
    u = rng.random()
    if u < 0.35 and side > 8:
        f = rng.uniform(max(0.3, 6 / side), 0.9)
        h, w = part.shape
        small = cv2.resize(part, (max(2, int(w * f)), max(2, int(h * f))), interpolation=cv2.INTER_AREA)
        part = cv2.resize(small, (w, h), interpolation=cv2.INTER_LINEAR)
    elif u < 0.6:
        part = cv2.GaussianBlur(part, (0, 0), rng.uniform(0.4, 1.5))
    if rng.random() < 0.5:
        part = part + rng.normal(0.0, rng.uniform(1.0, 6.0), part.shape).astype(np.float32)
    if rng.random() < 0.3:
        _, code = cv2.imencode(".jpg", np.clip(part, 0, 255).astype(np.uint8),
                               [cv2.IMWRITE_JPEG_QUALITY, int(rng.integers(35, 95))])
        part = cv2.imdecode(code, cv2.IMREAD_GRAYSCALE).astype(np.float32)
    return part, quad - lo, side
