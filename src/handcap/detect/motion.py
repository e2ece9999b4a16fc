"""Naming a camera's unread white squares from its neighbouring frames.

A square a camera could not read in one frame (blurred by a fast finger, a glyph cut by an occluder's edge) it has
often read in the frame before or after. Between two frames the patches around it move nearly as one piece, so the
corners the camera named in both frames near the unread square (within :data:`RADIUS` times its longest side) give
the local motion: the affine map that takes their pixels in the other frame to their pixels in this one (least
squares, :data:`MIN_FIT` corners or more, and used only where it fits them to :data:`FIT_PX` median). Every square
the camera named whole in the other frame (its four corners) is mapped so, and an unread square takes one's tag under
the tests of the other cameras' naming (:func:`~handcap.detect.naming.match_squares`: within the gate in one of four
turns, going round as the camera's read squares do, no other mapped square near; the tag not read elsewhere in the
frame, its corners not named otherwise). Where the frame before and the frame after name an unread square
differently, neither is taken.

It needs neither a rig nor more than one camera: a single video of a patched hand names more corners so. At 4 frames
a second (``handcap demo --images``) the fingers move too far between frames and it names few squares; at 20 and
more it names a good share of what the reader missed (README, ``benchmarks/views.py``). The blocks it names are
marked in ``block_from_views`` like those the other cameras name.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree
from tqdm import tqdm

from handcap.detect.naming import Namer, ViewNaming, affine_map, image_index, match_squares, square_corners, turning

#: The corners of both frames within this many times the unread square's longest side fit the local motion.
RADIUS = 3.0
#: Least corners named in both frames near the square for the local motion.
MIN_FIT = 6
#: Largest median distance of those corners from the fitted motion, pixels.
FIT_PX = 0.5


def name_from_frames(arrays: dict, unread, pattern, *, progress: bool | None = None) -> ViewNaming:
    """Name unread white squares where the camera's neighbouring frames place a square of the template (module
    docstring).

    Parameters
    ----------
    arrays : dict of str to ndarray
        A detections file's arrays (:mod:`~handcap.detect.capture`): frame ``t`` and ``t + 1`` of a camera are
        neighbours in time.
    unread : sequence of UnreadSquares
    pattern : Pattern
        The template that named the corners.
    progress : bool, optional
        A progress bar over the images.

    Returns
    -------
    ViewNaming
        ``left`` holds the squares still unread.
    """
    arrays = dict(arrays)
    arrays.setdefault("block_from_views", np.zeros(len(arrays["block_text"]), bool))
    tags, corners = square_corners(pattern, arrays["marker_names"])
    total = sum(len(u.xy) for u in unread)
    namer, left = Namer(tags, corners), []
    if len(tags) and len(arrays["frame"]):
        by_image, signs = image_index(arrays), turning(arrays)
        empty = (np.zeros(0, int), set())
        for u in tqdm([u for u in unread if len(u.xy)], desc="frames", unit="image", leave=False,
                      disable=None if progress is None else not progress):
            mine, read = by_image.get((u.camera, u.frame), empty)
            here = named_pixels(arrays, mine, len(arrays["marker_names"]))
            found = {}
            for other in (u.frame - 1, u.frame + 1):
                there = named_pixels(arrays, by_image.get((u.camera, other), empty)[0], len(arrays["marker_names"]))
                for k, (square, order) in _matches(u, here, there, corners, ~np.isin(tags, list(read)),
                                                   signs.get(u.camera, 1.0)).items():
                    if found.get(k, (square,))[0] != square:
                        found[k] = (-1, order)  # the two frames disagree
                    else:
                        found[k] = (square, order)
            rest = namer.take(u, {k: v for k, v in found.items() if v[0] >= 0}, arrays, mine)
            if rest is not None:
                left.append(rest)
        arrays = namer.appended(arrays) if namer.named else arrays
    else:
        left = [u for u in unread if len(u.xy)]
    return ViewNaming(arrays, namer.named, len(namer.rows["frame"]), total, namer.refused, (), tuple(left),
                      source="the neighbouring frames")


def named_pixels(arrays: dict, rows: np.ndarray, markers: int) -> np.ndarray:
    """An image's named corners by marker.

    Parameters
    ----------
    arrays : dict of str to ndarray
        A detections file's arrays.
    rows : ndarray (N,) int
        The rows of the image's named corners.
    markers : int
        How many markers the file names.

    Returns
    -------
    ndarray (markers, 2)
        Pixels; NaN where the image names none.
    """
    out = np.full((markers, 2), np.nan)
    out[arrays["marker"][rows]] = arrays["xy"][rows]
    return out


def _matches(u, here: np.ndarray, there: np.ndarray, corners: np.ndarray, allowed: np.ndarray, sign: float) -> dict:
    """``u``'s quads that take a square the other frame named whole (``there``), mapped by the local motion from the
    corners both frames name (``here``): {quad: (square, order)}."""
    named_here, named_there = np.isfinite(here).all(axis=1), np.isfinite(there).all(axis=1)
    common = np.flatnonzero(named_here & named_there)
    whole = np.flatnonzero(named_there[corners].all(axis=1) & allowed)
    if len(common) < MIN_FIT or not len(whole):
        return {}
    tree = cKDTree(here[common])
    squares = np.concatenate([there[corners[whole]], np.ones((len(whole), 4, 1))], axis=-1)  # (S, 4, 3)
    out = {}
    for k, quad in enumerate(u.xy):
        fit = local_motion(tree, common, quad, there, here)
        if fit is None:
            continue
        match = match_squares(quad[None], squares @ fit, sign)
        if 0 in match:
            square, order = match[0]
            out[k] = (int(whole[square]), order)
    return out


def local_motion(tree: cKDTree, common: np.ndarray, quad: np.ndarray, there: np.ndarray,
                 here: np.ndarray) -> np.ndarray | None:
    """The local motion around a square from another frame to this one (module docstring).

    Parameters
    ----------
    tree : cKDTree
        Over the pixels of the corners ``common`` in the frame ``quad`` lies in.
    common : ndarray (K,) int
        The markers both frames name.
    quad : ndarray (4, 2)
        The square, pixels.
    there, here : ndarray (M, 2)
        Each frame's named corners by marker, pixels (NaN where it names none).

    Returns
    -------
    ndarray (3, 2) or None
        The affine map from ``there`` to ``here`` (pixels as rows ``(x, y, 1)`` times it), fitted on the corners
        within :data:`RADIUS` times the square's longest side; None with fewer than :data:`MIN_FIT` of them or where it
        fits them worse than :data:`FIT_PX` median.
    """
    side = float(np.linalg.norm(np.roll(quad, -1, axis=0) - quad, axis=1).max())
    near = common[tree.query_ball_point(quad.mean(axis=0), RADIUS * side)]
    if len(near) < MIN_FIT:
        return None
    fit, distance = affine_map(there[near], here[near], MIN_FIT)
    return fit if distance <= FIT_PX else None
