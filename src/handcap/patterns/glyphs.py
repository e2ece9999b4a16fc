"""The drawing of a coded patch: squares, glyph outlines and underlines, in millimetres.

One geometry feeds the printable pages (:mod:`handcap.patterns.sheet`) and the
renderer's textures, so what is printed and what the detector is trained on
are the same shapes. Glyph outlines come from a TrueType/OpenType font through
matplotlib's text-to-path conversion; the default font is the DejaVu Sans Mono
Bold that ships with matplotlib, so a pattern looks the same on every machine.

The drawing frame of a patch: millimetres, ``x`` to the right and ``y``
downwards, grid vertex ``(r, c)`` at ``(c * pitch, r * pitch)``. The black
margin reaches half a square beyond the grid on every side.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from functools import lru_cache
from pathlib import Path

import numpy as np
from matplotlib import get_data_path
from matplotlib.font_manager import FontProperties
from matplotlib.ft2font import FT2Font
from matplotlib.path import Path as MplPath
from matplotlib.textpath import TextPath
from matplotlib.transforms import Affine2D

from handcap.core.errors import HandcapError
from handcap.patterns.pattern import Patch

#: matplotlib's own copy of DejaVu Sans Mono Bold (Bitstream Vera licence).
DEFAULT_FONT = Path(get_data_path()) / "fonts" / "ttf" / "DejaVuSansMono-Bold.ttf"
#: Glyph height (of ``H``) as a fraction of the square's side.
CAP_HEIGHT = 0.46
#: Top of the glyphs and the underline's top, fractions of the side from the square's top.
GLYPH_TOP = 0.19
UNDERLINE_TOP = 0.73
UNDERLINE_THICKNESS = 0.07
#: Black margin around a patch, squares.
MARGIN = 0.5


@dataclass(frozen=True)
class GlyphLayout:
    """Where the glyphs and the underline sit in a white square, fractions of its side.

    handcap prints with the defaults; other generators place them otherwise (DexterCap's, for
    one, has taller glyphs and a lower underline), and the reader is trained on many layouts.

    Attributes
    ----------
    cap_height : float
        Glyph height (of ``H``).
    glyph_top : float
        Top of the glyphs, from the square's top.
    underline_top, underline_thickness : float
    gap : float
        Space between the two glyphs.
    weight : float
        Ink grown (or, below 0, thinned) on every side of the glyphs' strokes, fractions of the glyph
        height. Raster textures only (:func:`handcap.synth.textures.patch_texture`): the vector drawing
        keeps the font's own strokes.
    slant : float
        Shear of the glyphs: shift to the right per unit of height above the baseline.
    stretch : float
        Glyph width, a fraction of the font's.
    wobble : float
        Amplitude of a smooth random displacement of the glyphs' outlines, glyph heights (0: none); one
        displacement per glyph and ``wobble_seed``, so a glyph looks the same in every square, as in a font.
    wobble_seed : int
    underline_span : (float, float) or None
        Left and right ends of the underline, fractions of the side from the square's left edge (DexterCap's
        generator draws it from 0.1 to the middle); None: under the first glyph, as wide as it.
    """

    cap_height: float = CAP_HEIGHT
    glyph_top: float = GLYPH_TOP
    underline_top: float = UNDERLINE_TOP
    underline_thickness: float = UNDERLINE_THICKNESS
    gap: float = 0.06
    weight: float = 0.0
    slant: float = 0.0
    stretch: float = 1.0
    wobble: float = 0.0
    wobble_seed: int = 0
    underline_span: tuple | None = None

    @classmethod
    def random(cls, rng, *, wide: bool = False) -> "GlyphLayout":
        """A random layout that fits the square (glyphs 0.36-0.58 high, the underline below them).

        Parameters
        ----------
        rng : numpy.random.Generator
        wide : bool
            Draw from wider ranges: the underline 0.03-0.2 of the side below the glyphs (0.03-0.1 otherwise)
            and, half the time, reaching from 0.03-0.12 of the side to 0.4-0.5 (the left half of the square)
            instead of spanning the first glyph. Other generators place it so: DexterCap's draws it about
            0.11 below the glyphs' foot, from 0.1 to the middle.

        Returns
        -------
        GlyphLayout
        """
        cap = rng.uniform(0.36, 0.58)
        thick = rng.uniform(0.04, 0.1)
        below = rng.uniform(0.03, min(0.2, 0.96 - 0.08 - cap - thick) if wide else 0.1)  # glyphs' foot to underline
        top = rng.uniform(0.08, max(0.09, 0.95 - cap - below - thick))
        span = (rng.uniform(0.03, 0.12), rng.uniform(0.4, 0.5)) if wide and rng.random() < 0.5 else None
        return cls(cap, top, top + cap + below, thick, rng.uniform(0.02, 0.1), underline_span=span)

    def varied(self, rng) -> "GlyphLayout":
        """This layout with glyphs that look like another font's: stroke weight, slant, width and outline.

        The reader is trained on a few fonts and must read fonts it never saw (another generator's
        patches); these variations cover the ways bold monospace fonts differ from each other.

        Parameters
        ----------
        rng : numpy.random.Generator

        Returns
        -------
        GlyphLayout
        """
        return replace(self, weight=rng.uniform(-0.015, 0.035), slant=rng.uniform(-0.08, 0.12),
                       stretch=rng.uniform(0.8, 1.0), wobble=rng.uniform(0.0, 0.03),
                       wobble_seed=int(rng.integers(1 << 30)))


@dataclass(frozen=True)
class Font:
    """Glyph outlines of one font, scaled so that ``H`` is 1 high.

    Attributes
    ----------
    path : Path
        The font file.
    name : str
        Family and style, e.g. ``DejaVu Sans Mono Bold``.
    advance : float
        The widest advance of the alphabet's glyphs, in ``H`` heights.
    """

    path: Path
    name: str
    advance: float

    def outline(self, ch: str) -> MplPath:
        """The outline of glyph ``ch``, baseline at y = 0, y up, ``H`` 1 high.

        Parameters
        ----------
        ch : str

        Returns
        -------
        matplotlib.path.Path
        """
        return _outline(str(self.path), ch)


@lru_cache(maxsize=64)
def _outline(path: str, ch: str) -> MplPath:
    prop = FontProperties(fname=path)
    scale = 1.0 / _cap_height(path)
    return TextPath((0, 0), ch, size=1.0, prop=prop).transformed(Affine2D().scale(scale))


@lru_cache(maxsize=16)
def _cap_height(path: str) -> float:
    verts = TextPath((0, 0), "H", size=1.0, prop=FontProperties(fname=path)).vertices
    return float(verts[:, 1].max() - verts[:, 1].min())


def load_font(path=None, alphabet: str = "") -> Font:
    """A font for patches: ``path`` (a .ttf/.otf file) or the default bold monospace.

    Parameters
    ----------
    path : str, Path or None
    alphabet : str
        Glyphs that must have outlines in the font.

    Returns
    -------
    Font

    Raises
    ------
    HandcapError
        A missing or unreadable font, or one without a glyph of ``alphabet``.
    """
    path = DEFAULT_FONT if path is None else Path(path)
    if not path.is_file():
        raise HandcapError(f"{path}: no such font file; give a .ttf or .otf file")
    try:
        ft = FT2Font(str(path))
        name = f"{ft.family_name} {ft.style_name}".replace(" Regular", "")
        cap = _cap_height(str(path))
    except (RuntimeError, OSError, ValueError) as err:
        raise HandcapError(f"{path}: not a font file matplotlib can read ({err})") from None
    if cap <= 0:
        raise HandcapError(f"{path}: the font has no outline for 'H'; give a font with Latin capitals")
    advance = 0.0
    for ch in alphabet:
        outline = _outline(str(path), ch)
        if len(outline.vertices) == 0:
            raise HandcapError(f"{path}: the font has no outline for glyph {ch!r}")
        advance = max(advance, float(np.ptp(outline.vertices[:, 0])))
    return Font(path, name, advance or 0.6 / 0.73)


def square_ink(text: str, x0: float, y0: float, side: float, font: Font,
               layout: GlyphLayout | None = None) -> list[MplPath]:
    """The glyphs and underline of one white square, in the drawing frame (mm, y down).

    Parameters
    ----------
    text : str
        The tag, two glyphs.
    x0, y0 : float
        Top-left corner of the square, mm.
    side : float
        Side of the square, mm.
    font : Font
    layout : GlyphLayout, optional
        Default: handcap's own.

    Returns
    -------
    list of matplotlib.path.Path
        One outline per glyph, then the underline (a rectangle under the first glyph, or where the layout's
        ``underline_span`` puts it).
    """
    layout = layout or GlyphLayout()
    height = layout.cap_height * side
    gap = layout.gap * side
    width = min(font.advance * height, (0.92 * side - gap) / 2)  # wide fonts are squeezed to fit
    left = x0 + (side - 2 * width - gap) / 2
    baseline = y0 + (layout.glyph_top + layout.cap_height) * side
    out = []
    for k, ch in enumerate(text):
        outline = _varied(font.outline(ch), ch, layout)
        xs = outline.vertices[:, 0]
        squeeze = layout.stretch * min(1.0, width / (font.advance * height))
        shift = left + k * (width + gap) + (width - squeeze * height * (xs.max() + xs.min())) / 2
        out.append(outline.transformed(Affine2D().scale(squeeze * height, -height).translate(shift, baseline)))
    u0 = y0 + layout.underline_top * side
    u1 = u0 + layout.underline_thickness * side
    a, b = (left, left + width) if layout.underline_span is None else (x0 + layout.underline_span[0] * side,
                                                                        x0 + layout.underline_span[1] * side)
    out.append(MplPath([(a, u0), (b, u0), (b, u1), (a, u1), (a, u0)], closed=True))
    return out


def _varied(outline: MplPath, ch: str, layout: GlyphLayout) -> MplPath:
    """A glyph's outline (``H`` 1 high, y up) slanted and wobbled as ``layout`` says."""
    if layout.slant == 0 and layout.wobble == 0:
        return outline
    v = outline.vertices @ np.array([[1.0, 0.0], [layout.slant, 1.0]])
    if layout.wobble:
        rng = np.random.default_rng((layout.wobble_seed, ord(ch)))
        freq = rng.uniform(0.6, 1.6, (2, 2)) * rng.choice((-1, 1), (2, 2))
        phase = rng.uniform(0, 2 * np.pi, 2)
        v = v + layout.wobble * np.sin(2 * np.pi * v @ freq.T + phase)
    return MplPath(v, outline.codes)


def patch_drawing(patch: Patch, pitch_mm: float, font: Font,
                  layout: GlyphLayout | None = None) -> tuple[tuple, list, list]:
    """A patch's drawing in its own frame: the black backing, the white squares and the ink on them.

    Parameters
    ----------
    patch : Patch
    pitch_mm : float
        Side of a square, mm.
    font : Font
    layout : GlyphLayout, optional
        Default: handcap's own.

    Returns
    -------
    backing : (x0, y0, x1, y1)
        The black rectangle, margin included, mm.
    white : list of (x0, y0, x1, y1)
        White squares, mm.
    ink : list of matplotlib.path.Path
        Glyphs and underlines, mm.
    """
    m = MARGIN * pitch_mm
    backing = (-m, -m, patch.cols * pitch_mm + m, patch.rows * pitch_mm + m)
    white, ink = [], []
    for text, r, c in patch.blocks():
        x0, y0 = c * pitch_mm, r * pitch_mm
        white.append((x0, y0, x0 + pitch_mm, y0 + pitch_mm))
        ink += square_ink(text, x0, y0, pitch_mm, font, layout)
    return backing, white, ink
