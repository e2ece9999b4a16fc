"""Saved detector networks: write and read their weights (``.npz``: arrays, class, configuration, provenance).

The shipped weights live in ``handcap/detect/weights/`` (``corners.npz``, ``refiner.npz``, ``reader.npz`` and the
block checker's ``checker.npz``), made by
``python -m handcap.detect.train``; ``info.source`` in each file is the command that made it and
``info.score`` what it measured on held-out rendered scenes.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import torch

from handcap.core.errors import HandcapError
from handcap.core.files import atomic_output
from handcap.detect.checker import BlockChecker
from handcap.detect.corners import CornerNet
from handcap.detect.int8 import int8_corner_net, int8_refiner
from handcap.detect.reader import BlockReader
from handcap.detect.refine import CornerRefiner

#: Folder of the shipped weights.
WEIGHTS = Path(__file__).resolve().parent / "weights"
#: The networks that can be saved and loaded, by class name.
NETWORKS = {"CornerNet": CornerNet, "CornerRefiner": CornerRefiner, "BlockReader": BlockReader,
            "BlockChecker": BlockChecker}
def save_net(net, path, info: dict | None = None) -> None:
    """Write a network's weights, class and configuration to an ``.npz`` (atomically).

    Parameters
    ----------
    net : CornerNet, CornerRefiner, BlockReader or BlockChecker
    path : str or Path
    info : dict, optional
        Strings recorded with the weights (how they were made, their scores).
    """
    arrays = {f"w.{k}": v.detach().numpy() for k, v in net.state_dict().items()}
    arrays["network"] = np.array(type(net).__name__)
    arrays["config"] = np.array(json.dumps(net.config()))
    if getattr(net, "ranges", None) is not None:
        arrays["ranges"] = np.asarray(net.ranges, dtype=np.float64)
    for key, value in (info or {}).items():
        arrays[f"info.{key}"] = np.array(str(value))
    with atomic_output(path) as fh:
        np.savez(fh, **arrays)


def load_net(path, kind: str):
    """The network of class ``kind`` saved at ``path``.

    Parameters
    ----------
    path : str or Path
    kind : {'CornerNet', 'CornerRefiner', 'BlockReader', 'BlockChecker'}

    Returns
    -------
    CornerNet, CornerRefiner, BlockReader or BlockChecker
        In evaluation mode.

    Raises
    ------
    HandcapError
        A missing file, or one that holds no such network.
    """
    path = Path(path)
    if not path.is_file():
        raise HandcapError(f"{path}: no {kind} weights there; train them with python -m handcap.detect.train")
    try:
        with np.load(path, allow_pickle=False) as data:
            if str(data["network"]) != kind:
                raise HandcapError(f"{path}: holds a {data['network']}, not a {kind}")
            net = NETWORKS[kind](**json.loads(str(data["config"])))
            state = {k[2:]: torch.from_numpy(data[k]) for k in data.files if k.startswith("w.")}
            if "ranges" in data.files:
                net.ranges = np.array(data["ranges"], dtype=np.float64)
        net.load_state_dict(state)
    except (KeyError, ValueError, RuntimeError, TypeError, OSError) as err:
        raise HandcapError(f"{path}: not {kind} weights ({err})") from None
    net.eval()
    return net


def net_info(path) -> dict:
    """The strings saved with a network's weights (``info`` of :func:`save_net`): how they were made, their scores.

    Parameters
    ----------
    path : str or Path

    Returns
    -------
    dict
    """
    with np.load(path, allow_pickle=False) as data:
        return {k[5:]: str(data[k]) for k in data.files if k.startswith("info.")}


def shipped_notes() -> tuple[str, ...]:
    """What the shipped weights measured when they were made (their ``info.score``), one line each.

    Returns
    -------
    tuple of str
    """
    notes = []
    for name in ("corners.npz", "refiner.npz", "reader.npz", "checker.npz"):
        path = WEIGHTS / name
        score = net_info(path).get("score") if path.is_file() else None
        if score is not None:
            notes.append(f"{name}: {score}")
    return tuple(notes)


def load_corner_net(path=None, *, int8: bool = False):
    """The corner network saved at ``path`` (default: the shipped weights).

    Parameters
    ----------
    path : str, Path or None
    int8 : bool
        Its 8-bit integer twin, for inference (:func:`handcap.detect.int8.int8_corner_net`), where its
        weights carry activation ranges (the shipped ones do) and PyTorch can run it; else the network.

    Returns
    -------
    CornerNet or Int8CornerNet
    """
    net = load_net(WEIGHTS / "corners.npz" if path is None else path, "CornerNet")
    return int8_corner_net(net) if int8 else net


def load_reader(path=None) -> BlockReader:
    """The block reader saved at ``path`` (default: the shipped weights).

    Parameters
    ----------
    path : str, Path or None

    Returns
    -------
    BlockReader
    """
    return load_net(WEIGHTS / "reader.npz" if path is None else path, "BlockReader")


def load_refiner(path=None, *, int8: bool = False):
    """The corner refiner saved at ``path`` (default: the shipped weights).

    Parameters
    ----------
    path : str, Path or None
    int8 : bool
        Its twin with the convolutions in 8-bit integers, for inference (:func:`handcap.detect.int8.int8_refiner`),
        where its weights carry activation ranges (the shipped ones do) and PyTorch can run it; else the refiner.

    Returns
    -------
    CornerRefiner or Int8Refiner
    """
    net = load_net(WEIGHTS / "refiner.npz" if path is None else path, "CornerRefiner")
    return int8_refiner(net) if int8 else net


def load_checker(path=None) -> BlockChecker | None:
    """The block checker saved at ``path`` (default: the shipped one, or None where none ships).

    Parameters
    ----------
    path : str, Path or None

    Returns
    -------
    BlockChecker or None
        None only for the default path when no checker ships there (the detector then uses the hand-set
        rules of :mod:`handcap.detect.checks`).
    """
    if path is None and not (WEIGHTS / "checker.npz").is_file():
        return None
    return load_net(WEIGHTS / "checker.npz" if path is None else path, "BlockChecker")
