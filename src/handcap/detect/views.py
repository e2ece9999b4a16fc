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
in that image onto where it named them (:func:`local_fit`; with :data:`MIN_FIT` of them or more).

A square that takes a tag gets the template's names for its corners, and the detections file one block row more,
marked in ``block_from_views``. The squares named so give the corners more views, so the naming runs again
(:data:`PASSES`). Cameras that were not triggered together disagree by more than the gate: nothing is taken
where the views do not agree, and a warning says so. Given each camera's time offset (a
:class:`~handcap.multiview.sync.Sync`), each camera's squares are named from corners triangulated at its own
moments: the other cameras' named corners are put on its frames, between their two frames around each moment
(:func:`~handcap.multiview.offsets.shift_detections`), and triangulated there (:class:`Clocks`). The affine map above
mends what the interpolation misses of the hand's motion.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
from tqdm import tqdm

from handcap.detect.naming import (Namer, ViewNaming, affine_map, image_index, match_squares, signed_area,
                                   square_corners, turning)
from handcap.core.errors import HandcapError
from handcap.multiview.detections import detections_of
from handcap.multiview.offsets import shift_detections
from handcap.multiview.reconstruct import triangulate_detections

#: Largest reprojection error of a corner triangulated from the named views, pixels, for it to be projected.
AGREE_PX = 1.0
#: A corner counts as placed where its reprojection error is within this many times the take's median too (a rig
#: calibrated less well than :data:`AGREE_PX` puts every corner farther).
SPREAD = 2.5
#: Least named corners of an image with which its projections are mended (:func:`local_fit`).
MIN_FIT = 8
#: Rounds of triangulating and naming.
PASSES = 2
#: The cameras' views are said not to agree where the named corners' median reprojection error is over this, pixels
#: (or where fewer than :data:`AGREEING` of the corners two cameras or more named triangulate within twice it).
DISAGREE_PX = 2.0
AGREEING = 0.5


def name_from_views(arrays: dict, unread, rig, pattern, *, passes: int = PASSES, progress: bool | None = None,
                    sync=None) -> ViewNaming:
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
    sync : Sync, optional
        Cameras not triggered together (:mod:`handcap.multiview.sync`): each camera's offset (and drift) in frames
        of the detections, cameras as in ``arrays``. None: the cameras are synchronised.

    Returns
    -------
    ViewNaming

    Raises
    ------
    HandcapError
        For a ``sync`` of other cameras than the detections'.
    """
    if sync is not None and tuple(sync.camera_names) != tuple(str(n) for n in arrays["camera_names"]):
        raise HandcapError(f"the offsets are of cameras {', '.join(sync.camera_names)}, and the detections' are "
                           f"{', '.join(str(n) for n in arrays['camera_names'])}")
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
        clocks, disagree = known_corners(arrays, rig, sync, progress)
        if disagree is not None:
            warnings.append(disagree)
            break
        namer = Namer(tags, corners)
        left = _match_all(arrays, left, clocks, rig, namer, progress)
        # A refused square stays unread and is refused again in the next pass: counted once, in the last.
        named, added, refused = named + namer.named, added + len(namer.rows["frame"]), namer.refused
        if not namer.named:
            break
        arrays = namer.appended(arrays)
    return ViewNaming(arrays, named, added, total, refused, tuple(warnings), tuple(left))


def known_corners(arrays: dict, rig, sync=None, progress: bool | None = None) -> tuple[Clocks, str | None]:
    """The corners the cameras named, triangulated where their views agree, on each camera's frames.

    Parameters
    ----------
    arrays : dict of str to ndarray
        A detections file's arrays, cameras named as in ``rig``.
    rig : CameraRig
    sync : Sync, optional
        The cameras' offsets (:func:`name_from_views`); None: synchronised.
    progress : bool, optional

    Returns
    -------
    clocks : Clocks
        Camera index -> its frames' known corners (T, M, 3), metres, NaN where unknown.
    warning : str or None
        Where the views of most named corners disagree (nothing should be named from them), why.

    Raises
    ------
    HandcapError
        Where ``sync`` gives no camera an offset.
    """
    timed = [] if sync is None else np.flatnonzero(np.isfinite(sync.offsets))
    if sync is not None and not len(timed):
        raise HandcapError("no camera has an offset: nothing to name the squares from")
    first = 0 if sync is None else int(timed[0])
    known, disagree = _known(arrays, rig, progress, rebased(sync, first))
    return Clocks(arrays, rig, sync, (first, known), progress), disagree


def rebased(sync, camera: int):
    """``sync`` (a :class:`~handcap.multiview.sync.Sync`) counted on ``camera``'s frames, or None where it is None.

    Camera j's frame h shows the reference's frame ``h (1 + d_j) + o_j``; on the clock of camera c, whose frame f
    shows ``f (1 + d_c) + o_c``, that is c's frame ``h + (o_j - o_c) / (1 + d_c) + h (d_j - d_c) / (1 + d_c)``.

    Parameters
    ----------
    sync : Sync or None
    camera : int
        Index into ``sync.camera_names``.
    """
    if sync is None:
        return None
    drift = np.zeros(len(sync.offsets)) if sync.drift is None else np.asarray(sync.drift, float)
    rate = 1.0 + drift[camera]
    return replace(sync, offsets=(np.asarray(sync.offsets, float) - sync.offsets[camera]) / rate,
                   drift=None if sync.drift is None else (drift - drift[camera]) / rate,
                   reference=sync.camera_names[camera])


class Clocks:
    """The known corners on each camera's own frames (T, M, 3): those of ``first`` for all where the cameras
    are synchronised (``sync`` None), else triangulated again for each camera on its clock (:func:`rebased`); the
    last camera asked for is kept.

    Parameters
    ----------
    arrays : dict of str to ndarray
        The detections file's arrays.
    rig : CameraRig
    sync : Sync or None
    first : (int, ndarray (T, M, 3))
        A camera with an offset, and the known corners on its frames, metres.
    progress : bool, optional
    """

    def __init__(self, arrays: dict, rig, sync, first: tuple, progress=None):
        self.arrays, self.rig, self.sync, self.progress = arrays, rig, sync, progress
        self.camera, self.known = first

    def __call__(self, camera: int) -> np.ndarray | None:
        """The known corners on ``camera``'s frames (T, M, 3), metres; None for a camera without an offset.

        Parameters
        ----------
        camera : int
        """
        if self.sync is None or camera == self.camera:
            return self.known
        self.camera = camera
        self.known = None
        if np.isfinite(self.sync.offsets[camera]):
            self.known = _known(self.arrays, self.rig, self.progress, rebased(self.sync, camera))[0]
        return self.known


def _known(arrays: dict, rig, progress, sync=None) -> tuple[np.ndarray, str | None]:
    """The named corners triangulated where their views agree (T, M, 3), metres (NaN elsewhere), on the frames of
    ``sync``'s reference, and a warning where the views of most corners disagree (else None)."""
    detections = detections_of(arrays)
    if sync is not None:
        detections, _ = shift_detections(detections, sync.offsets, sync.drift)
    tri = triangulate_detections(detections, rig, min_views=2, threshold_px=2 * DISAGREE_PX, progress=progress)
    seen = np.zeros((detections.n_frames, len(detections.marker_names), len(detections.camera_names)), bool)
    seen[detections.frame, detections.marker, detections.camera] = True
    twice = int((seen.sum(axis=2) >= 2).sum())
    error = tri.error_px[np.isfinite(tri.error_px)]
    median = float(np.median(error)) if len(error) else np.inf
    if twice and (len(error) < AGREEING * twice or median > DISAGREE_PX):
        return tri.positions, (f"the cameras' views of the named corners disagree ({len(error)} of the {twice} corners "
                               f"two cameras or more named agree to {2 * DISAGREE_PX:g} px, median {median:.1f} px): "
                               "no unread square was named from the other cameras. "
                               + ("Are the offsets (--sync) right? " if sync is not None else
                                  "Cameras not triggered together? detect --sync auto finds their offsets. ")
                               + "Or the rig is not the one that filmed the take")
    agree = np.isfinite(tri.error_px) & (tri.error_px <= max(AGREE_PX, SPREAD * median))
    return np.where(agree[..., None], tri.positions, np.nan), None


def _match_all(arrays: dict, unread, clocks: Clocks, rig, namer: Namer, progress=None) -> list:
    """Match every image's unread squares to the projections of the known squares; ``namer`` takes the matches.
    Returns the squares still unread."""
    tags, corners = namer.tags, namer.corners
    still = []
    by_image = image_index(arrays)
    signs = turning(arrays)
    if clocks.sync is not None:  # camera by camera: one triangulation each
        unread = sorted(unread, key=lambda u: u.camera)
    for u in tqdm(unread, desc="views", unit="image", disable=None if progress is None else not progress,
                  leave=False):
        known = clocks(u.camera)
        if known is None or u.frame >= len(known):
            still.append(u)
            continue
        now = known[u.frame]
        camera = rig[str(arrays["camera_names"][u.camera])]
        mine, read = by_image.get((u.camera, u.frame), (np.zeros(0, int), set()))
        square_ids, pixels = projected_squares(camera, now, arrays, mine, ~np.isin(tags, list(read)), corners)
        facing = signed_area(pixels) * signs.get(u.camera, 1.0) > 0
        match = match_squares(u.xy, pixels[facing], signs.get(u.camera, 1.0))
        square_ids = square_ids[facing]
        left = namer.take(u, {k: (square_ids[s], order) for k, (s, order) in match.items()}, arrays, mine)
        if left is not None:
            still.append(left)
    return still


def projected_squares(camera, now: np.ndarray, arrays: dict, mine: np.ndarray, allowed: np.ndarray,
                      corners: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Where the ``allowed`` squares whose four corners are known lie in a camera's image.

    Projected, then mended by the affine map of the camera's own named corners (:func:`local_fit`): where the rig's
    small errors put the projections.

    Parameters
    ----------
    camera : Camera
    now : ndarray (M, 3)
        The known corners at the image's moment, metres; NaN where unknown.
    arrays : dict of str to ndarray
        The detections file's arrays.
    mine : ndarray (N,) int
        The rows of the image's named corners.
    allowed : ndarray (S,) bool
        Which of the template's squares to place.
    corners : ndarray (S, 4) int
        The squares' markers in reading order (:func:`~handcap.detect.naming.square_corners`).

    Returns
    -------
    squares : ndarray (S',) int
        The squares placed (indices into ``corners``).
    pixels : ndarray (S', 4, 2)
        Their corners, pixels, in reading order.
    """
    take = np.flatnonzero(allowed)
    points = now[corners[take]]
    seen = np.isfinite(points).all(axis=(1, 2))
    take, points = take[seen], points[seen]
    if not len(take):
        return take, np.zeros((0, 4, 2))
    pixels, _ = camera.project(points)
    fit = local_fit(camera, now[arrays["marker"][mine]], arrays["xy"][mine])
    if fit is not None:
        pixels = np.concatenate([pixels, np.ones(pixels.shape[:-1] + (1,))], axis=-1) @ fit
    return take, pixels


def local_fit(camera, points: np.ndarray, detected: np.ndarray) -> np.ndarray | None:
    """The affine map that takes the camera's projections of points to where it named them.

    Fitted again without the points over three times the median distance from it.

    Parameters
    ----------
    camera : Camera
    points : ndarray (N, 3)
        Metres; NaN where unknown.
    detected : ndarray (N, 2)
        Where the camera named them, pixels.

    Returns
    -------
    ndarray (3, 2) or None
        Pixels as rows ``(x, y, 1)`` times it; None with fewer than :data:`MIN_FIT` points.
    """
    pixels, _ = camera.project(points)
    ok = np.isfinite(pixels).all(axis=1)
    fit = affine_map(pixels[ok], detected[ok], MIN_FIT, rounds=2)
    return None if fit is None else fit[0]
