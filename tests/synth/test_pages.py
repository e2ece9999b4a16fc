"""Photographs of printed sheets (handcap.synth.pages) agree with their exact corner truth.

Independent checks: OpenCV's cornerSubPix finds the photographed checkerboard corners where the truth
says, under tilt, perspective and paper curl; occluded corners are the ones under the occluder's pixels.
"""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from handcap.patterns import session_pattern
from handcap.patterns.glyphs import GlyphLayout, load_font, square_ink
from handcap.synth.images import ImageStyle
from handcap.synth.pages import PageLook, PagePhotographer, _sample, unbent_points
from handcap.synth.textures import build_atlas, patch_texture

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


@pytest.mark.parametrize("wide", [False, True])
def test_random_glyph_layouts_stay_inside_their_square(wide):
    rng = np.random.default_rng(0)
    gaps, spans = [], []
    for _ in range(200):
        layout = GlyphLayout.random(rng, wide=wide)
        paths = square_ink("MW", 0.0, 0.0, 1.0, FONT, layout)
        glyphs, underline = np.concatenate([p.vertices for p in paths[:2]]), paths[2].vertices
        assert glyphs.min() > 0.0 and glyphs.max() < 1.0
        assert underline[:, 1].min() > glyphs[:, 1].max() - 0.02  # under the glyphs (descenders aside)
        assert underline.min() > 0.0 and underline.max() < 1.0
        assert underline[:, 0].min() < paths[0].vertices[:, 0].max()  # under the first glyph
        assert underline[:, 0].max() < paths[1].vertices[:, 0].min() + 0.02  # not under the second
        gaps.append(layout.underline_top - layout.glyph_top - layout.cap_height)
        spans.append(layout.underline_span is not None)
    # the wide draws reach DexterCap's underline (about 0.11 of the side below the glyphs, from 0.1 to the middle)
    assert (max(gaps) > 0.15 and 0.3 < np.mean(spans) < 0.7) if wide else (max(gaps) <= 0.1 and not any(spans))


def test_an_underline_span_places_the_underline():
    layout = GlyphLayout(underline_span=(0.1, 0.5))
    underline = square_ink("HI", 2.0, 3.0, 2.0, FONT, layout)[2].vertices
    assert np.allclose([underline[:, 0].min(), underline[:, 0].max()], [2.2, 3.0])
    assert np.allclose(underline[:, 1].min(), 3.0 + 2.0 * layout.underline_top)
    default = square_ink("HI", 2.0, 3.0, 2.0, FONT, GlyphLayout())
    assert np.allclose(default[2].vertices[:, 1], underline[:, 1])  # only its length changes


def test_varied_glyphs_stay_inside_their_square():
    rng = np.random.default_rng(1)
    for k in range(200):
        base = GlyphLayout.random(rng) if k % 2 else GlyphLayout()
        layout = base.varied(rng)
        paths = square_ink("MW", 0.0, 0.0, 1.0, FONT, layout)
        glyphs = np.concatenate([p.vertices for p in paths[:2]])
        assert glyphs.min() > 0.0 and glyphs.max() < 1.0


def test_slant_shears_each_glyph_about_its_baseline():
    plain = square_ink("HI", 0.0, 0.0, 1.0, FONT, GlyphLayout())
    for slant in (-0.08, 0.12):
        sheared = square_ink("HI", 0.0, 0.0, 1.0, FONT, GlyphLayout(slant=slant))
        baseline = GlyphLayout().glyph_top + GlyphLayout().cap_height
        for a, b in zip(plain[:2], sheared[:2]):
            shift = b.vertices[:, 0] - a.vertices[:, 0]
            rise = baseline - a.vertices[:, 1]  # height above the baseline (y down)
            gain, offset = np.polyfit(rise, shift, 1)
            assert np.allclose(shift, gain * rise + offset, atol=1e-9)  # a shear, nothing else
            assert 0.5 < gain / slant <= 1.0 + 1e-9  # the glyph's own slant, times the squeeze of a wide font
            assert abs(b.vertices[:, 1] - a.vertices[:, 1]).max() < 1e-12


def test_wobble_is_one_shape_per_glyph_and_weight_grows_the_strokes():
    layout = GlyphLayout(wobble=0.03, wobble_seed=5)
    left, right, _ = square_ink("LL", 0.0, 0.0, 1.0, FONT, layout)
    plain, _, _ = square_ink("LL", 0.0, 0.0, 1.0, FONT, GlyphLayout())
    moved = right.vertices - left.vertices
    assert np.allclose(moved, moved[0], atol=1e-12)  # the same outline, only moved
    assert abs(left.vertices - plain.vertices - (left.vertices - plain.vertices).mean(0)).max() > 0.002
    patch = PATTERN.patches[0]
    ink = {w: patch_texture(patch, FONT, 48, layout=GlyphLayout(weight=w)) for w in (-0.015, 0.0, 0.03)}
    dark = {w: (255 - im.astype(float)).sum() for w, im in ink.items()}
    assert dark[-0.015] < dark[0.0] < dark[0.03]
    bare = patch_texture(patch, FONT, 48, ink=False)
    for im in ink.values():  # only the glyphs change: the squares' edges and corners stay where they were
        glyph_free = (bare == 0) | (abs(ink[0.03].astype(int) - bare) == 0)
        assert np.array_equal(im[glyph_free], bare[glyph_free])


def test_the_curl_is_undone_where_it_bends_more_than_a_pixel_per_pixel():
    # A field that bends up to 0.8 px per px (a small photograph of large squares under strong curl): plain
    # fixed-point steps diverge there; Newton's steps find every pixel whose map is one to one.
    h, w = 300, 400
    gy, gx = np.mgrid[0:h, 0:w].astype(np.float32)
    curl = np.stack([30 * np.sin(gx / 40 + gy / 90), 25 * np.cos(gy / 35 - gx / 120)]).astype(np.float32)
    slope = max(np.abs(np.gradient(curl[0], axis=1)).max(), np.abs(np.gradient(curl[1], axis=0)).max())
    assert slope > 0.7
    q_true = np.random.default_rng(0).uniform([20, 20], [w - 20, h - 20], (2000, 2))
    p = q_true + _sample(curl, q_true)
    q, ok = unbent_points(curl, p)
    # Where the map is one to one the answer is unique: found to a thousandth of a pixel.
    assert ok.mean() > 0.9
    np.testing.assert_allclose(q[ok], q_true[ok], atol=2e-3)
    fixed = p.copy()
    for _ in range(8):  # what the truth was before (2026-11-30): far off where the field bends steeply
        fixed = p - _sample(curl, fixed)
    assert np.abs(fixed - q_true)[ok].max() > 1.0


def test_photographs_of_large_squares_under_strong_curl_keep_their_truth():
    # Small images of 24-30 px squares bent by 1.5 squares: every X-corner the truth calls visible is found by
    # cornerSubPix within half a pixel of it (with the fixed-point steps of before, 3.6 % were 1-4.5 px off).
    look = PageLook(square_px=(24.0, 30.0), curl=(1.5, 1.5), size=(400, 320), occluders=(0, 0), glint=0.0,
                    shade=(1.0, 1.0), ink=(0.0, 0.0))
    crossing, errors = _x_corners(), []
    for seed in range(24):
        shot = _photographer(look).photograph(np.random.default_rng(seed))
        truth = shot.xy[shot.visible & crossing]
        h, w = shot.image.shape
        truth = truth[(truth[:, 0] > 12) & (truth[:, 1] > 12) & (truth[:, 0] < w - 13) & (truth[:, 1] < h - 13)]
        if len(truth):
            found = cv2.cornerSubPix(shot.image, truth.astype(np.float32).copy(), (4, 4), (-1, -1),
                                     (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_COUNT, 50, 1e-3))
            errors.append(np.linalg.norm(found - truth, axis=1))
    err = np.concatenate(errors)
    assert len(err) > 300 and np.median(err) < 0.1 and err.max() < 1.0, (np.median(err), err.max())
