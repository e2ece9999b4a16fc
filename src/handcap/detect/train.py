"""Train the detector's networks from rendered images only: ``python -m handcap.detect.train``.

Deterministic for a seed on the CPU (torch's deterministic algorithms, a fixed
number of threads), so the shipped weights can be remade bit for bit (``make
detect-weights`` holds the two commands that made them).

Scenes come from :class:`handcap.detect.scenes.SceneMaker` (random poses, cameras,
sensor scales and looks) and :class:`~handcap.detect.scenes.PageMaker`
(photographed printed sheets); the corner network learns from 96 x 96 crops of
them, most of them around a visible corner, with JPEG artefacts on some; the
refiner from 17 x 17 crops near true corners and at the corner network's false
candidates; the reader from views of their blocks in several fonts, alphabets and glyph
layouts, and its confidence gate is set on validation scenes. The test suite
trains a tiny version for a few steps to show the code runs.
"""

from __future__ import annotations

import argparse
import contextlib
import sys
import time
from pathlib import Path

import cv2
import numpy as np
import torch

from handcap.core.errors import HandcapError
from handcap.patterns.alphabet import ALPHABET, DEXTERCAP_ALPHABET
from handcap.detect.blocks import candidate_quads
from handcap.detect.corners import CornerNet, corner_loss, normalise, targets
from handcap.detect.evaluation import (CornerScore, evaluate_corners, evaluate_reader, reader_gate, reader_line,
                                       score_corners)
from handcap.detect.networks import WEIGHTS, load_corner_net, load_net, load_reader, save_net
from handcap.detect.reader import GLYPHS, NONE, BlockReader, block_views, reader_loss
from handcap.detect.refine import CornerRefiner, false_candidates, refiner_loss, refiner_samples
from handcap.detect.scenes import PageMaker, SceneMaker
from handcap.patterns.glyphs import GlyphLayout

CROP = 96
__all__ = ["CornerScore", "FONTS", "WEIGHTS", "crops", "evaluate_corners", "evaluate_reader", "load_corner_net",
           "load_net", "load_reader", "main", "reader_samples", "reader_scenes", "save_net",
           "score_corners", "train_corners", "train_reader", "train_refiner"]


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


@contextlib.contextmanager
def _deterministic():
    """torch's deterministic algorithms while training, the caller's setting restored afterwards."""
    before = torch.are_deterministic_algorithms_enabled()
    torch.use_deterministic_algorithms(True)
    try:
        yield
    finally:
        torch.use_deterministic_algorithms(before)


def _fit(make_net, batch_loss, scenes, *, steps: int, seed: int, lr: float, label: str, progress: bool):
    """The training loop both networks share: AdamW with cosine decay, deterministic for a seed.

    ``make_net()`` gives the network (after the seed is set, so its initial weights follow it) and
    ``batch_loss(net, rng)`` the loss of one freshly drawn batch.
    """
    if not scenes:
        raise HandcapError("no scenes to train on")
    torch.manual_seed(seed)
    rng = np.random.default_rng(seed)
    net = make_net()
    opt = torch.optim.AdamW(net.parameters(), lr=lr, weight_decay=1e-4)
    sched = torch.optim.lr_scheduler.CosineAnnealingLR(opt, max(steps, 1), eta_min=0.05 * lr)
    net.train()
    with _deterministic():
        for step in range(steps):
            loss = batch_loss(net, rng)
            opt.zero_grad()
            loss.backward()
            opt.step()
            sched.step()
            if progress and (step % 100 == 0 or step == steps - 1):
                print(f"{label} step {step:5d} loss {loss.item():.4f}", flush=True)
    net.eval()
    return net


def train_corners(scenes, *, steps: int = 2000, batch: int = 32, seed: int = 0, lr: float = 2e-3,
                  net: CornerNet | None = None, progress: bool = False) -> CornerNet:
    """Train the corner network on crops of rendered scenes (deterministic for a seed).

    Parameters
    ----------
    scenes : sequence of Scene
    steps : int
        Optimiser steps.
    batch : int
        Crops per step.
    seed : int
    lr : float
        AdamW learning rate, decayed by a cosine to 5 % of it.
    net : CornerNet, optional
        Start from these weights (default: a new network).
    progress : bool
        Print the loss every 100 steps.

    Returns
    -------
    CornerNet
    """
    def loss(model, rng):
        images, corners = crops(scenes, batch, rng)
        made = [targets(images.shape[1:], c) for c in corners]
        heat, offset, near = (torch.from_numpy(np.stack([m[k] for m in made])) for k in range(3))
        return corner_loss(model(torch.from_numpy(images)[:, None]), heat, offset, near)

    return _fit(lambda: net or CornerNet(), loss, scenes, steps=steps, seed=seed, lr=lr, label="corners",
                progress=progress)


def train_refiner(scenes, corner_net: CornerNet, *, steps: int = 2000, batch: int = 256, seed: int = 0,
                  lr: float = 2e-3, net: CornerRefiner | None = None, progress: bool = False) -> CornerRefiner:
    """Train the corner refiner on crops of rendered scenes (deterministic for a seed).

    Parameters
    ----------
    scenes : sequence of Scene
    corner_net : CornerNet
        Its candidates at a low threshold that lie more than 3 pixels from every printed corner are the
        refiner's negatives (what it must learn to turn away).
    steps, batch, seed : int
    lr : float
        AdamW learning rate, decayed by a cosine to 5 % of it.
    net : CornerRefiner, optional
        Start from these weights (default: a new network).
    progress : bool
        Print the loss every 100 steps.

    Returns
    -------
    CornerRefiner
    """
    negatives = [false_candidates(corner_net, scene) for scene in scenes]

    def loss(model, rng):
        crops, is_corner, offset = refiner_samples(scenes, batch, rng, negatives)
        return refiner_loss(model(torch.from_numpy(crops)[:, None]), torch.from_numpy(is_corner),
                            torch.from_numpy(offset))

    return _fit(lambda: net or CornerRefiner(), loss, scenes, steps=steps, seed=seed, lr=lr, label="refiner",
                progress=progress)


def reader_samples(scenes, count: int, rng, *, jitter: float = 0.04, negatives=None):
    """Training views for the block reader: true blocks turned at random, and quads that are not blocks.

    Parameters
    ----------
    scenes : sequence of Scene
    count : int
    rng : numpy.random.Generator
    jitter : float
        Corner noise, as a share of the block's side (detections are not exact).
    negatives : list of ndarray (N, 4, 2), optional
        Per scene, quads that are not blocks (default: made here, which is slow in a loop).

    Returns
    -------
    views : ndarray (count, 32, 32) float32
    first, second, turn : ndarray (count,) int
        Classes of the three heads.
    """
    views = np.zeros((count, 32, 32), np.float32)
    labels = np.zeros((3, count), np.int64)
    negatives = [_negatives(scene) for scene in scenes] if negatives is None else negatives
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
        views[k] = block_views(_photometric(scene.image, noisy, rng), noisy[None])[0]
    return views, labels[0], labels[1], labels[2]


def _negatives(scene) -> np.ndarray:
    """Quads of the scene's true corners that are not its white squares (black squares, odd shapes)."""
    quads = candidate_quads(scene.corners)
    truth = {frozenset(map(tuple, np.round(b, 4))) for b in scene.blocks}
    pts = scene.corners[quads] if len(quads) else np.zeros((0, 4, 2))
    return np.array([q for q in pts if frozenset(map(tuple, np.round(q, 4))) not in truth]).reshape(-1, 4, 2)


def _photometric(image: np.ndarray, quad: np.ndarray, rng) -> np.ndarray:
    """Sometimes JPEG artefacts around the quad (a phone photo), else the image as it is."""
    if rng.random() >= 0.3:
        return image
    lo = np.clip(np.floor(quad.min(axis=0)).astype(int) - 24, 0, None) // 8 * 8
    hi = np.clip(np.ceil(quad.max(axis=0)).astype(int) + 24, 0, image.shape[::-1])
    out = image.copy()
    part = np.ascontiguousarray(image[lo[1]:hi[1], lo[0]:hi[0]])
    if part.size == 0:
        return image
    ok, code = cv2.imencode(".jpg", part, [cv2.IMWRITE_JPEG_QUALITY, int(rng.integers(35, 95))])
    out[lo[1]:hi[1], lo[0]:hi[0]] = cv2.imdecode(code, cv2.IMREAD_GRAYSCALE)
    return out


def train_reader(scenes, *, steps: int = 2000, batch: int = 128, seed: int = 0, lr: float = 2e-3,
                 net: BlockReader | None = None, progress: bool = False) -> BlockReader:
    """Train the block reader on views of rendered scenes (deterministic for a seed).

    Parameters
    ----------
    scenes : sequence of Scene
    steps : int
    batch : int
    seed : int
    lr : float
        AdamW learning rate, decayed by a cosine to 5 % of it.
    net : BlockReader, optional
    progress : bool
        Print the loss every 100 steps.

    Returns
    -------
    BlockReader
    """
    negatives = [_negatives(scene) for scene in scenes]

    def loss(model, rng):
        views, first, second, turn = reader_samples(scenes, batch, rng, negatives=negatives)
        return reader_loss(model(torch.from_numpy(views)[:, None]), torch.from_numpy(first),
                           torch.from_numpy(second), torch.from_numpy(turn))

    return _fit(lambda: net or BlockReader(), loss, scenes, steps=steps, seed=seed, lr=lr, label="reader",
                progress=progress)


#: Bold monospace fonts tried for training the reader (Debian's font packages; missing ones are skipped).
FONTS = ("/usr/share/fonts/truetype/liberation/LiberationMono-Bold.ttf",
         "/usr/share/fonts/truetype/freefont/FreeMonoBold.ttf",
         "/usr/share/fonts/truetype/inconsolata/Inconsolata.otf",
         "/usr/share/fonts/truetype/noto/NotoSansMono-Bold.ttf")


def reader_scenes(count: int, seed: int, fonts, *, pages: float = 0.5) -> list:
    """Scenes for the reader: hand renders and photographed sheets in each font, many alphabets and layouts.

    Hand renders cycle through the fonts and handcap's, DexterCap's and random alphabets, half of
    them with handcap's glyph layout and half with a random one (:meth:`GlyphLayout.random`);
    photographed sheets (:class:`handcap.detect.scenes.PageMaker`, ten per sheet) do the same.

    Parameters
    ----------
    count : int
    seed : int
    fonts : sequence of str or None
        Font files (None: the default font).
    pages : float
        Share of photographed sheets among the scenes.

    Returns
    -------
    list of Scene
    """
    rng = np.random.default_rng(seed)
    n_pages = int(round(pages * count))
    out = []
    for kind, total, per in (("hand", count - n_pages, max(1, (count - n_pages) // (6 * len(fonts)))),
                             ("page", n_pages, 10)):
        made, k = 0, 0
        while made < total:
            font = fonts[k % len(fonts)]
            alphabets = (ALPHABET, DEXTERCAP_ALPHABET, "".join(rng.permutation(list(GLYPHS))[:27]))
            alphabet = alphabets[(k // len(fonts)) % 3]
            layout = GlyphLayout.random(rng) if (k // (3 * len(fonts))) % 2 else None
            make = SceneMaker if kind == "hand" else PageMaker
            extra = {"scale": (0.45, 1.0)} if kind == "hand" else {}
            maker = make(seed * 1000 + k + (0 if kind == "hand" else 500), font=font, alphabet=alphabet,
                         layout=layout, **extra)
            try:
                batch = [maker.scene() for _ in range(min(per, total - made))]
            finally:
                maker.close()
            out += batch
            made += len(batch)
            k += 1
    return out


def main(argv=None) -> int:
    """Render scenes, train the networks, score them on held-out scenes, write the weights."""
    p = argparse.ArgumentParser(prog="python -m handcap.detect.train", description=__doc__.split("\n\n")[0])
    p.add_argument("--what", choices=("corners", "refiner", "reader", "all"), default="all")
    p.add_argument("--scenes", type=int, default=600, help="rendered training scenes (default %(default)s)")
    p.add_argument("--test-scenes", type=int, default=40, help="held-out scenes to score on (default %(default)s)")
    p.add_argument("--steps", type=int, default=4000, help="optimiser steps (default %(default)s)")
    p.add_argument("--pages", type=float, default=0.3,
                   help="share of photographed sheets among the corner network's scenes (default %(default)s)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--init", help="start the network from these weights (.npz) instead of new ones")
    p.add_argument("--threads", type=int, default=2, help="torch CPU threads (default %(default)s)")
    p.add_argument("--out", default=str(WEIGHTS), help="folder for corners.npz, refiner.npz and reader.npz "
                                                       "(default: the shipped weights)")
    a = p.parse_args(argv)
    torch.set_num_threads(a.threads)
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    started = time.time()
    command = (f"python -m handcap.detect.train --what {a.what} --scenes {a.scenes} --test-scenes {a.test_scenes} "
               f"--steps {a.steps} --pages {a.pages} --seed {a.seed}" + (f" --init {a.init}" if a.init else ""))
    if a.init and a.what == "all":
        raise HandcapError("--init starts one network: name it with --what")
    init = load_net(a.init, {"corners": "CornerNet", "refiner": "CornerRefiner", "reader": "BlockReader"}[a.what]) \
        if a.init else None
    if a.what in ("corners", "all"):
        scenes = corner_scenes(a.scenes, a.seed, pages=a.pages, fonts=[None] + [f for f in FONTS if Path(f).is_file()])
        tests = corner_scenes(a.test_scenes, a.seed + 1_000_003)
        print(f"rendered {len(scenes)} + {len(tests)} scenes in {time.time() - started:.0f} s", flush=True)
        net = train_corners(scenes, steps=a.steps, seed=a.seed, net=init, progress=True)
        score = evaluate_corners(net, tests)
        print(score.summary(), flush=True)
        save_net(net, out / "corners.npz", {"source": command, "score": score.summary()})
    if a.what in ("refiner", "all"):
        corner_net = load_corner_net(out / "corners.npz" if (out / "corners.npz").is_file() else None)
        scenes = corner_scenes(a.scenes, a.seed, pages=a.pages, fonts=[None] + [f for f in FONTS if Path(f).is_file()])
        tests = corner_scenes(a.test_scenes, a.seed + 1_000_003)
        net = train_refiner(scenes, corner_net, steps=a.steps, seed=a.seed, net=init, progress=True)
        score = evaluate_corners(corner_net, tests, refiner=net)
        print(score.summary(), flush=True)
        save_net(net, out / "refiner.npz", {"source": command, "score": score.summary()})
    if a.what in ("reader", "all"):
        fonts = [None] + [f for f in FONTS if Path(f).is_file()]
        held_out, trained = fonts[-1:], fonts[:-1] if len(fonts) > 1 else fonts
        scenes = reader_scenes(a.scenes, a.seed, trained)
        tests = reader_scenes(a.test_scenes, a.seed + 1_000_003, held_out)
        print(f"reader: {len(scenes)} scenes in {len(trained)} font(s), held-out font {held_out[0]}", flush=True)
        net = train_reader(scenes, steps=a.steps, seed=a.seed, net=init, progress=True)
        validation = reader_scenes(a.test_scenes, a.seed + 2_000_003, trained)
        net.min_score = reader_gate(net, validation)
        print(f"reader: trusted alone from confidence {net.min_score:.4f} (at most 0.1 % wrong on "
              f"{len(validation)} validation scenes in the training fonts)", flush=True)
        score = {name: evaluate_reader(net, [t for t in tests if t.alphabet == alphabet], min_score=gate)
                 for name, alphabet in (("handcap", ALPHABET), ("dextercap", DEXTERCAP_ALPHABET))
                 for gate in (net.min_score,)}
        line = reader_line(score, held_out[0])
        print(line, flush=True)
        save_net(net, out / "reader.npz", {"source": command, "score": line})
    print(f"wrote {out} ({time.time() - started:.0f} s in all)")
    return 0


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


if __name__ == "__main__":
    sys.exit(main())
