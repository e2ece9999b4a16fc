"""From corners to blocks: the white squares of a patch as quadrilaterals of four detected corners.

A geometric and photometric test instead of DexterCap's EdgeNet (a ResNet-34
run on every pair of corners): every corner proposes parallelograms with two of
its nearest neighbours, the fourth corner must be a detection near where the
parallelogram puts it, the quadrilateral must be convex with sides and
diagonals of similar lengths (DexterCap's gates: inner angles 36-144 degrees,
side ratio <= 4, diagonal ratio <= 2.5), and its inside must be brighter than
the squares across its four sides (a white square between black ones). Each
block's corners come in a fixed image order (clockwise on screen from the one
nearest the top-left); the reader then says which of them is the tag's
top-left.
"""

from __future__ import annotations

import cv2
import numpy as np
from scipy.spatial import cKDTree

#: Nearest neighbours a corner pairs with.
NEIGHBOURS = 12
#: The fourth corner must lie within this fraction of the shorter side from where the parallelogram puts it.
CLOSE = 0.5
MIN_ANGLE, MAX_ANGLE = np.deg2rad(36.0), np.deg2rad(144.0)
MAX_SIDE_RATIO, MAX_DIAGONAL_RATIO = 4.0, 2.5
#: Least contrast between a block's inside and the squares around it, as a share of the image's spread.
MIN_CONTRAST = 0.15


def candidate_quads(xy: np.ndarray, min_side: float = 3.0) -> np.ndarray:
    """Quadrilaterals of detected corners that pass the geometric gates.

    Parameters
    ----------
    xy : ndarray (K, 2)
        Corners, pixels.
    min_side : float
        Shortest side allowed, pixels.

    Returns
    -------
    ndarray (Q, 4) int
        Corner indices of each quadrilateral in clockwise screen order (y down), starting from the corner
        with the smallest x + y; each quadrilateral once.
    """
    xy = np.asarray(xy, dtype=np.float64)
    if len(xy) < 4:
        return np.zeros((0, 4), int)
    tree = cKDTree(xy)
    k = min(NEIGHBOURS + 1, len(xy))
    _, nn = tree.query(xy, k)
    nn = nn[:, 1:]
    a = np.repeat(np.arange(len(xy)), (k - 1) * (k - 1))
    b = np.repeat(nn, k - 1, axis=1).ravel()
    d = np.tile(nn, (1, k - 1)).ravel()
    keep = b < d
    a, b, d = a[keep], b[keep], d[keep]
    ab, ad = xy[b] - xy[a], xy[d] - xy[a]
    lab, lad = np.linalg.norm(ab, axis=1), np.linalg.norm(ad, axis=1)
    cos = np.einsum("ij,ij->i", ab, ad) / np.maximum(lab * lad, 1e-9)
    ok = (lab >= min_side) & (lad >= min_side) & (cos < np.cos(MIN_ANGLE)) & (cos > np.cos(MAX_ANGLE))
    ok &= np.maximum(lab, lad) <= MAX_SIDE_RATIO * np.minimum(lab, lad)
    a, b, d, lab, lad = a[ok], b[ok], d[ok], lab[ok], lad[ok]
    guess = xy[b] + xy[d] - xy[a]
    dist, c = tree.query(guess, 1)
    ok = (dist <= CLOSE * np.minimum(lab, lad)) & (c != a) & (c != b) & (c != d)
    quads = np.stack([a, b, c, d], axis=1)[ok]
    if len(quads) == 0:
        return np.zeros((0, 4), int)
    quads = _ordered(xy, quads)
    quads = np.unique(quads[_convex_and_gated(xy[quads])], axis=0)
    return quads[_empty(xy, quads, tree)]


def _empty(xy: np.ndarray, quads: np.ndarray, tree) -> np.ndarray:
    """Quads with no other corner inside them or on their sides (one square, not two or four): (Q,) bool."""
    pts = xy[quads]
    centre = pts.mean(axis=1)
    reach = np.linalg.norm(pts - centre[:, None], axis=2).max(axis=1)
    keep = np.ones(len(quads), bool)
    for q, near in enumerate(tree.query_ball_point(centre, reach * 1.05)):
        others = [k for k in near if k not in quads[q]]
        if not others:
            continue
        # Shrink the quad by 15 % towards its centre: a point inside that is a corner of a larger shape.
        poly = centre[q] + 0.85 * (pts[q] - centre[q])
        p = xy[others]
        edges = np.roll(poly, -1, axis=0) - poly
        rel = p[:, None] - poly[None]
        cross = edges[None, :, 0] * rel[..., 1] - edges[None, :, 1] * rel[..., 0]
        keep[q] = not ((cross > 0).all(axis=1) | (cross < 0).all(axis=1)).any()
    return keep


def _ordered(xy: np.ndarray, quads: np.ndarray) -> np.ndarray:
    """Each quad's corners clockwise on screen (y down), from the one with the smallest x + y."""
    pts = xy[quads]
    centre = pts.mean(axis=1, keepdims=True)
    angle = np.arctan2(pts[..., 1] - centre[..., 1], pts[..., 0] - centre[..., 0])
    order = np.argsort(angle, axis=1)  # increasing angle with y down is clockwise on screen
    quads = np.take_along_axis(quads, order, axis=1)
    pts = xy[quads]
    start = np.argmin(pts.sum(axis=2), axis=1)
    roll = (np.arange(4)[None] + start[:, None]) % 4
    return np.take_along_axis(quads, roll, axis=1)


def _convex_and_gated(pts: np.ndarray) -> np.ndarray:
    """Convex, inner angles within the gates, side and diagonal ratios within theirs: (Q,) bool."""
    sides = np.roll(pts, -1, axis=1) - pts
    cross = sides[:, :, 0] * np.roll(sides, -1, axis=1)[:, :, 1] - sides[:, :, 1] * np.roll(sides, -1, axis=1)[:, :, 0]
    convex = (cross > 0).all(axis=1) | (cross < 0).all(axis=1)
    length = np.linalg.norm(sides, axis=2)
    nxt = np.roll(sides, -1, axis=1)
    cos = -np.einsum("qki,qki->qk", sides, nxt) / np.maximum(length * np.roll(length, -1, axis=1), 1e-9)
    angles_ok = ((cos < np.cos(MIN_ANGLE)) & (cos > np.cos(MAX_ANGLE))).all(axis=1)
    side_ok = length.max(axis=1) <= MAX_SIDE_RATIO * length.min(axis=1)
    diag = np.c_[np.linalg.norm(pts[:, 2] - pts[:, 0], axis=1), np.linalg.norm(pts[:, 3] - pts[:, 1], axis=1)]
    diag_ok = diag.max(axis=1) <= MAX_DIAGONAL_RATIO * diag.min(axis=1)
    return convex & angles_ok & side_ok & diag_ok


def white_blocks(image: np.ndarray, xy: np.ndarray, quads: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The quadrilaterals that are white squares between darker ones, with their contrast.

    The inside is sampled on a 5 x 5 grid of the quad's central part (in the
    projective frame of its corners; the median, so glyph ink does not count);
    the outside on strips just across its four sides (a black neighbour, or
    the half-square black margin at a patch's edge).

    Parameters
    ----------
    image : ndarray (H, W)
    xy : ndarray (K, 2)
    quads : ndarray (Q, 4) int

    Returns
    -------
    blocks : ndarray (B, 4) int
        The white ones among ``quads``, none overlapping another.
    contrast : ndarray (B,)
        Inside minus the brightest neighbouring square, as a share of the image's 5-95 % spread.
    """
    if len(quads) == 0:
        return quads.reshape(0, 4), np.zeros(0)
    img = np.asarray(image, dtype=np.float32)
    lo, hi = np.percentile(img[::4, ::4], (5, 95))
    spread = max(hi - lo, 1.0)
    pts = xy[quads].astype(np.float64)
    # Unit square -> quad homographies, vectorised (the 4-point DLT has a closed form via cv2 per quad).
    unit = np.array([[0, 0], [1, 0], [1, 1], [0, 1]], np.float32)
    homs = np.array([cv2.getPerspectiveTransform(unit, p.astype(np.float32)) for p in pts])
    def sample(us, vs):
        gu, gv = np.meshgrid(us, vs)
        h = np.c_[gu.ravel(), gv.ravel(), np.ones(gu.size)]
        p = np.einsum("qij,nj->qni", homs, h)
        p = p[..., :2] / p[..., 2:3]
        x = np.clip(np.round(p[..., 0]).astype(int), 0, img.shape[1] - 1)
        y = np.clip(np.round(p[..., 1]).astype(int), 0, img.shape[0] - 1)
        return np.median(img[y, x], axis=1)

    middle, before, after = np.linspace(0.3, 0.7, 5), np.linspace(-0.4, -0.1, 3), np.linspace(1.1, 1.4, 3)
    inside = sample(middle, middle)
    # Just across each side: the black neighbour, or the black margin (half a square) at a patch's edge.
    around = np.max([sample(before, middle), sample(after, middle), sample(middle, before), sample(middle, after)],
                    axis=0)
    contrast = (inside - around) / spread
    keep = contrast >= MIN_CONTRAST
    quads, contrast = quads[keep], contrast[keep]
    # White squares of a checkerboard never overlap: keep the best of overlapping quads (contrast times
    # how square they are), as a non-maximum suppression.
    pts = xy[quads]
    sides = np.linalg.norm(np.roll(pts, -1, axis=1) - pts, axis=2)
    score = contrast * sides.min(axis=1) / sides.max(axis=1)
    chosen = []
    for q in np.argsort(-score, kind="stable"):
        poly = pts[q].astype(np.float32)
        area = abs(cv2.contourArea(poly))
        if all(cv2.intersectConvexConvex(poly, pts[c].astype(np.float32))[0] <= 0.1 * area for c in chosen
               if np.abs(pts[c].mean(axis=0) - pts[q].mean(axis=0)).max() < sides[q].max() + sides[c].max()):
            chosen.append(q)
    chosen = np.sort(np.array(chosen, dtype=int))
    return quads[chosen], contrast[chosen]
