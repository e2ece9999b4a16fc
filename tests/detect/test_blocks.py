"""Block assembly from corners: white squares found among the true corners of rendered patches, and the
geometric gates on hand-made shapes."""

from __future__ import annotations

import cv2
import numpy as np

from handcap.detect.blocks import candidate_quads, unit_square_homographies, white_blocks


def _checkerboard(rows=4, cols=5, side=20, origin=(30, 30)):
    """A bare checkerboard image (white where r + c is even) with a black margin, and its corners."""
    h, w = rows * side + 2 * origin[1], cols * side + 2 * origin[0]
    image = np.full((h, w), 200, np.uint8)
    image[origin[1] - side // 2:origin[1] + rows * side + side // 2, origin[0] - side // 2:origin[0] + cols * side
          + side // 2] = 20
    for r in range(rows):
        for c in range(cols):
            if (r + c) % 2 == 0:
                y, x = origin[1] + r * side, origin[0] + c * side
                image[y:y + side, x:x + side] = 230
    corners = np.array([(origin[0] + c * side - 0.5, origin[1] + r * side - 0.5)
                        for r in range(rows + 1) for c in range(cols + 1)], float)
    return image, corners


def test_every_white_square_and_nothing_else_on_a_flat_board():
    image, corners = _checkerboard()
    quads = candidate_quads(corners)
    blocks, contrast = white_blocks(image, corners, quads)
    found = {frozenset(b) for b in blocks}
    expected = {frozenset((r * 6 + c, r * 6 + c + 1, (r + 1) * 6 + c + 1, (r + 1) * 6 + c))
                for r in range(4) for c in range(5) if (r + c) % 2 == 0}
    assert found == expected and (contrast > 0.5).all()
    # Corners come clockwise on screen from the top-left one.
    for b in blocks:
        p = corners[b]
        assert np.argmin(p.sum(axis=1)) == 0 and p[1, 0] > p[0, 0] and p[2, 1] > p[1, 1]


def test_more_quads_than_opencv_maps_at_once_are_tested_alike():
    # A textured backdrop can give hundreds of thousands of candidate quads; OpenCV's remap maps fewer than 32,767
    # rows at once. The board's quads, repeated past that, give the board's blocks and contrasts.
    image, corners = _checkerboard()
    quads = candidate_quads(corners)
    once = white_blocks(image, corners, quads)
    many = np.tile(quads, (-(-40000 // len(quads)), 1))
    blocks, contrast = white_blocks(image, corners, many)
    assert len(many) > 40000 and {frozenset(b) for b in blocks} == {frozenset(b) for b in once[0]}
    np.testing.assert_allclose(np.sort(contrast), np.sort(once[1]))


def test_a_false_corner_beside_a_missed_one_makes_no_block():
    # The detector missed the bottom-right corner of the white square at row 2, column 2 and found a false
    # one 5-6 px off instead, along a side or inwards (a quarter of the side: within the parallelogram's
    # reach, and the square's middle is still white): a side that runs to it leaves the printed edge. (Off
    # along the diagonal outwards, into the white square across the corner, both sides stay near their
    # edges for most of their length and the quad passes; the vote and the misfit test are left for it.)
    image, corners = _checkerboard()
    square = (2 * 6 + 2, 2 * 6 + 3, 3 * 6 + 3, 3 * 6 + 2)
    truth = {frozenset(q) for q in white_blocks(image, corners, candidate_quads(corners))[0]}
    assert frozenset(square) in truth
    for shift in ([6.0, 0.0], [0.0, 6.0], [-6.0, 0.0], [0.0, -5.0], [-5.0, -5.0]):
        moved = corners.copy()
        moved[square[2]] += shift
        found = {frozenset(q) for q in white_blocks(image, moved, candidate_quads(moved))[0]}
        assert frozenset(square) not in found
        # The squares that do not touch the moved corner are all still found.
        assert {q for q in truth if square[2] not in q} <= found


def test_gates_refuse_thin_and_crossed_shapes():
    thin = np.array([[0, 0], [40, 0], [40, 2], [0, 2]], float)  # side ratio 20
    assert len(candidate_quads(thin, min_side=1)) == 0
    assert len(candidate_quads(np.zeros((3, 2)))) == 0


def test_a_square_seen_along_its_diagonal_is_a_candidate():
    # A square foreshortened along one diagonal is a rhombus: at 30 degrees (inside the 25-155 degree gate) its
    # diagonals are in a ratio of 1 / tan(15 deg) = 3.7, which DexterCap's gates (36 degrees, ratio 2.5) refused;
    # at 20 degrees the angle gate refuses it.
    for angle, found in ((30.0, 1), (20.0, 0)):
        half = np.deg2rad(angle) / 2
        rhombus = np.array([[0, 0], [20 * np.cos(half), 20 * np.sin(half)], [40 * np.cos(half), 0],
                            [20 * np.cos(half), -20 * np.sin(half)]]) + 50
        assert len(candidate_quads(rhombus)) == found


def test_a_weak_corner_inside_a_square_does_not_hide_it():
    # A glyph's corner that passed the refiner weakly, inside a white square: the square is still a candidate.
    # The crossing at the middle of a 2 x 2 quad is strong, so the quad that spans four squares is not.
    image, corners = _checkerboard()
    square = (2 * 6 + 2, 2 * 6 + 3, 3 * 6 + 3, 3 * 6 + 2)
    glyph = np.vstack([corners, corners[list(square)].mean(axis=0) + (2.0, -3.0)])
    score = np.r_[np.full(len(corners), 0.99), 0.6]
    assert frozenset(square) not in {frozenset(q) for q in candidate_quads(glyph)}
    assert frozenset(square) in {frozenset(q) for q in candidate_quads(glyph, score=score)}
    blocks, _ = white_blocks(image, glyph, candidate_quads(glyph, score=score))
    assert frozenset(square) in {frozenset(q) for q in blocks}
    four = frozenset((2 * 6 + 2, 2 * 6 + 4, 4 * 6 + 4, 4 * 6 + 2))
    assert four not in {frozenset(q) for q in candidate_quads(glyph, score=score)}
    score[3 * 6 + 3] = 0.6  # the crossing itself weak: the 2 x 2 quad passes the geometry
    assert four in {frozenset(q) for q in candidate_quads(glyph, score=score)}


def test_white_squares_of_rendered_patches_from_their_true_corners(scenes):
    truth_total = hits = false = 0
    for scene in scenes:
        blocks, _ = white_blocks(scene.image, scene.corners, candidate_quads(scene.corners))
        index = {tuple(p): k for k, p in enumerate(np.round(scene.corners, 6))}
        truth = {frozenset(index[tuple(p)] for p in np.round(b, 6)) for b in scene.blocks}
        found = {frozenset(b) for b in blocks}
        truth_total += len(truth)
        hits += len(truth & found)
        false += len(found - truth)
    assert truth_total > 40
    assert hits >= 0.8 * truth_total and false <= 0.15 * (hits + false)


def test_unit_square_homographies_match_opencv():
    rng = np.random.default_rng(4)
    square = np.array([[0, 0], [1, 0], [1, 1], [0, 1]], float)
    quads = 50 + 30 * (square[None] + rng.normal(0, 0.15, (40, 4, 2)))  # convex, perspective-like
    homs = unit_square_homographies(quads)
    for quad, hom in zip(quads, homs):
        ref = cv2.getPerspectiveTransform(square.astype(np.float32), quad.astype(np.float32))
        np.testing.assert_allclose(hom, ref / ref[2, 2], rtol=1e-4, atol=1e-6)
        mapped = np.c_[square, np.ones(4)] @ hom.T
        np.testing.assert_allclose(mapped[:, :2] / mapped[:, 2:], quad, atol=1e-9)


def test_candidates_are_the_gated_quads_with_no_strong_corner_inside_found_by_brute_force():
    # A jittered checkerboard with scattered corners, some weak (a glyph's), some strong (a stray crossing): the
    # candidates are exactly the gated quads (all of them where no corner counts as strong) that hold no other
    # strong corner in their outline shrunk by SHRINK, tested here corner by corner with OpenCV.
    from handcap.detect.blocks import INSIDE_SCORE, SHRINK

    rng = np.random.default_rng(3)
    _, corners = _checkerboard(rows=5, cols=6, side=14)
    xy = np.vstack([corners + rng.normal(0, 0.6, corners.shape), rng.uniform(20, 110, (40, 2))])
    score = np.r_[np.full(len(corners), 0.99), rng.uniform(0.3, 1.0, 40)]
    gated = candidate_quads(xy, score=np.zeros(len(xy)))
    strong = np.flatnonzero(score >= INSIDE_SCORE)
    expected = []
    for quad in gated:
        pts = xy[quad]
        poly = (pts.mean(axis=0) + SHRINK * (pts - pts.mean(axis=0))).astype(np.float32)
        if all(cv2.pointPolygonTest(poly, (float(xy[p, 0]), float(xy[p, 1])), False) < 0
               for p in strong if p not in quad):
            expected.append(quad)
    found = candidate_quads(xy, score=score)
    assert 20 < len(found) < len(gated)
    assert np.array_equal(found, np.array(expected))
    assert np.array_equal(found, np.unique(found, axis=0))  # distinct, sorted as np.unique sorts rows


def test_distinct_rows_match_numpys():
    from handcap.detect.blocks import _unique_rows

    rng = np.random.default_rng(0)
    quads = rng.integers(0, 9, (500, 4))
    assert np.array_equal(_unique_rows(quads, 9), np.unique(quads, axis=0))
    assert _unique_rows(quads[:0], 9).shape == (0, 4)
