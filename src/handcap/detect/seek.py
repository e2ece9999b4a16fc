"""A second look, in each image, at the white squares that the rig's other cameras or the camera's neighbouring
frames place where it named none.

The detector names a square only where its corner network found all four corners and they make a white square.
A square seen at a grazing angle, blurred, or small is often missed so in one image while other cameras, or the
same camera a frame before or after, name it. So each image is looked at again where such squares are expected:

- from the other cameras (with a rig): the named corners triangulated (:func:`~handcap.detect.views.known_corners`),
  every square of the template whose four corners are known is projected into the camera, mended by the affine map
  of the camera's own named corners (:func:`~handcap.detect.views.projected_squares`);
- from the neighbouring frames: every square the camera named whole in the frame before or after, mapped by the
  local motion of the corners named in both frames near it (:func:`~handcap.detect.motion.local_motion`); both
  frames must place it, and agree to :data:`~handcap.detect.naming.GATE_PX` (it is looked for at their mean).

The corner refiner (:mod:`~handcap.detect.refine`, all eight turns and mirrors) looks at the four expected corners
in the image as the detector searched it, and the square takes its tag where

- the refiner believes a corner at each of the four (:data:`~handcap.detect.refine.REFINED_THRESHOLD`, its own
  gate) and places each within :data:`SEEK_PX` of where it was expected;
- the four make a white square as the detector's own must (:func:`~handcap.detect.blocks.white_blocks`: white
  inside, darker across each side, each half of each side a printed edge);
- the square faces the camera (goes round the way the camera's read squares do), lies :data:`EDGE` pixels or more
  inside the image and has no side under :data:`MIN_SIDE` pixels;
- the camera did not read that tag in the frame, and none of the four corners is named otherwise
  (:class:`~handcap.detect.naming.Namer`).

A square hidden in this camera behind a finger shows no corner where it is expected, or the corners of the finger's
patch, which the image names already. Measured on ``benchmarks/views.py`` (README): on three takes of 13 cameras
the squares the other cameras place took the tags reported right from 90.2 to 91.9 % of the visible, one more
wrong among the 1,567 squares named.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree
from scipy.special import expit
from tqdm import tqdm

from handcap.detect.blocks import MIN_SIDE, white_blocks
from handcap.detect.motion import MIN_FIT, local_motion, named_pixels
from handcap.detect.naming import (GATE_PX, Namer, UnreadSquares, ViewNaming, image_index, signed_area, square_corners,
                                   turning)
from handcap.detect.response import linear_light
from handcap.detect.refine import BORDER, RADIUS, REFINED_THRESHOLD, refiner_views
from handcap.detect.views import known_corners, projected_squares

#: Farthest the refiner may place a corner from where it was expected, pixels.
SEEK_PX = 1.0
#: Least distance of a projected corner from the image's edge, pixels (the refiner's crop lies inside).
EDGE = RADIUS + BORDER
EMPTY = (np.zeros(0, int), set())  # an image that names nothing


def second_look(arrays: dict, pattern, refiner, frames, *, rig=None, sync=None,
                progress: bool | None = None) -> ViewNaming:
    """Look again where the other cameras or the neighbouring frames place squares an image named none of (module
    docstring).

    Parameters
    ----------
    arrays : dict of str to ndarray
        A detections file's arrays (after :func:`~handcap.detect.views.name_from_views`), cameras named as in
        ``rig``; frame ``t`` and ``t + 1`` of a camera are neighbours in time.
    pattern : Pattern
        The template that named the corners.
    refiner : CornerRefiner
    frames : callable
        ``frames(c)`` yields camera ``c``'s ``(frame, image)``, image (H, W) uint8 as the detector searched it
        (decoded to linear light, denoised: :func:`searched_frames`), frames numbered as in ``arrays``.
    rig : CameraRig, optional
        Calibrated cameras, metres; without it only the neighbouring frames are looked at.
    sync : Sync, optional
        Cameras not triggered together (:func:`~handcap.detect.views.name_from_views`).
    progress : bool, optional
        Progress bar over the cameras.

    Returns
    -------
    ViewNaming
        ``unread`` counts the squares looked for; ``what`` says how many of those named the other cameras placed.
    """
    arrays = dict(arrays)
    arrays.setdefault("block_from_views", np.zeros(len(arrays["block_text"]), bool))
    tags, corners = square_corners(pattern, arrays["marker_names"])
    source = "a second look where the other cameras or the neighbouring frames place squares"
    if not len(tags) or len(arrays["frame"]) == 0:
        return ViewNaming(arrays, 0, 0, 0, source=source, what="squares looked for")
    clocks = None
    if rig is not None and len(arrays["camera_names"]) >= 2:
        clocks, disagree = known_corners(arrays, rig, sync, progress)
        clocks = None if disagree is not None else clocks  # name_from_views said so already
    namer, looked, by_views = Namer(tags, corners), 0, 0  # by_views: squares named where the other cameras place them
    by_image, signs = image_index(arrays), turning(arrays)
    n_markers = len(arrays["marker_names"])
    for c in tqdm(range(len(arrays["camera_names"])), desc="second look", unit="camera", leave=False,
                  disable=None if progress is None else not progress):
        known = None if clocks is None else clocks(c)
        camera = None if known is None else rig[str(arrays["camera_names"][c])]
        if known is None and not any((c, f - 1) in by_image and (c, f + 1) in by_image for (k, f) in by_image
                                     if k == c):
            continue  # nothing to look for: its images are not read again (a single photo, say)
        for f, image in frames(c):
            mine, read = by_image.get((c, f), EMPTY)
            allowed = ~np.isin(tags, list(read))
            views = None if known is None or f >= len(known) else projected_squares(camera, known[f], arrays,
                                                                                   mine, allowed, corners)
            moved = _moved(named_pixels(arrays, mine, n_markers),
                           [named_pixels(arrays, by_image.get((c, o), EMPTY)[0], n_markers) for o in (f - 1, f + 1)],
                           corners, allowed)
            done = np.zeros(0, np.int64)
            looks = ((True, *views), (False, *moved)) if views is not None else ((False, *moved),)
            for from_views, squares, pixels in looks:  # the other cameras' first
                keep = _plausible(pixels, image.shape, signs.get(c, 1.0)) & ~np.isin(squares, done)
                squares, pixels, done = squares[keep], pixels[keep], np.r_[done, squares]
                looked += len(squares)
                found, placed, score = _found(refiner, image, pixels)
                if found.any():
                    before = namer.named
                    u = UnreadSquares(c, f, placed[found], score[found])
                    namer.take(u, {j: (s, np.arange(4)) for j, s in enumerate(squares[found])}, arrays, mine)
                    by_views += (namer.named - before) if from_views else 0
    named = namer.appended(arrays) if namer.named else arrays
    what = f"squares looked for ({by_views} of those named placed by the other cameras)"
    return ViewNaming(named, namer.named, len(namer.rows["frame"]), looked, namer.refused, source=source, what=what)


def searched_frames(detector, sources, responses):
    """``frames`` for :func:`second_look`: each camera's frames read again, as ``detector`` searched them.

    Parameters
    ----------
    detector : Detector
    sources : sequence of FrameSource
        One per camera, as detected.
    responses : sequence of str
        Each source's response as the detection chose it (``linear`` or ``srgb``).

    Returns
    -------
    callable
        ``frames(c)`` yields ``(frame, image (H, W) uint8)``.
    """
    def frames(c: int):
        for t, image in sources[c].frames():
            yield t, detector.searched(linear_light(image) if responses[c] == "srgb" else image)[0]

    return frames


def _moved(here: np.ndarray, others: list, corners: np.ndarray, allowed: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The ``allowed`` squares the camera named whole in a neighbouring frame (``others``: each frame's named corners
    by marker (M, 2), NaN where none), mapped into this frame by the local motion of the corners both frames name
    (``here``), where both neighbours place it and agree to the gate: at their mean. Indices (S,), corners
    (S, 4, 2), pixels."""
    placed = [{}, {}]
    named_here = np.isfinite(here).all(axis=1)
    for guess, there in zip(placed, others):
        named_there = np.isfinite(there).all(axis=1)
        common = np.flatnonzero(named_here & named_there)
        whole = np.flatnonzero(named_there[corners].all(axis=1) & allowed)
        if len(common) < MIN_FIT or not len(whole):
            continue
        tree = cKDTree(there[common])
        for s in whole:
            fit = local_motion(tree, common, there[corners[s]], there, here)
            if fit is not None:
                guess[int(s)] = np.c_[there[corners[s]], np.ones(4)] @ fit
    before, after = placed
    agreed = {s: (before[s] + after[s]) / 2 for s in set(before) & set(after)
              if np.linalg.norm(before[s] - after[s], axis=1).max() <= GATE_PX}
    squares = np.array(sorted(agreed), dtype=np.int64)
    return squares, np.array([agreed[s] for s in squares]).reshape(-1, 4, 2)


def _plausible(pixels: np.ndarray, shape, sign: float) -> np.ndarray:
    """Which expected squares (S, 4, 2) lie :data:`EDGE` inside the image, face the camera (go round as ``sign``
    says its read squares do) and have no side under :data:`MIN_SIDE` pixels (S,)."""
    h, w = shape[:2]
    inside = ((pixels >= EDGE).all(axis=(1, 2)) & (pixels[..., 0] <= w - 1 - EDGE).all(axis=1)
              & (pixels[..., 1] <= h - 1 - EDGE).all(axis=1))
    sides = np.linalg.norm(np.roll(pixels, -1, axis=1) - pixels, axis=2).min(axis=1)
    return inside & (signed_area(pixels) * sign > 0) & (sides >= MIN_SIDE)


def _found(refiner, image: np.ndarray, pixels: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Which squares (S,) have a corner the refiner believes within :data:`SEEK_PX` of each of their four expected
    corners ``pixels`` (S, 4, 2), where it places them (S, 4, 2), pixels, and its probabilities (S, 4)."""
    if not len(pixels):
        return np.zeros(0, bool), pixels, np.zeros((0, 4))
    centres, back = np.unique(np.rint(pixels.reshape(-1, 2)).astype(int), axis=0, return_inverse=True)
    logit, offset = refiner_views(refiner, image, centres)
    placed = (centres + offset)[back.ravel()].reshape(pixels.shape)
    score = expit(logit)[back.ravel()].reshape(pixels.shape[:2])
    ok = ((np.linalg.norm(placed - pixels, axis=-1) <= SEEK_PX) & (score >= REFINED_THRESHOLD)).all(axis=1)
    # As the detector's own squares: white inside, darker across each side, each half of each side a printed edge.
    sure = np.flatnonzero(ok)
    white, _ = white_blocks(image, placed[sure].reshape(-1, 2), np.arange(4 * len(sure)).reshape(-1, 4))
    ok[:] = False
    ok[sure[white[:, 0] // 4]] = True
    return ok, placed, score
