"""Train the detector's networks from rendered images only: ``python -m handcap.detect.train``.

Deterministic for a seed on the CPU (torch's deterministic algorithms, a fixed number of threads), so the
shipped weights can be remade bit for bit (``make detect-weights`` holds the commands that made them).

Scenes come from :class:`handcap.detect.scenes.SceneMaker` (random poses, cameras, sensor scales and looks) and
:class:`~handcap.detect.scenes.PageMaker` (photographed printed sheets); the corner network learns from 96 x 96
crops of them, most of them around a visible corner, with JPEG artefacts on some; the refiner from 17 x 17 crops
near true corners and at the corner network's false candidates; the reader from views of their blocks in several
fonts, alphabets and glyph layouts, and its confidence gate is set on validation scenes; the block checker
(:mod:`handcap.detect.checker`) from the blocks the vote names in new scenes, as the networks read them. The test
suite trains a tiny version for a few steps to show the code runs.
"""

from __future__ import annotations

import argparse
import contextlib
import copy
import sys
import time
from pathlib import Path

import numpy as np
import torch
from torch.utils.data import DataLoader

from handcap.core.errors import HandcapError
from handcap.patterns.alphabet import ALPHABET, DEXTERCAP_ALPHABET
from handcap.detect.corners import CornerNet, corner_loss, detect_corners
from handcap.detect.checker import checker_samples, train_checker
from handcap.detect.evaluation import (CornerScore, evaluate_corners, evaluate_reader, reader_gate, reader_line,
                                       score_corners)
from handcap.detect.pipeline import Detector
from handcap.detect.networks import WEIGHTS, load_corner_net, load_net, load_reader, load_refiner, save_net
from handcap.detect.reader import BlockReader, reader_loss
from handcap.detect.refine import CornerRefiner, candidate_negatives, refiner_loss
from handcap.detect.samples import (Batches, corner_batch, corner_scenes, crops, non_blocks, reader_samples,
                                    reader_scenes, refiner_samples)
from handcap.detect.scenefile import load_scenes, save_scenes
from handcap.patterns.session import session_pattern

__all__ = ["CornerScore", "FONTS", "WEIGHTS", "crops", "evaluate_corners", "evaluate_reader", "load_corner_net",
           "load_net", "load_reader", "main", "reader_samples", "reader_scenes", "save_net",
           "score_corners", "train_corners", "train_reader", "train_refiner"]


@contextlib.contextmanager
def _deterministic(device: str = "cpu"):
    """torch's deterministic algorithms while training (on a GPU, a warning where an operation has no
    deterministic kernel), the caller's setting restored afterwards."""
    before = torch.are_deterministic_algorithms_enabled()
    torch.use_deterministic_algorithms(True, warn_only=device != "cpu")
    try:
        yield
    finally:
        torch.use_deterministic_algorithms(before)


def _stream(draw, scenes, batch: int, seed: int, workers: int, **options):
    """``next_batch(rng)``: ``draw(scenes, batch, rng, **options)`` as tensors, in this process
    (``workers`` 0, from ``rng``) or in worker processes (from ``seed`` and the worker count)."""
    if workers > 0:
        stream = iter(DataLoader(Batches(draw, scenes, batch, seed, **options), batch_size=None,
                                 num_workers=workers, prefetch_factor=8, persistent_workers=True))
        return lambda rng: next(stream)
    return lambda rng: tuple(map(torch.as_tensor, draw(scenes, batch, rng, **options)))


def _fit(make_net, batch_loss, scenes, *, steps: int, seed: int, lr: float, label: str, progress: bool,
         device: str = "cpu"):
    """The training loop the networks share: AdamW with cosine decay, deterministic for a seed.

    ``make_net()`` gives the network (after the seed is set, so its initial weights follow it) and
    ``batch_loss(net, rng)`` the loss of one freshly drawn batch. The network trains on ``device``
    and comes back on the CPU.
    """
    if steps > 0 and not scenes:
        raise HandcapError("no scenes to train on")
    torch.manual_seed(seed)
    rng = np.random.default_rng(seed)
    net = make_net().to(device)
    opt = torch.optim.AdamW(net.parameters(), lr=lr, weight_decay=1e-4)
    sched = torch.optim.lr_scheduler.CosineAnnealingLR(opt, max(steps, 1), eta_min=0.05 * lr)
    net.train()
    with _deterministic(device):
        for step in range(steps):
            loss = batch_loss(net, rng)
            opt.zero_grad()
            loss.backward()
            opt.step()
            sched.step()
            if progress and (step % 100 == 0 or step == steps - 1):
                print(f"{label} step {step:5d} loss {loss.item():.4f}", flush=True)
    return net.cpu().eval()


def train_corners(scenes, *, steps: int = 2000, batch: int = 32, seed: int = 0, lr: float = 2e-3,
                  net: CornerNet | None = None, progress: bool = False, device: str = "cpu",
                  workers: int = 0, config: dict | None = None) -> CornerNet:
    """Train the corner network on crops of rendered scenes (deterministic for a seed).

    Parameters
    ----------
    scenes : sequence of Scene
    steps, batch, seed : int
        Optimiser steps, crops per step, and the seed.
    lr : float
        AdamW learning rate, decayed by a cosine to 5 % of it.
    net : CornerNet, optional
        Start from these weights (default: a new network).
    progress : bool
        Print the loss every 100 steps.
    device : str
        Where the network trains (``'cpu'``, ``'cuda'``).
    workers : int
        Processes drawing the crops (:class:`~handcap.detect.samples.Batches`; 0: the training process itself).
        The crops, and so the weights, depend on the seed and this number.
    config : dict, optional
        A new network's :class:`~handcap.detect.corners.CornerNet` arguments (made after the seed is set).

    Returns
    -------
    CornerNet
        On the CPU, with no activation ranges: those of ``net`` held for its old weights (tools/corner_ranges.py).
    """
    draw = _stream(corner_batch, scenes, batch, seed, workers)

    def loss(model, rng):
        images, heat, offset, near = (t.to(device, non_blocking=True) for t in draw(rng))
        return corner_loss(model(images), heat, offset, near)

    trained = _fit(lambda: net or CornerNet(**(config or {})), loss, scenes, steps=steps, seed=seed, lr=lr,
                   label="corners", progress=progress, device=device)
    trained.ranges = None
    return trained


def train_refiner(scenes, corner_net: CornerNet, *, steps: int = 2000, batch: int = 256, seed: int = 0,
                  lr: float = 2e-3, net: CornerRefiner | None = None, progress: bool = False,
                  occluded: float = 0.0, phone: float = 0.0) -> CornerRefiner:
    """Train the corner refiner on crops of rendered scenes (deterministic for a seed).

    Parameters
    ----------
    scenes : sequence of Scene
    corner_net : CornerNet
        Its candidates at a low threshold that are no corner (:func:`~handcap.detect.refine.candidate_negatives`)
        are the refiner's negatives.
    steps, batch, seed : int
    lr : float
        AdamW learning rate, decayed by a cosine to 5 % of it.
    net : CornerRefiner, optional
        Start from these weights (default: a new network).
    progress : bool
        Print the loss every 100 steps.
    occluded : float
        Share of the negatives drawn from candidates at an occluder's edge near a hidden corner (0: no more often).
    phone : float
        Share of the crops processed as a phone camera does (:func:`~handcap.detect.samples.phone_look`).

    Returns
    -------
    CornerRefiner
        With no activation ranges: those of ``net`` held for its old weights (tools/corner_ranges.py).
    """
    negatives, hidden = zip(*[candidate_negatives(detect_corners(corner_net, s.image, threshold=0.05)[0], s)
                              for s in scenes])

    def loss(model, rng):
        crops, is_corner, offset = refiner_samples(scenes, batch, rng, negatives, occluded=hidden,
                                                   occluded_share=occluded, phone=phone)
        return refiner_loss(model(torch.from_numpy(crops)[:, None]), torch.from_numpy(is_corner),
                            torch.from_numpy(offset))

    trained = _fit(lambda: net or CornerRefiner(), loss, scenes, steps=steps, seed=seed, lr=lr, label="refiner",
                   progress=progress)
    trained.ranges = None
    return trained


def train_reader(scenes, *, steps: int = 2000, batch: int = 128, seed: int = 0, lr: float = 2e-3,
                 net: BlockReader | None = None, progress: bool = False, device: str = "cpu",
                 workers: int = 0, negatives=None, displaced: float = 0.0, phone: float = 0.0) -> BlockReader:
    """Train the block reader on views of rendered scenes (deterministic for a seed).

    Parameters
    ----------
    scenes : sequence of Scene
    steps, batch, seed : int
    lr : float
        AdamW learning rate, decayed by a cosine to 5 % of it.
    net : BlockReader, optional
    progress : bool
        Print the loss every 100 steps.
    device : str
        Where the network trains (``'cpu'``, ``'cuda'``).
    workers : int
        Processes drawing the views (0: the training process); the views depend on the seed and this number.
    negatives : list of ndarray (N, 4, 2), optional
        Per scene, quads of its corners that are not blocks (default: :func:`non_blocks`, made here).
    displaced, phone : float
        Shares of the true blocks shown with one corner moved, as no block, and of the views processed as a
        phone does (:func:`reader_samples`).

    Returns
    -------
    BlockReader
        On the CPU.
    """
    negatives = [non_blocks(s) for s in scenes] if negatives is None else negatives
    draw = _stream(reader_samples, scenes, batch, seed, workers, negatives=negatives, displaced=displaced, phone=phone)

    def loss(model, rng):
        views, first, second, turn = (t.to(device, non_blocking=True) for t in draw(rng))
        return reader_loss(model(views[:, None]), first, second, turn)

    return _fit(lambda: net or BlockReader(), loss, scenes, steps=steps, seed=seed, lr=lr, label="reader",
                progress=progress, device=device)


#: Bold monospace fonts tried for training the reader (Debian's font packages; missing ones are skipped).
FONTS = ("/usr/share/fonts/truetype/liberation/LiberationMono-Bold.ttf",
         "/usr/share/fonts/truetype/freefont/FreeMonoBold.ttf",
         "/usr/share/fonts/truetype/inconsolata/Inconsolata.otf",
         "/usr/share/fonts/truetype/noto/NotoSansMono-Bold.ttf")


def main(argv=None) -> int:
    """Render scenes, train the networks, score them on held-out scenes, write the weights."""
    threads = torch.get_num_threads()
    try:
        return _main(argv)
    finally:  # run in a process that goes on (a test, a notebook), --threads must not outlive the command
        torch.set_num_threads(threads)


def _main(argv) -> int:
    p = argparse.ArgumentParser(prog="python -m handcap.detect.train", description=__doc__.split("\n\n")[0])
    p.add_argument("--what", choices=("corners", "refiner", "reader", "checker", "all"), default="all")
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
    p.add_argument("--scenes-file", help="the networks' scenes: read from this .npz when it exists, rendered and "
                   "written there when not (train where nothing renders)")
    p.add_argument("--device", default="cpu", help="where the corner network or the reader trains: cpu or cuda")
    p.add_argument("--workers", type=int, default=0, help="processes drawing the corner network's crops or the "
                                                          "reader's views (default 0: the training process)")
    p.add_argument("--batch", type=int, help="samples per step (default 32 crops for the corner network, 128 "
                                             "views for the reader)")
    p.add_argument("--no-score", action="store_true",
                   help="the reader: train only (where nothing renders); set its confidence gate and scores "
                        "afterwards with --steps 0 --init on the weights written")
    p.add_argument("--lr", type=float, default=2e-3, help="learning rate (default %(default)s)")
    p.add_argument("--width", type=int, default=24, help="a new corner network's channels at half resolution")
    p.add_argument("--stem", type=int, default=16, help="a new corner network's channels at full resolution")
    p.add_argument("--dilations", default="1,2,4", help="a new corner network's dilations (default %(default)s)")
    p.add_argument("--cut", action="store_true", help="the reader: cut its training scenes to their corners "
                                                      "(the same views, a third smaller in --scenes-file)")
    p.add_argument("--displaced", type=float, default=0.0,
                   help="the reader: share of true blocks shown with one corner moved, as no block (default 0)")
    p.add_argument("--occluded", type=float, default=0.0, help="the refiner: share of its negatives drawn from "
                   "candidates at an occluder's edge near a hidden corner (default 0: as often as any other)")
    p.add_argument("--phone", type=float, default=0.0, help="the refiner or reader: share of views a phone sharpens")
    p.add_argument("--vary", type=float, default=0.0, help="the reader: share of its training scenes whose glyphs "
                   "are varied in weight, slant, width and outline, to read fonts it never saw")
    p.add_argument("--wide", type=float, default=0.0, help="the reader: share of its random glyph layouts drawn "
                   "from wider ranges (underlines further down, or to the square's middle)")
    p.add_argument("--layouts", type=float, default=0.5, help="the reader: share of its scenes with a random glyph "
                   "layout, the rest in handcap's (default %(default)s)")
    p.add_argument("--seconds", type=float,
                   help="the corner network or the reader: time a few steps first and train only as many as fit "
                        "this long")
    p.add_argument("--hidden", type=int, default=0, help="the checker: hidden units (default 0: logistic regression)")
    p.add_argument("--floor", action="store_true",
                   help="the checker: fit and keep only blocks the vote's own rules keep")
    p.add_argument("--max-wrong", type=float, help="the checker: share of wrong blocks its gate keeps (default: "
                   "as many as the hand-set checks keep of the same blocks)")
    a = p.parse_args(argv)
    torch.set_num_threads(a.threads)
    (out := Path(a.out)).mkdir(parents=True, exist_ok=True)
    started = time.time()
    if a.init and a.what == "all":
        raise HandcapError("--init starts one network: name it with --what")
    if a.seconds and a.what not in ("corners", "reader"):
        raise HandcapError("--seconds plans one network's steps: give it with --what corners or --what reader")
    if a.init and a.what == "checker":
        raise HandcapError("--init: the checker is fitted anew each time")
    init = load_net(a.init, {"corners": "CornerNet", "refiner": "CornerRefiner", "reader": "BlockReader"}[a.what]) \
        if a.init else None
    if a.what in ("corners", "all"):
        scenes, tests = corner_data = _scenes(a)
        print(f"{len(scenes)} + {len(tests)} scenes ready in {time.time() - started:.0f} s", flush=True)
        shape = {"width": a.width, "stem": a.stem, "dilations": [int(d) for d in a.dilations.split(",")]}
        settings = {"seed": a.seed, "lr": a.lr, "batch": a.batch or 32, "device": a.device, "workers": a.workers}
        if a.seconds:
            a.steps = _plan(train_corners, scenes, a, init, config=shape, **settings)
        net = train_corners(scenes, steps=a.steps, net=init, config=shape, progress=True, **settings)
        score = evaluate_corners(net, tests)
        print(score.summary(), flush=True)
        save_net(net, out / "corners.npz", {"source": _command(a), "score": score.summary()})
    if a.what in ("refiner", "all"):
        corner_net = load_corner_net(out / "corners.npz" if (out / "corners.npz").is_file() else None)
        scenes, tests = corner_data if a.what == "all" else _scenes(a)
        net = train_refiner(scenes, corner_net, steps=a.steps, seed=a.seed, lr=a.lr, net=init, progress=True,
                            occluded=a.occluded, phone=a.phone)
        score = evaluate_corners(corner_net, tests, refiner=net)
        print(score.summary(), flush=True)
        save_net(net, out / "refiner.npz", {"source": _command(a), "score": score.summary()})
    if a.what in ("reader", "all"):
        fonts = [None] + [f for f in FONTS if Path(f).is_file()]
        held_out, trained = fonts[-1:], fonts[:-1] if len(fonts) > 1 else fonts
        scenes = _reader_scenes(a, trained) if a.steps > 0 else []
        print(f"reader: {len(scenes)} scenes in {len(trained)} font(s), held-out font {held_out[0]}", flush=True)
        settings = {"seed": a.seed, "lr": a.lr, "batch": a.batch or 128, "device": a.device, "workers": a.workers,
                    "negatives": [non_blocks(s) for s in scenes], "displaced": a.displaced, "phone": a.phone}
        if a.seconds:
            a.steps = _plan(train_reader, scenes, a, init, **settings)
        net = train_reader(scenes, steps=a.steps, net=init, progress=True, **settings)
        line = "not scored (trained with --no-score)"
        if not a.no_score:
            validation = reader_scenes(a.test_scenes, a.seed + 2_000_003, trained)
            net.min_score = reader_gate(net, validation)
            print(f"reader: trusted alone from confidence {net.min_score:.4f} (at most 0.1 % wrong on "
                  f"{len(validation)} validation scenes in the training fonts)", flush=True)
            tests = reader_scenes(a.test_scenes, a.seed + 1_000_003, held_out)
            score = {name: evaluate_reader(net, [t for t in tests if t.alphabet == alphabet], min_score=net.min_score)
                     for name, alphabet in (("handcap", ALPHABET), ("dextercap", DEXTERCAP_ALPHABET))}
            line = reader_line(score, held_out[0])
        print(line, flush=True)
        save_net(net, out / "reader.npz", {"source": _command(a), "score": line})
    if a.what in ("checker", "all"):
        _train_checker(a, out)
    print(f"wrote {out} ({time.time() - started:.0f} s in all)")
    return 0


def _train_checker(a, out: Path) -> None:
    """Fit the block checker on the vote's blocks in new scenes, as the networks in ``out`` (else the shipped
    ones) read them, in three folds of the scenes (:func:`~handcap.detect.checker.train_checker`)."""
    corner_net, refiner, reader = (load(out / name if (out / name).is_file() else None) for load, name in (
        (lambda path: load_corner_net(path, int8=True), "corners.npz"),
        (lambda path: load_refiner(path, int8=True), "refiner.npz"), (load_reader, "reader.npz")))  # as detect runs
    if a.scenes < 3:
        raise HandcapError(f"--scenes {a.scenes}: the checker needs 3 scenes or more (three folds)")
    fonts = [None] + [f for f in FONTS if Path(f).is_file()][:-1]  # the reader's training fonts
    made = {"what": "checker", "scenes": a.scenes, "seed": a.seed, "pages": a.pages}
    scenes = _kept(a.scenes_file, made, ("train",), lambda: {
        "train": corner_scenes(a.scenes, a.seed + 3_000_003, pages=a.pages, fonts=fonts)})["train"]
    ruled = {name: Detector(corner_net, reader, pattern, refiner=refiner)  # the hand-set checks
             for name, pattern in (("hand", session_pattern(("right",), ())), ("session", session_pattern()))}
    detectors = [ruled["hand" if all(str(n).startswith("right:") for n in s.corner_names) else "session"]
                 for s in scenes]
    folds = [checker_samples(detectors[k::3], scenes[k::3]) for k in range(3)]  # hands and sheets in each
    print(f"checker: {sum(len(f[0]) for f in folds)} blocks ({sum(int((~f[1]).sum()) for f in folds)} wrong) in "
          f"{len(scenes)} scenes, three folds", flush=True)
    checker, line = train_checker(folds, min_support=reader.min_score, hidden=a.hidden, floor=a.floor,
                                  max_wrong=a.max_wrong, seed=a.seed)
    print(line, flush=True)
    save_net(checker, out / "checker.npz", {"source": _command(a), "score": line})


def _plan(train, scenes, a, init, **settings) -> int:
    """The steps of ``train`` that fit in ``a.seconds``, from two short runs (their difference leaves out the
    start: workers, device), at most ``a.steps``."""
    took = []
    for steps in (40, 240):
        probe = time.time()
        train(scenes, steps=steps, net=copy.deepcopy(init), **settings)
        took.append(time.time() - probe)
    steps = min(a.steps, int(200 * a.seconds / max(took[1] - took[0], 1e-3)))
    print(f"{a.what}: {steps} steps fit in {a.seconds:.0f} s", flush=True)
    return steps


def _reader_scenes(a, fonts) -> list:
    """The reader's training scenes: rendered in ``fonts``, or read from ``--scenes-file``."""
    made = {"what": "reader", "scenes": a.scenes, "seed": a.seed, "cut": a.cut}
    made |= {k: getattr(a, k) for k, v in (("vary", 0), ("wide", 0), ("layouts", 0.5)) if getattr(a, k) != v}
    return _kept(a.scenes_file, made, ("train",), lambda: {  # (files made before those options stay readable)
        "train": reader_scenes(a.scenes, a.seed, fonts, cut=a.cut, vary=a.vary, wide=a.wide,
                               layouts=a.layouts)})["train"]


def _kept(path, made: dict, names, render) -> dict:
    """Groups ``names`` of scenes read from the scenes file ``path`` where it exists (made as ``made`` says),
    else ``render()``'s, written there when ``path`` is given."""
    if path and Path(path).is_file():
        groups, info = load_scenes(path)
        if {k: info.get(k) for k in made} != made or set(groups) != set(names):
            raise HandcapError(f"{path}: holds scenes made with {info}, not {made}")
        return groups
    groups = render()
    if path:
        save_scenes(path, groups, made)
    return groups


def _command(a) -> str:
    """The command that made the weights, as stored with them (options at their defaults left out); after
    the command that made the ``--init`` weights, where they say."""
    words = (f"python -m handcap.detect.train --what {a.what} --scenes {a.scenes} --test-scenes {a.test_scenes} "
             f"--steps {a.steps} --pages {a.pages} --seed {a.seed}" + (f" --init {a.init}" if a.init else ""))
    for option, default in (("device", "cpu"), ("workers", 0), ("batch", None), ("lr", 2e-3), ("width", 24),
                            ("stem", 16), ("dilations", "1,2,4"), ("scenes_file", None), ("no_score", False),
                            ("cut", False), ("displaced", 0.0), ("vary", 0.0), ("phone", 0.0), ("wide", 0.0),
                            ("layouts", 0.5)):
        if getattr(a, option) != default:
            words += f" --{option.replace('_', '-')}" + ("" if getattr(a, option) is True else f" {getattr(a, option)}")
    if a.what == "checker":
        words += f" --hidden {a.hidden}" + (" --floor" if a.floor else "") + (
            f" --max-wrong {a.max_wrong}" if a.max_wrong is not None else "")
    if a.init:
        with np.load(a.init, allow_pickle=False) as data:
            if "info.source" in data.files:
                words = f"{data['info.source']}; then {words}"
    return words


def _scenes(a) -> tuple[list, list]:
    """The corner network's training and test scenes: rendered, or read from ``--scenes-file``."""
    made = {"scenes": a.scenes, "test_scenes": a.test_scenes, "seed": a.seed, "pages": a.pages}
    fonts = [None] + [f for f in FONTS if Path(f).is_file()]
    groups = _kept(a.scenes_file, made, ("train", "test"),
                   lambda: {"train": corner_scenes(a.scenes, a.seed, pages=a.pages, fonts=fonts),
                            "test": corner_scenes(a.test_scenes, a.seed + 1_000_003)})
    return groups["train"], groups["test"]


if __name__ == "__main__":
    try:
        sys.exit(main())
    except HandcapError as err:
        print(f"handcap: {err}", file=sys.stderr)
        sys.exit(2)
