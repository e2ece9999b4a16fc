"""Naming a camera's unread white squares from the other cameras of a calibrated rig.

A white square whose four corners one camera found but whose tag it could not read (too small, blurred, a glyph
cut by a finger's edge) is often read by other cameras at the same moment. The corners those cameras name are
triangulated (:func:`~handcap.multiview.reconstruct.triangulate_detections`, at least two views that agree to
:data:`AGREE_PX`, or to :data:`SPREAD` times the take's median where its rig agrees less well), every square of the
template whose four corners are known is projected into the camera, and an unread square takes a square's tag where

- each of its four corners lies within :data:`~handcap.detect.naming.GATE_PX` of that square's projected corners
  (in one of the four turns, going round the same way as the camera's read squares do: a square facing away is
  never taken);
- no other square's projection comes within :data:`~handcap.detect.naming.MARGIN` times the gate of it, and no
  other unread square takes the same tag;
- the camera did not read that tag elsewhere in the frame, and none of the four corners is named otherwise
  (:mod:`~handcap.detect.naming`).

A rig calibrated to half a pixel puts every projection that far off, mostly the same way over the hand: so each
image's projections are first mapped by the affine map that takes the projections of the corners the camera named
in that image onto where it named them (:func:`_local_fit`; with :data:`MIN_FIT` of them or more).

A square that takes a tag gets the template's names for its corners, and the detections file one block row more,
marked in ``block_from_views``. The squares named so give the corners more views, so the naming runs again
(:data:`PASSES`). Cameras that were not triggered together disagree by more than the gate: nothing is taken
where the views do not agree, and a warning says so.
"""

from __future__ import annotations

import numpy as np
from tqdm import tqdm

from handcap.detect.naming import (Namer, ViewNaming, affine_map, image_index, match_squares, signed_area,
                                   square_corners, turning)
from handcap.multiview.detections import Detections
from handcap.multiview.reconstruct import triangulate_detections

#: Largest reprojection error of a corner triangulated from the named views, pixels, for it to be projected.
AGREE_PX = 1.0
#: A corner counts as placed where its reprojection error is within this many times the take's median too (a rig
#: calibrated less well than :data:`AGREE_PX` puts every corner farther).
SPREAD = 2.5
#: Least named corners of an image with which its projections are mended (:func:`_local_fit`).
MIN_FIT = 8
#: Rounds of triangulating and naming.
PASSES = 2
#: The cameras' views are said not to agree where the named corners' median reprojection error is over this, pixels
#: (or where fewer than :data:`AGREEING` of the corners two cameras or more named triangulate within twice it).
DISAGREE_PX = 2.0
AGREEING = 0.5


def name_from_views(arrays: dict, unread, rig, pattern, *, passes: int = PASSES,
                    progress: bool | None = None) -> ViewNaming:
    """Name unread white squares where the rig's other cameras place a square of the template (module docstring).

    Parameters
    ----------
    arrays : dict of str to ndarray
        A detections file's arrays (:mod:`~handcap.detect.capture`), cameras named as in ``rig``.
    unread : sequence of UnreadSquares
    rig : CameraRig
        Calibrated cameras, metres.
    pattern : Pattern
        The template that named the corners.
    passes : int
        Rounds of triangulating and naming.
    progress : bool, optional
        Progress bars of the triangulation.

    Returns
    -------
    ViewNaming
    """
    arrays = dict(arrays)
    arrays.setdefault("block_from_views", np.zeros(len(arrays["block_text"]), bool))
    tags, corners = square_corners(pattern, arrays["marker_names"])
    total = sum(len(u.xy) for u in unread)
    left = [u for u in unread if len(u.xy)]
    named = added = refused = 0
    warnings = []
    for _ in range(passes):
        if not left or not len(tags) or len(arrays["frame"]) == 0 or len(arrays["camera_names"]) < 2:
            break
        known, disagree = _known(arrays, rig, progress)
        if disagree is not None:
            warnings.append(disagree)
            break
        namer = Namer(tags, corners)
        left = _match_all(arrays, left, known, rig, namer, progress)
        # A refused square stays unread and is refused again in the next pass: counted once, in the last.
        named, added, refused = named + namer.named, added + len(namer.rows["frame"]), namer.refused
        if not namer.named:
            break
        arrays = namer.appended(arrays)
    return ViewNaming(arrays, named, added, total, refused, tuple(warnings), tuple(left))


def _known(arrays: dict, rig, progress) -> tuple[np.ndarray, str | None]:
    """The named corners triangulated where their views agree (T, M, 3), metres (NaN elsewhere), and a warning
    where the views of most corners disagree (else None)."""
    detections = Detections(arrays["camera_names"], arrays["marker_names"], arrays["frame"], arrays["camera"],
                            arrays["marker"], arrays["xy"], arrays["score"], arrays["rate"], int(arrays["n_frames"]))
    tri = triangulate_detections(detections, rig, min_views=2, threshold_px=2 * DISAGREE_PX, progress=progress)
    seen = np.zeros((detections.n_frames, len(detections.marker_names), len(detections.camera_names)), bool)
    seen[detections.frame, detections.marker, detections.camera] = True
    twice = int((seen.sum(axis=2) >= 2).sum())
    error = tri.error_px[np.isfinite(tri.error_px)]
    median = float(np.median(error)) if len(error) else np.inf
    if twice and (len(error) < AGREEING * twice or median > DISAGREE_PX):
        return tri.positions, (f"the cameras' views of the named corners disagree ({len(error)} of the {twice} corners "
                               f"two cameras or more named agree to {2 * DISAGREE_PX:g} px, median {median:.1f} px): "
                               "no unread square was named from the other cameras. Cameras not triggered together? "
                               "triangulate --sync auto finds their offsets. Or the rig is not the one that filmed "
                               "the take")
    agree = np.isfinite(tri.error_px) & (tri.error_px <= max(AGREE_PX, SPREAD * median))
    return np.where(agree[..., None], tri.positions, np.nan), None


def _match_all(arrays: dict, unread, known: np.ndarray, rig, namer: Namer, progress=None) -> list:
    """Match every image's unread squares to the projections of the known squares; ``namer`` takes the matches.
    Returns the squares still unread."""
    tags, corners = namer.tags, namer.corners
    still = []
    by_image = image_index(arrays)
    signs = turning(arrays)
    for u in tqdm(unread, desc="views", unit="image", disable=None if progress is None else not progress,
                  leave=False):
        if u.frame >= len(known):
            still.append(u)
            continue
        camera = rig[str(arrays["camera_names"][u.camera])]
        mine, read = by_image.get((u.camera, u.frame), (np.zeros(0, int), set()))
        take = ~np.isin(tags, list(read))
        points = known[u.frame][corners[take]]
        seen = np.isfinite(points).all(axis=(1, 2))
        pixels, _ = camera.project(points[seen])
        fit = _local_fit(camera, known[u.frame][arrays["marker"][mine]], arrays["xy"][mine])
        if fit is not None:  # where the rig's small errors put the camera's projections, mended on its named corners
            pixels = np.concatenate([pixels, np.ones(pixels.shape[:-1] + (1,))], axis=-1) @ fit
        facing = signed_area(pixels) * signs.get(u.camera, 1.0) > 0
        match = match_squares(u.xy, pixels[facing], signs.get(u.camera, 1.0))
        square_ids = np.flatnonzero(take)[seen][facing]
        left = namer.take(u, {k: (square_ids[s], order) for k, (s, order) in match.items()}, arrays, mine)
        if left is not None:
            still.append(left)
    return still


def _local_fit(camera, points: np.ndarray, detected: np.ndarray) -> np.ndarray | None:
    """The affine map (3, 2) that takes the camera's projections of ``points`` (N, 3, metres; NaN where unknown) to
    where it named them (``detected`` (N, 2), pixels), fitted again without the points over three times the median
    distance from it; None with fewer than :data:`MIN_FIT` points."""
    pixels, _ = camera.project(points)
    ok = np.isfinite(pixels).all(axis=1)
    fit = affine_map(pixels[ok], detected[ok], MIN_FIT, rounds=2)
    return None if fit is None else fit[0]
