"""From corners to blocks: the white squares of a patch as quadrilaterals of four detected corners.

A geometric and photometric test instead of DexterCap's EdgeNet (a ResNet-34 run
on every pair of corners): every corner proposes parallelograms with two of its
nearest neighbours, the fourth corner must be a detection near where the
parallelogram puts it, the quadrilateral must be convex with sides and diagonals
of similar lengths (DexterCap's gates are inner angles 36-144 degrees, side
ratio <= 4 and diagonal ratio <= 2.5; here the angles may reach 25-155 degrees
and the diagonals the ratio of a rhombus at that angle: a square seen obliquely
along its diagonal is such a rhombus), no strong corner may lie inside it, and
its inside must be brighter than the squares across its four sides (a white
square between black ones). Each block's corners come in a fixed image order
(clockwise on screen from the one nearest the top-left); the reader then says
which of them is the tag's top-left.
"""

from __future__ import annotations

import cv2
import numpy as np
from scipy.spatial import cKDTree

from handcap.detect.corners import grey_levels

#: Nearest neighbours a corner pairs with.
NEIGHBOURS = 12
#: The fourth corner must lie within this fraction of the shorter side from where the parallelogram puts it.
CLOSE = 0.5
#: Shortest side of a white square, pixels.
MIN_SIDE = 3.0
#: Inner angles (DexterCap: 36-144 degrees; on rendered hands the wider gate reads 1-2 % more tags, none wrong).
MIN_ANGLE, MAX_ANGLE = np.deg2rad(25.0), np.deg2rad(155.0)
MAX_SIDE_RATIO = 4.0
#: The diagonals of a rhombus with the least inner angle: a square foreshortened along its diagonal.
MAX_DIAGONAL_RATIO = 1.0 / np.tan(MIN_ANGLE / 2)
#: Least score of a corner inside a quad that makes it more than one square. The grid corners inside a quad
#: spanning several squares are clean crossings; a weaker one inside a white square is a glyph's corner that
#: passed the refiner, and must not hide the square.
INSIDE_SCORE = 0.7
#: Least contrast between a block's inside and the squares around it, as a share of the image's spread.
MIN_CONTRAST = 0.15
#: Least step across each side, between strips just inside and just outside it (a share of the spread): half
#: the least contrast. A quad with a false corner has a side that leaves the printed edge, and the strips
#: along it both fall on one colour.
MIN_STEP = MIN_CONTRAST / 2
#: Where the side strips lie, in sides of the block from the side (inside and, mirrored, outside).
STRIP = (0.06, 0.18)
#: The two halves of a side whose steps are tested apart, in sides of the block along it.
HALVES = ((0.12, 0.45), (0.55, 0.88))


def candidate_quads(xy: np.ndarray, min_side: float = MIN_SIDE, score: np.ndarray | None = None) -> np.ndarray:
    """Quadrilaterals of detected corners that pass the geometric gates and hold no other strong corner.

    Parameters
    ----------
    xy : ndarray (K, 2)
        Corners, pixels.
    min_side : float
        Shortest side allowed, pixels.
    score : ndarray (K,), optional
        Corner probabilities: a corner below :data:`INSIDE_SCORE` inside a quad does not refuse it
        (default: every corner counts).

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
    # Each quad is proposed from several of its corners: one of each set of four, then their order and gates.
    quads = _unique_rows(np.sort(quads, axis=1), len(xy))
    quads = _ordered(xy, quads)
    quads = _unique_rows(quads[_convex_and_gated(xy[quads])], len(xy))
    strong = np.ones(len(xy), bool) if score is None else np.asarray(score) >= INSIDE_SCORE
    return quads[_empty(xy, quads, strong)]


def _unique_rows(quads: np.ndarray, n: int) -> np.ndarray:
    """The distinct rows of ``quads`` (Q, 4) of indices below ``n``, sorted as ``np.unique(quads, axis=0)`` sorts
    them (one integer key per row: several times faster)."""
    if n ** 4 >= 2 ** 63:
        return np.unique(quads, axis=0)
    key = ((quads[:, 0] * n + quads[:, 1]) * n + quads[:, 2]) * n + quads[:, 3]
    return quads[np.unique(key, return_index=True)[1]]


#: Corners inside a quad shrunk by this share towards its centre refuse it (:func:`_empty`).
SHRINK = 0.85
#: Quads sampled in one call of OpenCV's remap, which maps fewer than 32,767 rows (and columns) at once.
REMAP_ROWS = 16384


def _empty(xy: np.ndarray, quads: np.ndarray, strong: np.ndarray) -> np.ndarray:
    """Quads with no other ``strong`` corner inside them (one square, not two or four): (Q,) bool."""
    pts = xy[quads]
    centre = pts.mean(axis=1)
    reach = np.linalg.norm(pts - centre[:, None], axis=2).max(axis=1)
    # Only strong corners can refuse a quad, and only within the shrunk quad's reach of its centre.
    index = np.flatnonzero(strong)
    if len(index) == 0:
        return np.ones(len(quads), bool)
    near = cKDTree(xy[index]).query_ball_point(centre, reach * (SHRINK * (1 + 1e-9)),
                                                  return_sorted=False)
    counts = np.fromiter(map(len, near), int, len(quads))
    q = np.repeat(np.arange(len(quads)), counts)
    p = index[np.concatenate(near).astype(int)] if counts.sum() else np.zeros(0, int)
    other = (quads[q] != p[:, None]).all(axis=1)
    q, p = q[other], p[other]
    # Shrink each quad by 15 % towards its centre: a point inside that is a corner of a larger shape.
    poly = centre[q, None] + SHRINK * (pts[q] - centre[q, None])
    edges = np.roll(poly, -1, axis=1) - poly
    rel = xy[p, None] - poly
    cross = edges[..., 0] * rel[..., 1] - edges[..., 1] * rel[..., 0]
    inside = (cross > 0).all(axis=1) | (cross < 0).all(axis=1)
    return np.bincount(q[inside], minlength=len(quads)) == 0


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


def white_blocks(image: np.ndarray, xy: np.ndarray, quads: np.ndarray,
                 levels: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """The quadrilaterals that are white squares between darker ones, with their contrast.

    The inside is sampled on a 5 x 5 grid of the quad's central part (in the
    projective frame of its corners; the median, so glyph ink does not count);
    the outside on strips just across its four sides (a black neighbour, or
    the half-square black margin at a patch's edge). Each side must also be a
    printed edge: a strip just inside it brighter than one just outside it by
    :data:`MIN_STEP` (a quad with one false corner, beside the true one or at
    an occluding contour, has a side that runs through one colour).

    Parameters
    ----------
    image : ndarray (H, W)
    xy : ndarray (K, 2)
    quads : ndarray (Q, 4) int
    levels : ndarray (3,), optional
        :func:`~handcap.detect.corners.grey_levels` of the whole frame when ``image`` is a part of it.

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
    lo, _, hi = grey_levels(image) if levels is None else levels
    spread = max((hi - lo) * (255.0 if np.asarray(image).dtype == np.uint8 else 1.0), 1.0)
    pts = xy[quads].astype(np.float64)
    homs = unit_square_homographies(pts)
    middle, before, after = np.linspace(0.3, 0.7, 5), np.linspace(-0.4, -0.1, 3), np.linspace(1.1, 1.4, 3)
    inside = _sample(img, homs, middle, middle)
    # Just across each side: the black neighbour, or the black margin (half a square) at a patch's edge.
    around = np.max([_sample(img, homs, u, v) for u, v in
                     ((before, middle), (after, middle), (middle, before), (middle, after))], axis=0)
    contrast = (inside - around) / spread
    keep = contrast >= MIN_CONTRAST
    quads, contrast, homs = quads[keep], contrast[keep], homs[keep]
    near = np.linspace(*STRIP, 3)
    step = np.full(len(quads), np.inf)
    for half in HALVES:  # each half of each side on its own: a false corner bends the half next to it most
        edge = np.linspace(*half, 4)
        inner = np.array([_sample(img, homs, u, v) for u, v in
                          ((near, edge), (edge, near), (1 - near, edge), (edge, 1 - near))])
        outer = np.array([_sample(img, homs, u, v) for u, v in
                          ((-near, edge), (edge, -near), (1 + near, edge), (edge, 1 + near))])
        step = np.minimum(step, ((inner - outer) / spread).min(axis=0))
    keep = step >= MIN_STEP
    quads, contrast = quads[keep], contrast[keep]
    # White squares of a checkerboard never overlap: keep the best of overlapping quads (contrast times
    # how square they are), as a non-maximum suppression.
    pts = xy[quads]
    sides = np.linalg.norm(np.roll(pts, -1, axis=1) - pts, axis=2)
    score = contrast * sides.min(axis=1) / sides.max(axis=1)
    chosen = _suppress(pts, sides.max(axis=1), score)
    return quads[chosen], contrast[chosen]


def _sample(img: np.ndarray, homs: np.ndarray, us: np.ndarray, vs: np.ndarray) -> np.ndarray:
    """Median grey of each quad over the grid ``us`` x ``vs`` of its unit square (bilinear): (Q,)."""
    if len(homs) == 0:
        return np.zeros(0, np.float32)
    gu, gv = np.meshgrid(us, vs)
    h = np.c_[gu.ravel(), gv.ravel(), np.ones(gu.size)]
    p = np.matmul(h[None], homs.transpose(0, 2, 1))
    p = (p[..., :2] / p[..., 2:3]).astype(np.float32)
    # One row of the map per quad; OpenCV maps fewer than 32,767 rows at once (a textured backdrop gives more).
    return np.concatenate([np.median(cv2.remap(img, part[..., 0], part[..., 1], cv2.INTER_LINEAR,
                                               borderMode=cv2.BORDER_REPLICATE), axis=1)
                           for part in np.array_split(p, -(-len(p) // REMAP_ROWS))])


def unit_square_homographies(pts: np.ndarray) -> np.ndarray:
    """The homographies taking the unit square's corners (0,0), (1,0), (1,1), (0,1) to each quad's.

    Parameters
    ----------
    pts : ndarray (Q, 4, 2)

    Returns
    -------
    ndarray (Q, 3, 3)
        Scaled so that the last entry is 1 (Heckbert's closed form for a square, vectorised).
    """
    p = np.asarray(pts, dtype=np.float64)
    (x0, y0), (x1, y1), (x2, y2), (x3, y3) = (p[:, k].T for k in range(4))
    sx, sy = x0 - x1 + x2 - x3, y0 - y1 + y2 - y3
    dx1, dx2, dy1, dy2 = x1 - x2, x3 - x2, y1 - y2, y3 - y2
    den = dx1 * dy2 - dx2 * dy1
    den = np.where(np.abs(den) < 1e-12, 1e-12, den)
    g = (sx * dy2 - dx2 * sy) / den
    h = (dx1 * sy - sx * dy1) / den
    one = np.ones_like(g)
    return np.stack([np.stack([x1 - x0 + g * x1, x3 - x0 + h * x3, x0], axis=1),
                     np.stack([y1 - y0 + g * y1, y3 - y0 + h * y3, y0], axis=1),
                     np.stack([g, h, one], axis=1)], axis=1)


def _suppress(pts: np.ndarray, reach: np.ndarray, score: np.ndarray) -> np.ndarray:
    """Greedy non-maximum suppression of overlapping convex quads, best score first: kept indices, sorted."""
    centre = pts.mean(axis=1)
    pairs = cKDTree(centre).query_pairs(2 * float(reach.max()) if len(reach) else 0.0, output_type="ndarray")
    if len(pairs):
        close = np.abs(centre[pairs[:, 0]] - centre[pairs[:, 1]]).max(axis=1) < reach[pairs].sum(axis=1)
        pairs = pairs[close]
    poly = pts.astype(np.float32)
    area = np.abs([cv2.contourArea(p) for p in poly])
    overlap = np.array([cv2.intersectConvexConvex(poly[a], poly[b])[0] for a, b in pairs]).reshape(-1)
    beats = {}  # quad -> the quads that overlap it by more than a tenth of its area
    for (a, b), inter in zip(pairs, overlap):
        if inter > 0.1 * area[a]:
            beats.setdefault(a, []).append(b)
        if inter > 0.1 * area[b]:
            beats.setdefault(b, []).append(a)
    kept = np.zeros(len(pts), bool)
    for q in np.argsort(-score, kind="stable"):
        kept[q] = not kept[beats.get(q, [])].any()
    return np.flatnonzero(kept)
