"""Corners of coded patches named by their grid: ``PATCH_r{r}c{c}``, the vertex in row ``r``, column ``c``.

Adjacent corners of one patch (``c`` or ``r`` one apart) lie one printed square apart, whatever the patch is stuck
on: a ruler in every frame of a take. :func:`grid_sides` measures it; ``triangulate`` reports it against the
printed pitch (:func:`handcap.quality.stage_checks.pitch_check`) and ``clean`` sizes the patches of a layout that
gives no positions by it (:func:`handcap.multiview.clean_groups.layout_groups`).
"""

from __future__ import annotations

import re

import numpy as np

_GRID = re.compile(r"^(.*)_r(\d+)c(\d+)$")
#: Least adjacent-corner distances (pairs times frames) to take a patch's square side from.
MIN_SIDES = 20
#: At most this many frames, evenly spread, are measured: a median needs no more, and a long take's pairs would not
#: fit memory.
MAX_FRAMES = 1000


def grid_cell(name) -> tuple[str, int, int] | None:
    """``(patch, row, column)`` of a corner named ``PATCH_r{r}c{c}`` (an ``OWNER:`` prefix stays in ``patch``), or
    None for another name.

    Parameters
    ----------
    name : str

    Returns
    -------
    (str, int, int) or None
    """
    match = _GRID.match(str(name))
    return (match[1], int(match[2]), int(match[3])) if match else None


def grid_sides(positions: np.ndarray, names) -> np.ndarray:
    """Distances between adjacent corners of the patches, over the frames (at most :data:`MAX_FRAMES`).

    Parameters
    ----------
    positions : ndarray (T, M, 3)
        Metres, NaN where missing.
    names : sequence of str, length M

    Returns
    -------
    ndarray (K,)
        Every finite distance between two markers ``PATCH_r{r}c{c}`` and ``PATCH_r{r}c{c+1}`` (or
        ``PATCH_r{r+1}c{c}``) in a measured frame, metres.
    """
    index = {cell: i for i, cell in ((i, grid_cell(n)) for i, n in enumerate(names)) if cell is not None}
    pairs = [(i, index[(p, r + dr, c + dc)]) for (p, r, c), i in index.items() for dr, dc in ((0, 1), (1, 0))
             if (p, r + dr, c + dc) in index]
    if not pairs or not len(positions):
        return np.zeros(0)
    a, b = np.array(pairs).T
    frames = np.unique(np.linspace(0, len(positions) - 1, min(len(positions), MAX_FRAMES)).astype(int))
    picked = np.asarray(positions)[frames]
    sides = np.linalg.norm(picked[:, a] - picked[:, b], axis=-1)
    return sides[np.isfinite(sides)]
