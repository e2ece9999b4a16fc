"""Training samples drawn from rendered scenes: crops for the corner network and refiner, views for the reader.

Each function draws from a numpy random generator only, so a stream of batches is
fixed by its seed. :class:`Batches` runs :func:`corner_batch` or
:func:`reader_samples` in worker processes (torch's DataLoader), each with its
own seed, for training where the network is faster than one process can draw
samples (a GPU).
"""

from __future__ import annotations

import cv2
import numpy as np
import torch
from torch.utils.data import IterableDataset

from handcap.core.errors import HandcapError
from handcap.detect.blocks import candidate_quads
from handcap.detect.corners import normalise, targets
from handcap.detect.reader import GLYPHS, NONE, block_views
from handcap.detect.refine import RADIUS, normalise_crops, raw_crops
from handcap.detect.scenes import PageMaker, SceneMaker
from handcap.patterns.alphabet import ALPHABET, DEXTERCAP_ALPHABET
from handcap.patterns.glyphs import GlyphLayout

#: Side of the corner network's training crops, pixels.
CROP = 96


def crops(scenes, count: int, rng, size: int = CROP):
    """Random training crops of the scenes: images (count, size, size) and their corners.

    Parameters
    ----------
    scenes : sequence of Scene
    count : int
    rng : numpy.random.Generator
    size : int
        Crop side (even).

    Returns
    -------
    images : ndarray (count, size, size) float32
        Normalised (:func:`handcap.detect.corners.normalise`).
    corners : list of ndarray (K, 2)
        Pixels in each crop.
    """
    images, corners = np.zeros((count, size, size), np.float32), []
    for k in range(count):
        scene = scenes[int(rng.integers(len(scenes)))]
        h, w = scene.image.shape
        if len(scene.corners) and rng.random() < 0.8:
            centre = scene.corners[int(rng.integers(len(scene.corners)))] + rng.uniform(-size / 3, size / 3, 2)
        else:
            centre = rng.uniform([0, 0], [w, h])
        x0 = int(np.clip(centre[0] - size / 2, 0, max(w - size, 0))) // 2 * 2
        y0 = int(np.clip(centre[1] - size / 2, 0, max(h - size, 0))) // 2 * 2
        crop = np.zeros((size, size), np.uint8)
        part = scene.image[y0:y0 + size, x0:x0 + size]
        crop[:part.shape[0], :part.shape[1]] = part
        if rng.random() < 0.3:
            ok, code = cv2.imencode(".jpg", crop, [cv2.IMWRITE_JPEG_QUALITY, int(rng.integers(40, 95))])
            crop = cv2.imdecode(code, cv2.IMREAD_GRAYSCALE)
        images[k] = normalise(crop)
        inside = scene.corners - [x0, y0]
        keep = ((inside >= -0.5).all(axis=1) & (inside[:, 0] < part.shape[1] - 0.5)
                & (inside[:, 1] < part.shape[0] - 0.5))
        corners.append(inside[keep])
    return images, corners


def corner_batch(scenes, count: int, rng, size: int = CROP):
    """One training batch for the corner network: crops (:func:`crops`) and their targets.

    Parameters
    ----------
    scenes : sequence of Scene
    count : int
    rng : numpy.random.Generator
    size : int

    Returns
    -------
    images : Tensor (count, 1, size, size)
    heat : Tensor (count, size / 2, size / 2)
    offset : Tensor (count, 2, size / 2, size / 2)
    near : Tensor (count, size / 2, size / 2) bool
        As :func:`handcap.detect.corners.targets` gives them.
    """
    images, corners = crops(scenes, count, rng, size)
    made = [targets(images.shape[1:], c) for c in corners]
    heat, offset, near = (torch.from_numpy(np.stack([m[k] for m in made])) for k in range(3))
    return torch.from_numpy(images)[:, None], heat, offset, near


class Batches(IterableDataset):
    """An endless stream of batches ``draw(scenes, count, rng, **options)``; worker ``i`` draws with seed ``(seed, i)``.

    With a fixed number of workers the DataLoader takes their batches in turn, so the stream is fixed by
    the seed and the worker count.

    Parameters
    ----------
    draw : callable
        A module-level function (it travels to the workers): :func:`corner_batch` or :func:`reader_samples`.
    scenes : sequence of Scene
    count : int
        Samples per batch.
    seed : int
    **options
        Passed on to ``draw``.
    """

    def __init__(self, draw, scenes, count: int, seed: int, **options):
        super().__init__()
        self.draw, self.scenes, self.count, self.seed, self.options = draw, scenes, count, seed, options

    def __iter__(self):
        """Batches, forever."""
        worker = torch.utils.data.get_worker_info()
        rng = np.random.default_rng([self.seed, 0 if worker is None else worker.id])
        while True:
            yield self.draw(self.scenes, self.count, rng, **self.options)


def reader_samples(scenes, count: int, rng, *, jitter: float = 0.04, negatives=None, displaced: float = 0.0,
                   phone: float = 0.0):
    """Training views for the block reader: true blocks turned at random, and quads that are not blocks.

    With ``displaced`` > 0, that share of the true blocks drawn has one corner moved by 18-50 % of the
    block's side and counts as no block: a corner found at an occluder's edge beside a hidden one (2-6 px
    off on rendered hands) makes a square the reader reads well but whose corners are wrong.

    Parameters
    ----------
    scenes : sequence of Scene
    count : int
    rng : numpy.random.Generator
    jitter : float
        Corner noise, as a share of the block's side (detections are not exact).
    negatives : list of ndarray (N, 4, 2), optional
        Per scene, quads that are not blocks (default: made here, which is slow in a loop).
    displaced : float
        Share of the true blocks drawn that get one corner moved and count as no block.
    phone : float
        Share of the views processed around their block as a phone's camera does (:func:`phone_look`).

    Returns
    -------
    views : ndarray (count, 32, 32) float32
    first, second, turn : ndarray (count,) int
        Classes of the three heads.
    """
    views = np.zeros((count, 32, 32), np.float32)
    labels = np.zeros((3, count), np.int64)
    negatives = [non_blocks(scene) for scene in scenes] if negatives is None else negatives
    for k in range(count):
        pick = int(rng.integers(len(scenes)))
        scene = scenes[pick]
        if len(scene.blocks) and rng.random() < 0.7:
            b = int(rng.integers(len(scene.blocks)))
            reading = scene.blocks[b]
            shift = int(rng.integers(4))
            quad = np.roll(reading, -shift, axis=0)  # quad[j] = reading[(j + shift) % 4]
            text = scene.block_text[b]
            labels[:, k] = (GLYPHS.index(text[0]), GLYPHS.index(text[1]), (-shift) % 4)
            if displaced and rng.random() < displaced:
                quad = quad.copy()
                side = np.linalg.norm(np.roll(quad, -1, axis=0) - quad, axis=1).mean()
                turn = rng.uniform(0, 2 * np.pi)
                quad[int(rng.integers(4))] += rng.uniform(0.18, 0.5) * side * np.array([np.cos(turn), np.sin(turn)])
                labels[:, k] = (NONE, NONE, 4)
        else:
            pool = negatives[pick]
            if len(pool) and rng.random() < 0.8:
                quad = pool[int(rng.integers(len(pool)))]
            else:  # a random small quadrilateral anywhere
                centre = rng.uniform([0, 0], scene.image.shape[::-1])
                side = rng.uniform(5, 30)
                quad = centre + side * (np.array([[-0.5, -0.5], [0.5, -0.5], [0.5, 0.5], [-0.5, 0.5]])
                                        + rng.normal(0, 0.1, (4, 2)))
            labels[:, k] = (NONE, NONE, 4)
        side = np.linalg.norm(np.roll(quad, -1, axis=0) - quad, axis=1).mean()
        noisy = quad + rng.normal(0, jitter * side, quad.shape)
        views[k] = block_views(_photometric(scene.image, noisy, rng, phone), noisy[None])[0]
    return views, labels[0], labels[1], labels[2]


def non_blocks(scene) -> np.ndarray:
    """Quads of the scene's true corners that are not its white squares (black squares, odd shapes)."""
    quads = candidate_quads(scene.corners)
    truth = {frozenset(map(tuple, np.round(b, 4))) for b in scene.blocks}
    pts = scene.corners[quads] if len(quads) else np.zeros((0, 4, 2))
    return np.array([q for q in pts if frozenset(map(tuple, np.round(q, 4))) not in truth]).reshape(-1, 4, 2)


def phone_look(image: np.ndarray, rng) -> np.ndarray:
    """A phone camera's processing of a grey image: half the time its noise reduction, then its sharpening.

    The noise reduction is an edge-keeping bilateral filter; the sharpening an unsharp mask (sigma 0.6-2 px,
    amount 0.3-2), which rings beside every edge: printed squares photographed so keep their corners where
    they were, but the overshoot brightens the paper and darkens the ink along each edge.

    Parameters
    ----------
    image : ndarray (H, W) uint8
    rng : numpy.random.Generator

    Returns
    -------
    ndarray (H, W) uint8
    """
    out = image
    if rng.random() < 0.5:
        out = cv2.bilateralFilter(out, 5, float(rng.uniform(10, 40)), float(rng.uniform(1, 3)))
    level = out.astype(np.float32)
    blurred = cv2.GaussianBlur(level, (0, 0), float(rng.uniform(0.6, 2.0)), borderType=cv2.BORDER_REFLECT)
    return np.clip(np.rint(level + rng.uniform(0.3, 2.0) * (level - blurred)), 0, 255).astype(np.uint8)


def refiner_samples(scenes, count: int, rng, negatives, *, shift: float = 1.5, occluded=None,
                    occluded_share: float = 0.0, phone: float = 0.0):
    """Training crops: true corners seen from a nearby pixel, and candidates that are no corner.

    Parameters
    ----------
    scenes : sequence of Scene
    count : int
    rng : numpy.random.Generator
    negatives : list of ndarray (N, 2)
        Per scene, points more than 3 pixels from any printed corner (the corner network's false
        candidates), pixels; a scene without any gets random points instead.
    shift : float
        Largest distance of a positive crop's centre from its corner, pixels.
    occluded : list of ndarray (M, 2), optional
        Per scene, candidates at an occluder's edge near a hidden corner
        (:func:`~handcap.detect.refine.candidate_negatives`), pixels.
    occluded_share : float
        Share of the negatives drawn from ``occluded`` (from any scene that has some): they are rare among
        the candidates, and the costliest to take for corners.
    phone : float
        Share of the crops processed as a phone's camera does (:func:`phone_look`), before the JPEG artefacts
        some get (drawn from ``rng`` only where above 0, so a stream without it is as before).

    Returns
    -------
    crops : ndarray (count, 17, 17) float32
    is_corner : ndarray (count,) float32
    offset : ndarray (count, 2) float32
        Corner minus crop centre, pixels (zero for negatives).
    """
    size = 2 * RADIUS + 1
    raw = np.zeros((count, size, size), np.uint8)
    label = np.zeros(count, np.float32)
    offset = np.zeros((count, 2), np.float32)
    hard = [] if occluded is None or occluded_share <= 0 else [k for k, o in enumerate(occluded) if len(o)]
    for k in range(count):
        pick = int(rng.integers(len(scenes)))
        scene, pool = scenes[pick], negatives[pick]
        if len(scene.corners) and rng.random() < 0.6:
            corner = scene.corners[int(rng.integers(len(scene.corners)))]
            r, a = shift * np.sqrt(rng.random()), rng.uniform(0, 2 * np.pi)
            centre = np.rint(corner + r * np.array([np.cos(a), np.sin(a)])).astype(int)
            label[k], offset[k] = 1.0, corner - centre
        elif hard and rng.random() < occluded_share:
            pick = hard[int(rng.integers(len(hard)))]
            scene, pool = scenes[pick], occluded[pick]
            centre = np.rint(pool[int(rng.integers(len(pool)))]).astype(int)
        elif len(pool):
            centre = np.rint(pool[int(rng.integers(len(pool)))]).astype(int)
        else:  # anywhere; a corner there is a positive
            centre = np.rint(rng.uniform([0, 0], scene.image.shape[::-1])).astype(int)
            if len(scene.corners):
                gap = np.linalg.norm(scene.corners - centre, axis=1)
                j = int(np.argmin(gap))
                if gap[j] <= shift:
                    label[k], offset[k] = 1.0, scene.corners[j] - centre
        raw[k] = raw_crops(scene.image, centre)[0]
        if phone > 0 and rng.random() < phone:
            raw[k] = phone_look(raw[k], rng)
        if rng.random() < 0.3:  # a phone photo's JPEG artefacts
            ok, code = cv2.imencode(".jpg", raw[k], [cv2.IMWRITE_JPEG_QUALITY, int(rng.integers(40, 95))])
            raw[k] = cv2.imdecode(code, cv2.IMREAD_GRAYSCALE)
    crops = normalise_crops(raw)
    # The eight turns and mirrors of the square, with the offsets turned alike.
    flip_x, flip_y, swap = rng.random((3, count)) < 0.5
    crops[flip_x] = crops[flip_x, :, ::-1]
    offset[flip_x, 0] *= -1
    crops[flip_y] = crops[flip_y, ::-1, :]
    offset[flip_y, 1] *= -1
    crops[swap] = crops[swap].transpose(0, 2, 1)
    offset[swap] = offset[swap][:, ::-1]
    return np.ascontiguousarray(crops), label, offset


def _photometric(image: np.ndarray, quad: np.ndarray, rng, phone: float = 0.0) -> np.ndarray:
    """Around the quad, sometimes a phone's processing (a share ``phone``, :func:`phone_look`) and sometimes JPEG
    artefacts, else the image as it is (``phone`` 0 draws nothing for it)."""
    sharpened = phone > 0 and rng.random() < phone
    jpeg = rng.random() < 0.3
    if not (sharpened or jpeg):
        return image
    lo = np.clip(np.floor(quad.min(axis=0)).astype(int) - 24, 0, None) // 8 * 8
    hi = np.clip(np.ceil(quad.max(axis=0)).astype(int) + 24, 0, image.shape[::-1])
    out = image.copy()
    part = np.ascontiguousarray(image[lo[1]:hi[1], lo[0]:hi[0]])
    if part.size == 0:
        return image
    if sharpened:
        part = phone_look(part, rng)
    if jpeg:
        ok, code = cv2.imencode(".jpg", part, [cv2.IMWRITE_JPEG_QUALITY, int(rng.integers(35, 95))])
        part = cv2.imdecode(code, cv2.IMREAD_GRAYSCALE)
    out[lo[1]:hi[1], lo[0]:hi[0]] = part
    return out


def reader_scenes(count: int, seed: int, fonts, *, pages: float = 0.5, cut: bool = False, vary: float = 0.0,
                  wide: float = 0.0, layouts: float = 0.5) -> list:
    """Scenes for the reader: hand renders and photographed sheets in each font, many alphabets and layouts.

    Hand renders cycle through the fonts and handcap's, DexterCap's and random alphabets, half of
    them with handcap's glyph layout and half with a random one (:meth:`GlyphLayout.random`; ``layouts`` sets that
    share); photographed sheets (:class:`handcap.detect.scenes.PageMaker`, ten per sheet) do the same.
    ``cut`` cuts each scene to its corners (:meth:`Scene.cropped`). A share ``vary`` of the scenes gets glyphs
    varied in weight, slant, width and outline (:meth:`GlyphLayout.varied`, from its own random stream); a share
    ``wide`` of the random layouts is drawn from wider ranges instead (``GlyphLayout.random(..., wide=True)``:
    underlines further below the glyphs or reaching to the square's middle, as other generators print them).

    Parameters
    ----------
    count, seed : int
    fonts : sequence of str or None
        Font files (None: the default font).
    pages : float
        Share of photographed sheets among the scenes.
    cut : bool
        Cut each scene to its corners: the same views, a third smaller to keep in a scenes file.
    vary : float
        Share of the scenes whose glyphs look like another font's.
    wide : float
        Share of the random layouts drawn from the wider ranges.
    layouts : float
        Share of the scenes with a random glyph layout (0.5: every other group of scenes, as before this option;
        other shares move groups to or from handcap's layout at random, from a stream of their own).

    Returns
    -------
    list of Scene
    """
    if not 0.0 <= layouts <= 1.0:
        raise HandcapError(f"the share of random glyph layouts must be 0 to 1, got {layouts}")
    rng, other, wider, mixed = (np.random.default_rng(s) for s in (seed, (seed, 17), (seed, 19), (seed, 23)))
    flip = abs(layouts - 0.5) / 0.5  # chance that a group takes the other kind of layout than the alternation's
    n_pages = int(round(pages * count))
    out = []
    for kind, total, per in (("hand", count - n_pages, max(1, (count - n_pages) // (6 * len(fonts)))),
                             ("page", n_pages, 10)):
        made, k = 0, 0
        while made < total:
            font = fonts[k % len(fonts)]
            alphabets = (ALPHABET, DEXTERCAP_ALPHABET, "".join(rng.permutation(list(GLYPHS))[:27]))
            alphabet = alphabets[(k // len(fonts)) % 3]
            random_layout = bool((k // (3 * len(fonts))) % 2)
            if flip and random_layout == (layouts < 0.5) and mixed.random() < flip:
                random_layout = not random_layout
            layout = GlyphLayout.random(rng) if random_layout else None
            layout = GlyphLayout.random(wider, wide=True) if layout and wider.random() < wide else layout
            layout = (layout or GlyphLayout()).varied(other) if other.random() < vary else layout
            make = SceneMaker if kind == "hand" else PageMaker
            extra = {"scale": (0.45, 1.0)} if kind == "hand" else {}
            maker = make(seed * 1000 + k + (0 if kind == "hand" else 500), font=font, alphabet=alphabet,
                         layout=layout, **extra)
            try:
                batch = [maker.scene() for _ in range(min(per, total - made))]
                batch = [b.cropped() for b in batch] if cut else batch
            finally:
                maker.close()
            out += batch
            made += len(batch)
            k += 1
    return out


def corner_scenes(count: int, seed: int, *, pages: float = 0.0, fonts=(None,)) -> list:
    """Scenes for the corner network: hand renders, and a share of photographed sheets.

    Parameters
    ----------
    count : int
    seed : int
    pages : float
        Share of photographed sheets (:class:`handcap.detect.scenes.PageMaker`, ten per sheet, each
        in one of ``fonts`` with a random glyph layout).
    fonts : sequence of str or None
        Fonts of the sheets.

    Returns
    -------
    list of Scene
    """
    n_pages = int(round(pages * count))
    maker = SceneMaker(seed)
    try:
        out = [maker.scene() for _ in range(count - n_pages)]
    finally:
        maker.close()
    rng = np.random.default_rng(seed + 7)
    k = 0
    while len(out) < count:
        sheet = PageMaker(seed * 1000 + 500 + k, font=fonts[k % len(fonts)], layout=GlyphLayout.random(rng))
        out += [sheet.scene() for _ in range(min(10, count - len(out)))]
        k += 1
    return out
