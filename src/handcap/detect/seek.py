"""A second look, in each camera, at the white squares the rig's other cameras place where it named none.

The detector names a square only where its corner network found all four corners and they make a white square.
A square seen at a grazing angle, blurred, or small is often missed so in one camera while other cameras name it.
Once the named corners are triangulated (:func:`~handcap.detect.views.known_corners`), every square of the template
whose four corners are known is projected into each camera (mended by the affine map of the camera's own named
corners, :func:`~handcap.detect.views.local_fit`), and where that camera names no such square the corner refiner
(:mod:`~handcap.detect.refine`, all eight turns and mirrors) looks at the four projected corners in the image as the
detector searched it. The square takes its tag where

- the refiner believes a corner at each of the four (:data:`~handcap.detect.refine.REFINED_THRESHOLD`, its own
  gate) and places each within :data:`SEEK_PX` of its projection;
- the four make a white square as the detector's own must (:func:`~handcap.detect.blocks.white_blocks`: white
  inside, darker across each side, each half of each side a printed edge);
- the square faces the camera (goes round the way the camera's read squares do), lies :data:`EDGE` pixels or more
  inside the image and has no side under :data:`MIN_SIDE` pixels;
- the camera did not read that tag in the frame, and none of the four corners is named otherwise
  (:class:`~handcap.detect.naming.Namer`).

A square hidden in this camera behind a finger shows no corner at its projections, or the corners of the finger's
patch, which the image names already. Measured on ``benchmarks/views.py``'s first take (13 cameras, 143 images
the networks never saw): after both namings 7,024 of 7,812 visible tags were reported right; 312 of the 788 left
were squares whose four corners the other cameras place, and this takes 215 of them, none wrong, their corners a
median 0.43 px from the truth at the farthest of the four.
"""

from __future__ import annotations

import numpy as np
from scipy.special import expit
from tqdm import tqdm

from handcap.detect.blocks import MIN_SIDE, white_blocks
from handcap.detect.naming import Namer, UnreadSquares, ViewNaming, image_index, signed_area, square_corners, turning
from handcap.detect.response import linear_light
from handcap.detect.refine import BORDER, RADIUS, REFINED_THRESHOLD, refiner_views
from handcap.detect.views import known_corners, local_fit

#: Farthest the refiner may place a corner from its projection, pixels.
SEEK_PX = 1.0
#: Least distance of a projected corner from the image's edge, pixels (the refiner's crop lies inside).
EDGE = RADIUS + BORDER


def seek_from_views(arrays: dict, rig, pattern, refiner, frames, *, sync=None,
                    progress: bool | None = None) -> ViewNaming:
    """Look again where the other cameras place squares this camera named none of (module docstring).

    Parameters
    ----------
    arrays : dict of str to ndarray
        A detections file's arrays (after :func:`~handcap.detect.views.name_from_views`), cameras named as in
        ``rig``.
    rig : CameraRig
        Calibrated cameras, metres.
    pattern : Pattern
        The template that named the corners.
    refiner : CornerRefiner
    frames : callable
        ``frames(c)`` yields camera ``c``'s ``(frame, image)``, image (H, W) uint8 as the detector searched it
        (decoded to linear light, denoised: :meth:`~handcap.detect.pipeline.Detector.searched`), frames numbered
        as in ``arrays``.
    sync : Sync, optional
        Cameras not triggered together (:func:`~handcap.detect.views.name_from_views`).
    progress : bool, optional
        Progress bar over the images.

    Returns
    -------
    ViewNaming
        ``unread`` counts the squares looked at.
    """
    arrays = dict(arrays)
    arrays.setdefault("block_from_views", np.zeros(len(arrays["block_text"]), bool))
    tags, corners = square_corners(pattern, arrays["marker_names"])
    source, what = "a second look where the other cameras place squares", "squares looked for"
    n_cameras = len(arrays["camera_names"])
    if not len(tags) or len(arrays["frame"]) == 0 or n_cameras < 2:
        return ViewNaming(arrays, 0, 0, 0, source=source, what=what)
    clocks, disagree = known_corners(arrays, rig, sync, progress)
    if disagree is not None:  # name_from_views said so already
        return ViewNaming(arrays, 0, 0, 0, source=source, what=what)
    namer, looked = Namer(tags, corners), 0
    by_image, signs = image_index(arrays), turning(arrays)
    hidden = None if progress is None else not progress
    for c in tqdm(range(n_cameras), desc="second look", unit="camera", disable=hidden, leave=False):
        known = clocks(c)
        if known is None:
            continue
        camera = rig[str(arrays["camera_names"][c])]
        for f, image in frames(c):
            if f >= len(known):
                continue
            mine, read = by_image.get((c, f), (np.zeros(0, int), set()))
            squares, pixels = _expected(camera, known[f], arrays, mine, read, tags, corners, signs.get(c, 1.0),
                                        image.shape)
            looked += len(squares)
            found, placed, score = _found(refiner, image, pixels)
            if found.any():
                u = UnreadSquares(c, f, placed[found], score[found])
                namer.take(u, {k: (s, np.arange(4)) for k, s in enumerate(squares[found])}, arrays, mine)
    named = namer.appended(arrays) if namer.named else arrays
    return ViewNaming(named, namer.named, len(namer.rows["frame"]), looked, namer.refused, source=source, what=what)


def searched_frames(detector, sources, responses):
    """``frames`` for :func:`seek_from_views`: each camera's frames read again, as ``detector`` searched them.

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


def _expected(camera, now: np.ndarray, arrays: dict, mine: np.ndarray, read: set, tags, corners, sign: float,
              shape) -> tuple[np.ndarray, np.ndarray]:
    """The template squares the camera should see in a frame and named none of: their indices (S,) and where their
    corners lie (S, 4, 2), pixels, in reading order."""
    take = np.flatnonzero(~np.isin(tags, list(read)))
    points = now[corners[take]]
    seen = np.isfinite(points).all(axis=(1, 2))
    take, points = take[seen], points[seen]
    if not len(take):
        return take, np.zeros((0, 4, 2))
    pixels, _ = camera.project(points)
    fit = local_fit(camera, now[arrays["marker"][mine]], arrays["xy"][mine])
    if fit is not None:
        pixels = np.concatenate([pixels, np.ones(pixels.shape[:-1] + (1,))], axis=-1) @ fit
    h, w = shape[:2]
    inside = ((pixels >= EDGE).all(axis=(1, 2)) & (pixels[..., 0] <= w - 1 - EDGE).all(axis=1)
              & (pixels[..., 1] <= h - 1 - EDGE).all(axis=1))
    sides = np.linalg.norm(np.roll(pixels, -1, axis=1) - pixels, axis=2).min(axis=1)
    keep = inside & (signed_area(pixels) * sign > 0) & (sides >= MIN_SIDE)
    return take[keep], pixels[keep]


def _found(refiner, image: np.ndarray, pixels: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Which squares (S,) have a corner the refiner believes within :data:`SEEK_PX` of each of their four projected
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
