"""Photographs of printed sheets (handcap.synth.pages) agree with their exact corner truth.

Independent checks: OpenCV's cornerSubPix finds the photographed checkerboard corners where the truth
says, under tilt, perspective and paper curl; occluded corners are the ones under the occluder's pixels.
"""

from __future__ import annotations

import cv2
import numpy as np

from handcap.patterns import session_pattern
from handcap.patterns.glyphs import GlyphLayout, load_font, square_ink
from handcap.synth.images import ImageStyle
from handcap.synth.pages import PageLook, PagePhotographer
from handcap.synth.textures import build_atlas

PATTERN = session_pattern(("right",), ())
FONT = load_font(None, PATTERN.alphabet)


def _x_corners():
    """Which corners (photograph truth order) are checkerboard X-corners: two white squares across them."""
    out = []
    for patch in PATTERN.patches:
        white = np.pad([[bool(t) for t in row] for row in patch.tags], 1)
        for r, c in patch.vertices():
            out.append((white[r, c] and white[r + 1, c + 1]) or (white[r, c + 1] and white[r + 1, c]))
    return np.array(out)


def _photographer(look, ink=False, layout=None):
    return PagePhotographer(build_atlas(PATTERN.patches, FONT, 48, ink=ink, layout=layout), look, ImageStyle.clean())


def test_corner_truth_survives_tilt_perspective_and_curl():
    look = PageLook(square_px=(22.0, 28.0), tilt_deg=(35.0, 50.0), focal_px=(600.0, 800.0), curl=(1.0, 1.5),
                    occluders=(0, 0), glint=0.0, shade=(1.0, 1.0), ink=(0.0, 0.0))
    errors, crossing = [], _x_corners()
    for seed in range(3):
        shot = _photographer(look).photograph(np.random.default_rng(seed))
        assert shot.image.dtype == np.uint8 and shot.xy.shape == (len(shot.visible), 2)
        # cornerSubPix finds X-corners; on the patch's outline a corner is an L of one white square.
        truth = shot.xy[shot.visible & crossing]
        h, w = shot.image.shape
        keep = (truth[:, 0] > 12) & (truth[:, 1] > 12) & (truth[:, 0] < w - 13) & (truth[:, 1] < h - 13)
        start = (truth[keep] + np.random.default_rng(seed).uniform(-1, 1, (keep.sum(), 2))).astype(np.float32)
        found = cv2.cornerSubPix(shot.image, start.copy(), (4, 4), (-1, -1),
                                 (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_COUNT, 50, 1e-3))
        errors.append(np.linalg.norm(found - truth[keep], axis=1))
    err = np.concatenate(errors)
    assert len(err) > 100
    assert np.median(err) < 0.1, np.median(err)


def test_occluded_corners_are_the_covered_ones():
    look = PageLook(square_px=(20.0, 24.0), occluders=(8, 8), glint=0.0, curl=(0.0, 0.0))
    plain = PageLook(square_px=(20.0, 24.0), occluders=(0, 0), glint=0.0, curl=(0.0, 0.0))
    covered = _photographer(look).photograph(np.random.default_rng(4))
    bare = _photographer(plain).photograph(np.random.default_rng(4))
    # The same draws up to the occluders: the same corners in the image, some of them now hidden.
    np.testing.assert_allclose(covered.xy, bare.xy)
    assert covered.visible.sum() < bare.visible.sum() and not (covered.visible & ~bare.visible).any()


def test_the_same_seed_gives_the_same_photograph():
    a = _photographer(PageLook(), ink=True).photograph(np.random.default_rng(7))
    b = _photographer(PageLook(), ink=True).photograph(np.random.default_rng(7))
    assert np.array_equal(a.image, b.image) and np.array_equal(a.xy, b.xy)


def test_random_glyph_layouts_stay_inside_their_square():
    rng = np.random.default_rng(0)
    for _ in range(200):
        layout = GlyphLayout.random(rng)
        paths = square_ink("MW", 0.0, 0.0, 1.0, FONT, layout)
        glyphs, underline = np.concatenate([p.vertices for p in paths[:2]]), paths[2].vertices
        assert glyphs.min() > 0.0 and glyphs.max() < 1.0
        assert underline[:, 1].min() > glyphs[:, 1].max() - 0.02  # under the glyphs (descenders aside)
        assert underline[:, 1].max() < 1.0
