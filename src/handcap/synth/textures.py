"""Textures of printed coded patches for the renderer, and each patch's surface through its corners.

The texture of a patch is its printed drawing (:func:`handcap.patterns.glyphs.patch_drawing`)
rasterised with anti-aliasing; all patches of a body share one atlas. Grid vertex ``(r, c)``
of a patch sits at atlas pixel ``origin + (c, r) * square`` (x right, y down), so a mesh
through the corners, with those texture coordinates, shows the corners exactly where the
3D corners project.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from handcap.patterns.glyphs import MARGIN, Font, GlyphLayout, patch_drawing
from handcap.patterns.pattern import Patch

_SUPERSAMPLE = 8  # glyphs are drawn this much finer, then averaged down
_SHIFT = 4  # cv2 fixed-point bits for polygon vertices


@dataclass(frozen=True)
class PatchAtlas:
    """Textures of several patches in one grayscale image.

    Attributes
    ----------
    image : ndarray (H, W) uint8
        Ink 0, paper 255.
    patches : tuple of Patch
    origins : ndarray (P, 2) float
        Atlas pixel (x, y) of each patch's grid vertex (0, 0).
    square : int
        Pixels per square.
    """

    image: np.ndarray
    patches: tuple[Patch, ...]
    origins: np.ndarray
    square: int

    def uv(self, index: int, r, c) -> np.ndarray:
        """Texture coordinates (0..1, v downwards) of grid points ``(r, c)`` of patch ``index``.

        Parameters
        ----------
        index : int
            Position of the patch in :attr:`patches`.
        r, c : array_like
            Grid rows and columns (fractions allowed: the margin lies at -0.5 and ``rows + 0.5``).

        Returns
        -------
        ndarray (..., 2)
        """
        x = self.origins[index, 0] + np.asarray(c, dtype=np.float64) * self.square
        y = self.origins[index, 1] + np.asarray(r, dtype=np.float64) * self.square
        h, w = self.image.shape
        return np.stack([x / w, y / h], axis=-1)


def patch_texture(patch: Patch, font: Font, square: int = 48, *, ink: bool = True,
                  layout: GlyphLayout | None = None) -> np.ndarray:
    """One patch drawn at ``square`` pixels per square, its black margin included.

    Parameters
    ----------
    patch : Patch
    font : Font
    square : int
        Pixels per square.
    ink : bool
        Draw the glyphs and underlines (False: the bare checkerboard).
    layout : GlyphLayout, optional
        Where the glyphs sit in a square (default: handcap's).

    Returns
    -------
    ndarray (H, W) uint8
        Grid vertex (0, 0) at ``(MARGIN * square, MARGIN * square)`` counted from the image's top-left
        edge (OpenGL's texel convention: pixel ``i`` spans ``[i, i + 1)``).
    """
    backing, white, glyphs = patch_drawing(patch, 1.0, font, layout)  # drawing unit: one square
    offset = -backing[0]
    w = int(round((backing[2] - backing[0]) * square))
    h = int(round((backing[3] - backing[1]) * square))
    # White squares by their exact area over each texel (texel i spans [i, i + 1)): corners stay exact.
    paper = np.zeros((h, w))
    for x0, y0, x1, y1 in white:
        paper += np.outer(_coverage((y0 + offset) * square, (y1 + offset) * square, h),
                          _coverage((x0 + offset) * square, (x1 + offset) * square, w))
    if ink and glyphs:
        scale = square * _SUPERSAMPLE
        mask = np.zeros((h * _SUPERSAMPLE, w * _SUPERSAMPLE), np.uint8)
        # cv2's fixed-point coordinates have pixel centres at integers: an edge at x lies at x * scale - 0.5.
        polys = [np.round(((p + offset) * scale - 0.5) * (1 << _SHIFT)).astype(np.int32)
                 for path in glyphs for p in path.to_polygons(closed_only=True)]
        cv2.fillPoly(mask, polys, 255, lineType=cv2.LINE_8, shift=_SHIFT)
        grow = int(round((layout.weight * layout.cap_height * scale) if layout else 0))
        if grow:
            disc = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * abs(grow) + 1,) * 2)
            mask = (cv2.dilate if grow > 0 else cv2.erode)(mask, disc)
        covered = cv2.resize(mask, (w, h), interpolation=cv2.INTER_AREA) / 255.0
        paper *= 1.0 - covered
    return np.round(np.clip(paper, 0, 1) * 255).astype(np.uint8)


def _coverage(lo: float, hi: float, n: int) -> np.ndarray:
    """Length of ``[lo, hi]`` inside each unit cell ``[i, i + 1)`` of ``0 .. n``."""
    edges = np.arange(n, dtype=np.float64)
    return np.clip(np.minimum(edges + 1, hi) - np.maximum(edges, lo), 0.0, 1.0)


def build_atlas(patches, font: Font, square: int = 48, width: int = 2048, *, ink: bool = True,
                layout: GlyphLayout | None = None) -> PatchAtlas:
    """All ``patches`` in one atlas, packed in shelves.

    Parameters
    ----------
    patches : sequence of Patch
    font : Font
    square : int
        Pixels per square.
    width : int
        Atlas width, pixels (its height follows).
    ink : bool
        Draw the glyphs (False: bare checkerboards, e.g. to check corner geometry).
    layout : GlyphLayout, optional
        Where the glyphs sit in a square (default: handcap's).

    Returns
    -------
    PatchAtlas
    """
    tiles = [patch_texture(p, font, square, ink=ink, layout=layout) for p in patches]
    gap = 4
    x = y = shelf = 0
    places = []
    for tile in tiles:
        h, w = tile.shape
        if x + w > width:
            x, y, shelf = 0, y + shelf + gap, 0
        places.append((x, y))
        x, shelf = x + w + gap, max(shelf, h)
    height = int(2 ** np.ceil(np.log2(max(y + shelf, 1))))
    atlas = np.zeros((height, width), np.uint8)
    for (x0, y0), tile in zip(places, tiles):
        atlas[y0:y0 + tile.shape[0], x0:x0 + tile.shape[1]] = tile
    origins = np.array(places, dtype=np.float64) + MARGIN * square
    return PatchAtlas(atlas, tuple(patches), origins.reshape(-1, 2), square)


def patch_grid(patch: Patch, known: np.ndarray) -> np.ndarray:
    """3D points of a patch's whole grid, its half-square margin included, from the corners that are known.

    Parameters
    ----------
    patch : Patch
    known : ndarray (T, rows + 1, cols + 1, 3)
        Corner positions, metres; NaN where a corner is not known (a corner the layout leaves out).

    Returns
    -------
    ndarray (T, rows + 3, cols + 3, 3)
        Points at grid rows ``-0.5, 0, 1, ..., rows, rows + 0.5`` and the same columns, metres.
        Known corners are kept; the others come from a quadratic surface through the known ones (an
        affine one when fewer than 8 are known), as a stiff tape would lie.
    """
    known = np.asarray(known, dtype=np.float64)
    t, rows1, cols1, _ = known.shape
    rr, cc = np.meshgrid(np.arange(rows1, dtype=np.float64), np.arange(cols1, dtype=np.float64), indexing="ij")
    have = ~np.isnan(known).any(axis=(0, 3))
    full = known.copy()
    if not have.all():
        terms = [np.ones_like(rr), rr, cc] + ([rr * rr, rr * cc, cc * cc] if have.sum() >= 8 else [])
        design = np.stack(terms, axis=-1)
        coef = np.linalg.pinv(design[have]) @ known[:, have].transpose(1, 0, 2).reshape(have.sum(), -1)
        fitted = (design[~have] @ coef).reshape(-1, t, 3).transpose(1, 0, 2)
        full[:, ~have] = fitted
    # Half a square beyond the border on every side: linear extrapolation of the edge rows and columns.
    rows_ext = np.concatenate([1.5 * full[:, :1] - 0.5 * full[:, 1:2], full,
                               1.5 * full[:, -1:] - 0.5 * full[:, -2:-1]], axis=1)
    return np.concatenate([1.5 * rows_ext[:, :, :1] - 0.5 * rows_ext[:, :, 1:2], rows_ext,
                           1.5 * rows_ext[:, :, -1:] - 0.5 * rows_ext[:, :, -2:-1]], axis=2)
