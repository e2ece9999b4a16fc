"""What the two namings of unread white squares share (:mod:`~handcap.detect.views`, the rig's other cameras;
:mod:`~handcap.detect.motion`, the camera's neighbouring frames).

Both know, for an image, where some squares of the template should lie (projected from the other cameras, or
mapped from the frame before or after), and name the image's unread white squares that lie there:
:func:`match_squares` takes an unread square for a square where each of its four corners lies within
:data:`GATE_PX` of that square's corners (in one of the four turns, going round the same way as the camera's read
squares do: a square facing away is never taken), no other square comes within :data:`MARGIN` times the gate of
it, and no other unread square takes the same square; :class:`Namer` then names it where the camera did not read
that tag elsewhere in the frame and names none of its corners otherwise, and adds its corner rows and a block row,
marked in ``block_from_views``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

#: Farthest a found corner of an unread square may lie from where a square is expected, pixels.
GATE_PX = 1.5
#: No other square may be expected within this many times :data:`GATE_PX` of the unread square.
MARGIN = 3.0


@dataclass(frozen=True)
class UnreadSquares:
    """One image's white squares without a tag.

    Attributes
    ----------
    camera, frame : int
        Index into the detections' cameras, and frame.
    xy : ndarray (U, 4, 2)
        Their corners in the order they go round the square, pixels.
    score : ndarray (U, 4)
        The corners' probabilities.
    """

    camera: int
    frame: int
    xy: np.ndarray
    score: np.ndarray


@dataclass(frozen=True)
class ViewNaming:
    """What the other cameras (or the neighbouring frames, :mod:`~handcap.detect.motion`) named.

    Attributes
    ----------
    arrays : dict of str to ndarray
        The detections file's arrays with the named squares' corner rows and block rows added
        (``block_from_views`` (B,) bool marks the blocks named so).
    squares : int
        Unread squares named.
    corners : int
        Corner rows added.
    unread : int
        Unread squares there were.
    refused : int
        Squares that matched a projection but whose tag the camera read elsewhere or whose corners it names
        otherwise.
    warnings : tuple of str
    left : tuple of UnreadSquares
        The squares still unread.
    source : str
        What named them, for the summary.
    what : str
        What ``unread`` counts, for the summary.
    """

    arrays: dict
    squares: int
    corners: int
    unread: int
    refused: int = 0
    warnings: tuple = ()
    left: tuple = ()
    source: str = "the other cameras"
    what: str = "unread white squares"

    def summary(self) -> str:
        """One line: the squares named and the corners added."""
        return f"named from {self.source}: {self.squares} of {self.unread} {self.what}, {self.corners} corners"


def square_corners(pattern, marker_names) -> tuple[np.ndarray, np.ndarray]:
    """Every tag of the template and the markers of its square's corners.

    Parameters
    ----------
    pattern : Pattern
    marker_names : sequence of str
        The detections' marker names.

    Returns
    -------
    tags : ndarray (S,) str
        The tags whose four corners are all among ``marker_names``.
    corners : ndarray (S, 4) int
        Indices into ``marker_names`` in reading order (top-left, top-right, bottom-right, bottom-left).
    """
    index = {str(n): k for k, n in enumerate(marker_names)}
    tags, corners = [], []
    for patch in pattern.patches:
        for tag, r, c in patch.blocks():
            ids = [index.get(patch.corner_name(vr, vc), -1) for vr, vc in patch.block_vertices(r, c)]
            if min(ids) >= 0:
                tags.append(tag)
                corners.append(ids)
    return np.array(tags, dtype="<U2"), np.array(corners, dtype=np.int64).reshape(-1, 4)


class Namer:
    """The corner rows and block rows of the unread squares named, as they are taken.

    Parameters
    ----------
    tags : ndarray (S,) str
    corners : ndarray (S, 4) int
        The template's squares (:func:`square_corners`).
    """

    def __init__(self, tags: np.ndarray, corners: np.ndarray):
        self.tags, self.corners = tags, corners
        self.rows = {"frame": [], "camera": [], "marker": [], "xy": [], "score": []}
        self.blocks = {"block_text": [], "block_frame": [], "block_camera": [], "block_xy": []}
        self.named = self.refused = 0

    def take(self, u: UnreadSquares, matches: dict, arrays: dict, mine: np.ndarray) -> UnreadSquares | None:
        """Name ``u``'s squares that matched, where the image's named corners allow it.

        Parameters
        ----------
        u : UnreadSquares
        matches : dict of int to (int, ndarray (4,) int)
            Unread square -> (the template square it matched, its corners in that square's reading order).
        arrays : dict of str to ndarray
            The detections file's arrays.
        mine : ndarray (N,) int
            The rows of the image's named corners.

        Returns
        -------
        UnreadSquares or None
            Those of ``u`` still unread (None: none).
        """
        names = dict(zip(arrays["marker"][mine].tolist(), arrays["xy"][mine]))
        done = np.zeros(len(u.xy), bool)
        for k, (square, order) in matches.items():
            ids = self.corners[square]
            xy, score = u.xy[k][order], u.score[k][order]
            if not _consistent(ids, xy, names, arrays["xy"][mine], arrays["marker"][mine]):
                self.refused += 1
                continue
            new = [j for j in range(4) if int(ids[j]) not in names]
            self.rows["frame"] += [u.frame] * len(new)
            self.rows["camera"] += [u.camera] * len(new)
            self.rows["marker"] += [int(ids[j]) for j in new]
            self.rows["xy"] += [xy[j] for j in new]
            self.rows["score"] += [float(score[j]) for j in new]
            names.update({int(ids[j]): xy[j] for j in new})
            for key, value in zip(self.blocks, (str(self.tags[square]), u.frame, u.camera, xy)):
                self.blocks[key].append(value)
            done[k] = True
            self.named += 1
        return None if done.all() else UnreadSquares(u.camera, u.frame, u.xy[~done], u.score[~done])

    def appended(self, arrays: dict) -> dict:
        """``arrays`` with the rows and blocks added at the end (the blocks' scores 0: the reader did not read
        them; ``block_from_views`` True)."""
        n = len(self.blocks["block_text"])
        new = {**self.rows, **self.blocks, "block_score": np.zeros(n), "block_from_views": np.ones(n, bool)}
        out = dict(arrays)
        out.setdefault("block_from_views", np.zeros(len(arrays["block_text"]), bool))
        for key, values in new.items():
            old = np.asarray(out[key])
            out[key] = np.concatenate([old, np.asarray(values, dtype=old.dtype).reshape((-1,) + old.shape[1:])])
        return out


def affine_map(src: np.ndarray, dst: np.ndarray, least: int, *, rounds: int = 1):
    """The affine map that takes pixels ``src`` (N, 2) to ``dst`` (N, 2), least squares.

    Parameters
    ----------
    src, dst : ndarray (N, 2)
        Pixels.
    least : int
        Fewest points to fit with.
    rounds : int
        Fits: after each but the last, the points over three times the median distance (and over 0.5 px) are left
        out.

    Returns
    -------
    (ndarray (3, 2), float) or None
        The map (pixels as rows ``(x, y, 1)`` times it) and the median distance of the points it was fitted to from
        it, pixels; None where fewer than ``least`` points remain.
    """
    src, dst = np.c_[src, np.ones(len(src))], dst
    for k in range(rounds):
        if len(src) < least:
            return None
        fit = np.linalg.lstsq(src, dst, rcond=None)[0]
        distance = np.linalg.norm(src @ fit - dst, axis=1)
        if k + 1 < rounds:
            keep = distance <= max(3 * float(np.median(distance)), 0.5)
            src, dst = src[keep], dst[keep]
    return fit, float(np.median(distance))


def match_squares(quads: np.ndarray, squares: np.ndarray, sign: float) -> dict:
    """The unread quads that take one of the squares where they are expected (module docstring).

    Parameters
    ----------
    quads : ndarray (U, 4, 2)
        Unread white squares' corners, in the order they go round, pixels.
    squares : ndarray (S, 4, 2)
        Where the template's squares are expected, corners in reading order, pixels.
    sign : float
        +1 where the camera's read squares go round clockwise on the image in reading order, -1 mirrored.

    Returns
    -------
    dict of int to (int, ndarray (4,) int)
        Quad -> (square, the quad's corners in the square's reading order).
    """
    if not len(quads) or not len(squares):
        return {}
    # The quads go round the way the camera's read squares do, so only their four turns need trying.
    ways = np.where((signed_area(quads) * sign < 0)[:, None], np.arange(4)[::-1], np.arange(4))  # (U, 4)
    turned = np.take_along_axis(quads, ways[..., None], axis=1)
    tree = cKDTree(squares.mean(axis=1))
    sides = np.linalg.norm(np.roll(quads, -1, axis=1) - quads, axis=2).max(axis=1)
    chosen = {}
    for k, near in enumerate(tree.query_ball_point(turned.mean(axis=1), sides + MARGIN * GATE_PX)):
        if not near:
            continue
        rolled = np.stack([np.roll(turned[k], -r, axis=0) for r in range(4)])  # (4 turns, 4, 2)
        dist = np.linalg.norm(rolled[None] - squares[near][:, None], axis=-1).max(axis=-1)  # (n, 4 turns)
        best = dist.min(axis=1)
        first = int(np.argmin(best))
        if best[first] > GATE_PX or np.any(np.delete(best, first) <= MARGIN * GATE_PX):
            continue
        r = int(np.argmin(dist[first]))
        chosen[k] = (near[first], ways[k][(np.arange(4) + r) % 4])
    taken = {}
    for k, (s, _) in chosen.items():
        taken.setdefault(s, []).append(k)
    return {k: v for k, v in chosen.items() if len(taken[v[0]]) == 1}


def _consistent(ids, xy, names: dict, image_xy, image_marker) -> bool:
    """Whether the square's corners ``xy`` (4, 2) can take the markers ``ids`` (4,): a marker the image names
    already lies at that corner, and no other marker the image names does."""
    for m, p in zip(ids.tolist(), xy):
        if m in names and np.linalg.norm(names[m] - p) > GATE_PX:
            return False
        if len(image_xy):
            near = np.linalg.norm(image_xy - p, axis=1) <= GATE_PX
            if np.any(near & (image_marker != m)):
                return False
    return True


def signed_area(quads: np.ndarray) -> np.ndarray:
    """Twice the signed area of each quad.

    Parameters
    ----------
    quads : ndarray (..., 4, 2)
        Corners in the order they go round, pixels.

    Returns
    -------
    ndarray (...)
        Positive where they go round clockwise on the image (y down), pixels squared.
    """
    x, y = quads[..., 0], quads[..., 1]
    return (x * np.roll(y, -1, axis=-1) - np.roll(x, -1, axis=-1) * y).sum(axis=-1)


def turning(arrays: dict) -> dict:
    """Each camera's way round of the squares it read, in reading order.

    Parameters
    ----------
    arrays : dict of str to ndarray
        A detections file's arrays.

    Returns
    -------
    dict of int to float
        Camera index -> +1 (clockwise on the image) or -1 (a mirrored image).
    """
    areas = signed_area(np.asarray(arrays["block_xy"], dtype=np.float64).reshape(-1, 4, 2))
    cameras = np.asarray(arrays["block_camera"])
    return {int(c): 1.0 if np.median(areas[cameras == c]) >= 0 else -1.0 for c in np.unique(cameras)}


def image_index(arrays: dict) -> dict:
    """The named corners and read tags of every image.

    Parameters
    ----------
    arrays : dict of str to ndarray
        A detections file's arrays.

    Returns
    -------
    dict of (int, int) to (ndarray (N,) int, set of str)
        (camera, frame) -> (the rows of its named corners, the tags it read).
    """
    key = arrays["camera"].astype(np.int64) * (int(arrays["frame"].max(initial=0)) + 1) + arrays["frame"]
    order = np.argsort(key, kind="stable")
    out = {}
    if len(order):
        starts = np.flatnonzero(np.r_[True, np.diff(key[order]) != 0])
        for a, b in zip(starts, np.r_[starts[1:], len(order)]):
            rows = order[a:b]
            out[(int(arrays["camera"][rows[0]]), int(arrays["frame"][rows[0]]))] = (rows, set())
    for text, c, f in zip(arrays["block_text"], arrays["block_camera"], arrays["block_frame"]):
        out.setdefault((int(c), int(f)), (np.zeros(0, int), set()))[1].add(str(text))
    return out
