"""Rendered training scenes and their truth, kept in one ``.npz`` so they are rendered once.

Rendering is most of the cost of training the detector's networks on the CPU
(about half a second per scene), and a machine that trains (a GPU machine, say)
may have no OpenGL at all. ``python -m handcap.detect.train --scenes-file F``
renders its scenes into ``F`` once and reads them from there afterwards. Images
are stored as lossless PNG, so a scene read back is the scene rendered, bit for
bit. Where a transfer limits a file's size, ``python -m handcap.detect.scenefile
split F N`` writes it as N parts and ``... join F PART...`` joins them again.
This module imports no renderer.
"""

from __future__ import annotations

import argparse
import json
import sys
from dataclasses import dataclass
from pathlib import Path
import zipfile

import cv2
import numpy as np

from handcap.core.errors import HandcapError
from handcap.core.files import atomic_output


@dataclass(frozen=True)
class Scene:
    """One rendered image and its truth.

    Attributes
    ----------
    image : ndarray (H, W) uint8
    corners : ndarray (K, 2)
        Visible corners, pixels.
    corner_names : ndarray (K,) str
    blocks : ndarray (B, 4, 2)
        Visible tags' corners in reading order, pixels.
    block_text : ndarray (B,) str
    alphabet : str
        Glyphs of the printed tags.
    projected : dict, optional
        Name -> pixels of every printed corner, hidden ones included (where the camera would see it):
        a detection named so is right when it lies there, even if the truth calls it hidden (a
        corner seen at a grazing angle, or at an occluder's edge).
    """

    image: np.ndarray
    corners: np.ndarray
    corner_names: np.ndarray
    blocks: np.ndarray
    block_text: np.ndarray
    alphabet: str
    projected: dict | None = None

    def cropped(self, margin: int = 32) -> "Scene":
        """The scene cut to the box of its visible corners widened by ``margin`` pixels (coordinates moved).

        What the reader learns from lies there, and a cut scene is about a third smaller to keep and ship.

        Parameters
        ----------
        margin : int
            Pixels kept around the corners.

        Returns
        -------
        Scene
            This scene where it has no corners.
        """
        if not len(self.corners):
            return self
        lo = np.clip(np.floor(self.corners.min(axis=0)).astype(int) - margin, 0, None)
        hi = np.minimum(np.ceil(self.corners.max(axis=0)).astype(int) + margin + 1, self.image.shape[::-1])
        projected = {k: v - lo for k, v in self.projected.items()} if self.projected else self.projected
        return Scene(np.ascontiguousarray(self.image[lo[1]:hi[1], lo[0]:hi[0]]), self.corners - lo,
                     self.corner_names, self.blocks - lo, self.block_text, self.alphabet, projected)


def _ragged(parts, dtype, shape=()):
    """Parts concatenated along their first axis, and the offsets of each part's start (N + 1,).

    Strings are stored as UTF-8 bytes (a quarter of numpy's unicode for ASCII).
    """
    sizes = [len(p) for p in parts]
    if dtype is str:  # the longest string sets the width
        parts = [np.char.encode(np.asarray(p, str).reshape(-1), "utf-8") for p in parts]
        joined = np.concatenate(parts) if parts else np.zeros(0, "S1")
    else:
        joined = np.concatenate([np.asarray(p, dtype).reshape((-1,) + shape) for p in parts]) if parts \
            else np.zeros((0,) + shape, dtype)
    return joined, np.concatenate([[0], np.cumsum(sizes)]).astype(np.int64)


def _text(array: np.ndarray) -> np.ndarray:
    """Stored strings as numpy unicode."""
    return np.char.decode(array, "utf-8") if array.dtype.kind == "S" else array


def save_scenes(path, groups: dict, info: dict | None = None) -> None:
    """Write groups of scenes (``{"train": [...], "test": [...]}``) to an ``.npz``, atomically.

    Parameters
    ----------
    path : str or Path
    groups : dict of str -> list of Scene
    info : dict, optional
        What made them (seeds, counts): stored as JSON and returned by :func:`load_scenes`.
    """
    arrays = {"info": np.array(json.dumps(info or {})), "groups": np.array(sorted(groups))}
    for name, scenes in groups.items():
        pngs = [np.frombuffer(cv2.imencode(".png", s.image, [cv2.IMWRITE_PNG_COMPRESSION, 9])[1], np.uint8)
                for s in scenes]
        arrays[f"{name}.png"], arrays[f"{name}.png_at"] = _ragged(pngs, np.uint8)
        arrays[f"{name}.corners"], arrays[f"{name}.corners_at"] = _ragged([s.corners for s in scenes], float, (2,))
        arrays[f"{name}.corner_names"], _ = _ragged([s.corner_names for s in scenes], str)
        arrays[f"{name}.blocks"], arrays[f"{name}.blocks_at"] = _ragged([s.blocks for s in scenes], float, (4, 2))
        arrays[f"{name}.block_text"], _ = _ragged([s.block_text for s in scenes], str)
        arrays[f"{name}.alphabet"] = np.array([s.alphabet for s in scenes], str)
        projected = [s.projected or {} for s in scenes]
        arrays[f"{name}.projected_names"], arrays[f"{name}.projected_at"] = _ragged(
            [list(p) for p in projected], str)
        arrays[f"{name}.projected_xy"], _ = _ragged([list(p.values()) for p in projected], float, (2,))
    with atomic_output(path) as fh:
        np.savez(fh, **arrays)


def load_scenes(path) -> tuple[dict, dict]:
    """The groups of scenes written by :func:`save_scenes`, and their ``info``.

    Parameters
    ----------
    path : str or Path

    Returns
    -------
    groups : dict of str -> list of Scene
    info : dict

    Raises
    ------
    HandcapError
        A missing file, or one that holds no scenes.
    """
    path = Path(path)
    if not path.is_file():
        raise HandcapError(f"{path}: no scenes file there")
    try:
        with np.load(path, allow_pickle=False) as data:
            info = json.loads(str(data["info"]))
            groups = {str(name): _group(data, str(name)) for name in data["groups"]}
    except (KeyError, ValueError, OSError, zipfile.BadZipFile, cv2.error) as err:
        raise HandcapError(f"{path}: not a scenes file ({err})") from None
    return groups, info


def _group(data, name: str) -> list:
    """One group's scenes from an open scenes file."""
    png, png_at = data[f"{name}.png"], data[f"{name}.png_at"]
    corners, corners_at = data[f"{name}.corners"], data[f"{name}.corners_at"]
    corner_names = _text(data[f"{name}.corner_names"])
    blocks, blocks_at = data[f"{name}.blocks"], data[f"{name}.blocks_at"]
    block_text, alphabet = _text(data[f"{name}.block_text"]), data[f"{name}.alphabet"]
    p_names, p_at, p_xy = (_text(data[f"{name}.projected_names"]), data[f"{name}.projected_at"],
                           data[f"{name}.projected_xy"])
    out = []
    for k in range(len(png_at) - 1):
        image = cv2.imdecode(png[png_at[k]:png_at[k + 1]], cv2.IMREAD_GRAYSCALE)
        if image is None:
            raise ValueError(f"scene {k} of {name!r}: its image does not decode")
        c, b, p = slice(corners_at[k], corners_at[k + 1]), slice(blocks_at[k], blocks_at[k + 1]), \
            slice(p_at[k], p_at[k + 1])
        out.append(Scene(image, corners[c], corner_names[c], blocks[b], block_text[b], str(alphabet[k]),
                         dict(zip(p_names[p].tolist(), p_xy[p])) or None))
    return out


def join_scenes(paths, path) -> None:
    """Join scenes files written in parts into one, each group's scenes in the order of the parts.

    A scenes file too large to move in one piece (a transfer limit) is written as parts whose ``info``
    holds ``part: [k, n]`` and the whole's ``info``; the joined file has the whole's ``info`` without it.

    Parameters
    ----------
    paths : sequence of str or Path
        Every part, in order.
    path : str or Path
        The joined file (written atomically).

    Raises
    ------
    HandcapError
        A part missing, repeated, out of order, or of another whole.
    """
    arrays, whole = {}, None
    for k, part in enumerate(paths):
        try:
            with np.load(part, allow_pickle=False) as data:
                info = json.loads(str(data["info"]))
                got = {key: data[key] for key in data.files}
        except (KeyError, ValueError, OSError, zipfile.BadZipFile) as err:
            raise HandcapError(f"{part}: not a scenes file ({err})") from None
        rest = {key: v for key, v in info.items() if key != "part"}
        if info.get("part") != [k + 1, len(paths)] or (whole is not None and rest != whole):
            raise HandcapError(f"{part}: part {info.get('part')} of {rest}, expected part {[k + 1, len(paths)]}"
                               f" of {whole or rest}")
        whole = rest
        for key, value in got.items():
            if key in ("info", "groups"):
                continue
            if key not in arrays:
                arrays[key] = value
            elif key.endswith("_at"):
                arrays[key] = np.concatenate([arrays[key], value[1:] + arrays[key][-1]])
            else:
                arrays[key] = np.concatenate([arrays[key], value])
    groups = sorted({key.split(".")[0] for key in arrays})
    arrays["info"], arrays["groups"] = np.array(json.dumps(whole)), np.array(groups)
    with atomic_output(path) as fh:
        np.savez(fh, **arrays)


def split_scenes(path, parts: int) -> list[Path]:
    """Write a scenes file as ``parts`` files of about equal size, for :func:`join_scenes` to join elsewhere.

    Each group's scenes keep their order across the parts; the parts are ``{stem}.part{k}of{n}.npz`` beside
    ``path`` (each written atomically), and ``path`` itself is left as it is.

    Parameters
    ----------
    path : str or Path
        A whole scenes file (:func:`save_scenes`).
    parts : int
        How many parts, 1 or more.

    Returns
    -------
    list of Path
        The parts, in order.

    Raises
    ------
    HandcapError
        Fewer than one part, more parts than scenes, or a file that is itself a part.
    """
    path = Path(path)
    groups, info = load_scenes(path)
    if "part" in info:
        raise HandcapError(f"{path}: is part {info['part']} of a scenes file already; join the parts first")
    order = [(name, k) for name in sorted(groups) for k in range(len(groups[name]))]
    if not 1 <= parts <= len(order):
        raise HandcapError(f"{path}: cannot split {len(order)} scenes into {parts} parts")
    with np.load(path, allow_pickle=False) as data:  # each scene's stored PNG bytes, as the file holds them
        size = np.concatenate([np.diff(data[f"{name}.png_at"]) for name in sorted(groups)]).astype(np.float64)
    # Cut where the running size passes each k / parts of the whole, every part keeping one scene or more.
    cuts = [0]
    for k in range(1, parts):
        cut = int(np.searchsorted(np.cumsum(size), size.sum() * k / parts)) + 1
        cuts.append(min(max(cut, cuts[-1] + 1), len(order) - (parts - k)))
    which = np.searchsorted(cuts, np.arange(len(order)), side="right") - 1
    out = []
    for p in range(parts):
        chosen = {}
        for (name, k), w in zip(order, which):
            if w == p:
                chosen.setdefault(name, []).append(groups[name][k])
        out.append(path.with_name(f"{path.stem}.part{p + 1}of{parts}.npz"))
        save_scenes(out[-1], chosen, dict(info, part=[p + 1, parts]))
    return out


def main(argv=None) -> int:
    """``python -m handcap.detect.scenefile split FILE N`` or ``... join OUT PART...``: move a scenes file
    to another machine in parts (a transfer's size limit)."""
    p = argparse.ArgumentParser(prog="python -m handcap.detect.scenefile", description=main.__doc__.split(":")[0])
    verbs = p.add_subparsers(dest="verb", required=True)
    s = verbs.add_parser("split", help="write FILE as N parts beside it")
    s.add_argument("file")
    s.add_argument("parts", type=int)
    j = verbs.add_parser("join", help="join the parts, in order, into OUT")
    j.add_argument("out")
    j.add_argument("part", nargs="+")
    a = p.parse_args(argv)
    try:
        if a.verb == "split":
            for part in split_scenes(a.file, a.parts):
                print(f"wrote {part} ({part.stat().st_size / 1e6:.1f} MB)")
        else:
            join_scenes(a.part, a.out)
            print(f"wrote {a.out}")
    except HandcapError as err:
        print(f"python -m handcap.detect.scenefile: error: {err}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
