"""Printed patches stuck on the skin: a fine grid of each patch attached to the hand mesh like markers.

A transfer on tape follows the skin under it. Each patch of a hand layout is
sampled on a grid ``subdivision`` times finer than its squares (its half-square
margin included); every sample is attached to the closest point of the
template hand's skin (triangle, barycentric coordinates, the layout's
``marker_radius`` along the normal), as :class:`~handcap.hand.attachment.MarkerAttachment`
attaches markers. Posed with the hand, the samples are the mesh the renderer
textures, and the samples at integer grid points are the patch's corners: the
truth of every printed corner, including those the layout leaves out because
their skin does not move rigidly with a segment.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from handcap.core.errors import HandcapError
from handcap.core.geometry import closest_points_on_mesh
from handcap.patterns.pattern import Patch
from handcap.hand.attachment import MarkerAttachment
from handcap.synth.textures import patch_grid


#: Steps that scale each patch to the printed pitch on the subject's hand (:func:`patch_skin`).
PITCH_STEPS = 3


@dataclass(frozen=True)
class PatchSkin:
    """The sampled patches of one hand and their attachment to its skin.

    Attributes
    ----------
    patches : tuple of Patch
    rows, cols : tuple of ndarray
        Per patch, the grid coordinates of its sample rows and columns (from -0.5 to ``rows + 0.5``).
    attachment : MarkerAttachment
        Every sample, patch by patch, row-major.
    """

    patches: tuple[Patch, ...]
    rows: tuple[np.ndarray, ...]
    cols: tuple[np.ndarray, ...]
    attachment: MarkerAttachment

    def grids(self, vertices, faces) -> list[np.ndarray]:
        """The samples of every patch on a posed hand.

        Parameters
        ----------
        vertices : ndarray (..., V, 3)
            Posed hand mesh, metres.
        faces : ndarray (F, 3)

        Returns
        -------
        list of ndarray (..., n_rows, n_cols, 3)
            Metres.
        """
        points = np.asarray(self.attachment.positions(np.asarray(vertices, dtype=np.float64), faces))
        out, start = [], 0
        for r, c in zip(self.rows, self.cols):
            n = len(r) * len(c)
            out.append(points[..., start:start + n, :].reshape(points.shape[:-2] + (len(r), len(c), 3)))
            start += n
        return out


def patch_skin(layout, patches, model, betas=None, *, subdivision: int = 4, pitch: float | None = None) -> PatchSkin:
    """Attach the ``patches`` of a hand layout to the skin of ``model`` (see the module docstring).

    A layout places its corners on the template hand; a subject's hand is larger or smaller, and the skin under
    a patch curves, so the corners of a patch attached there lie a little more or less than the printed pitch
    apart on the subject. Printed tape does not stretch with the hand: with ``pitch``, each patch is scaled about
    its middle along the template's skin until its adjacent corners lie a median ``pitch`` apart on the subject's
    hand at rest (:data:`PITCH_STEPS` steps, to well under 0.1 %).

    Parameters
    ----------
    layout : MarkerLayout
        A patch layout (``marker_kind = "patch"``): corner names ``PATCH_rRcC`` with positions.
    patches : sequence of Patch
        The patches to attach; each must have corners in the layout.
    model : HandModel
    betas : ndarray (10,), optional
        The subject's shape.
    subdivision : int
        Samples per square side.
    pitch : float, optional
        Side of the printed squares, metres (None: the patches as the layout places them, which grow with the hand).

    Returns
    -------
    PatchSkin

    Raises
    ------
    HandcapError
        A patch with fewer than 3 corners placed by the layout.
    """
    layout = layout.for_side(model.side)
    where = {m.name: m.position for m in layout.hand_markers if m.position is not None}
    template = model.forward(np.zeros(10)).vertices
    betas = np.zeros(10) if betas is None else np.asarray(betas, dtype=np.float64)
    rows, cols, grids = [], [], []
    for patch in patches:
        known = np.full((patch.rows + 1, patch.cols + 1, 3), np.nan)
        for r in range(patch.rows + 1):
            for c in range(patch.cols + 1):
                name = patch.corner_name(r, c, owner=False)
                if name in where:
                    known[r, c] = where[name]
        if (~np.isnan(known[..., 0])).sum() < 3:
            raise HandcapError(f"layout {layout.name!r} places fewer than 3 corners of patch {patch.name}; it "
                               "cannot be drawn")
        grids.append(patch_grid(patch, known[None])[0])  # rows -0.5, 0 .. R, R + 0.5 and the same columns
        rows.append(_fine(patch.rows, subdivision))
        cols.append(_fine(patch.cols, subdivision))
    names = tuple(f"{p.name}#{k}" for p, r, c in zip(patches, rows, cols) for k in range(len(r) * len(c)))
    scale = np.ones(len(patches))
    subject = None if pitch is None else model.forward(betas).vertices
    for step in range(PITCH_STEPS + 1 if pitch is not None else 1):
        samples = []
        for full, r, c, k, patch in zip(grids, rows, cols, scale, patches):  # scaled along the skin, not in space
            samples.append(_bilinear(full, patch.rows / 2 + k * (r - patch.rows / 2),
                                     patch.cols / 2 + k * (c - patch.cols / 2)).reshape(-1, 3))
        _, triangles, bary = closest_points_on_mesh(np.concatenate(samples), template, model.faces)
        attachment = MarkerAttachment(names, triangles, bary, np.full(len(triangles), layout.marker_radius), betas,
                                      model.name, model.side)
        if subject is not None and step < PITCH_STEPS:
            skin = PatchSkin(tuple(patches), tuple(rows), tuple(cols), attachment)
            scale *= pitch / np.array([np.mean(corner_sides(g, r, c))
                                       for g, r, c in zip(skin.grids(subject, model.faces), rows, cols)])
    return PatchSkin(tuple(patches), tuple(rows), tuple(cols), attachment)


def corner_sides(grid: np.ndarray, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
    """Distances between a sampled patch's adjacent corners (its samples at whole grid coordinates).

    Parameters
    ----------
    grid : ndarray (n_rows, n_cols, 3)
        One patch's samples (:meth:`PatchSkin.grids`), metres.
    rows, cols : ndarray
        Their grid coordinates.

    Returns
    -------
    ndarray (S,)
        Metres, along rows and along columns.
    """
    whole_r, whole_c = np.flatnonzero(rows == np.round(rows)), np.flatnonzero(cols == np.round(cols))
    whole_r, whole_c = whole_r[rows[whole_r] >= 0], whole_c[cols[whole_c] >= 0]
    corners = np.asarray(grid)[whole_r][:, whole_c]
    return np.r_[np.linalg.norm(np.diff(corners, axis=0), axis=-1).ravel(),
                 np.linalg.norm(np.diff(corners, axis=1), axis=-1).ravel()]


def _fine(n: int, subdivision: int) -> np.ndarray:
    """Grid coordinates -0.5 .. n + 0.5 in steps of 1 / subdivision (the integers included)."""
    inner = np.arange(0, n * subdivision + 1) / subdivision
    margin = np.arange(1, subdivision // 2 + 1) / subdivision
    return np.r_[-margin[::-1], inner, n + margin]


def _bilinear(full: np.ndarray, r: np.ndarray, c: np.ndarray) -> np.ndarray:
    """Points of a grid given at rows/cols -0.5, 0 .. n, n + 0.5, bilinearly between them, at (r, c)."""
    nodes_r = np.r_[-0.5, np.arange(full.shape[0] - 2), full.shape[0] - 2.5]
    nodes_c = np.r_[-0.5, np.arange(full.shape[1] - 2), full.shape[1] - 2.5]
    i = np.clip(np.searchsorted(nodes_r, r, side="right") - 1, 0, len(nodes_r) - 2)
    j = np.clip(np.searchsorted(nodes_c, c, side="right") - 1, 0, len(nodes_c) - 2)
    fr = ((r - nodes_r[i]) / (nodes_r[i + 1] - nodes_r[i]))[:, None, None]
    fc = ((c - nodes_c[j]) / (nodes_c[j + 1] - nodes_c[j]))[None, :, None]
    a = full[i][:, j]
    b = full[i][:, j + 1]
    d = full[i + 1][:, j]
    e = full[i + 1][:, j + 1]
    return (1 - fr) * ((1 - fc) * a + fc * b) + fr * ((1 - fc) * d + fc * e)
