"""Printable pages of coded patches: PDF (all pages) and SVG (one file per page), exact physical size.

Patches are packed on pages row by row, each with its name printed under it
and a cut line around its black margin. Every page carries a 50 mm scale bar
with 5 mm ticks, to check that the printer did not scale the page (print at
100 %, "actual size"). Drawing units are millimetres; matplotlib writes
them as PDF points (1 mm = 72 / 25.4 pt) and SVG points, so a square of the
pattern is ``pitch`` wide on paper.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from handcap.core.errors import HandcapError
from handcap.core.files import atomic_output
from handcap.patterns.glyphs import MARGIN, Font, patch_drawing
from handcap.patterns.pattern import Patch, Pattern

#: Paper sizes, mm (width, height).
PAPERS = {"a4": (210.0, 297.0), "letter": (215.9, 279.4)}
PAGE_MARGIN = 12.0  # mm, clear of the printer's unprintable border
GAP = 4.0           # mm between patches
LABEL = 3.0         # mm of text height under a patch
SCALE_BAR = 50.0    # mm
_HEADER = 14.0      # mm at the top of a page for the title and the scale bar


@dataclass(frozen=True)
class Placement:
    """Where a patch lies on a page: its grid vertex (0, 0) at ``(x, y)`` mm from the top-left of page ``page``."""

    patch: Patch
    page: int
    x: float
    y: float


def layout_pages(pattern: Pattern, paper: str = "a4") -> list[Placement]:
    """Pack the patches onto pages, row by row in template order.

    Parameters
    ----------
    pattern : Pattern
    paper : {'a4', 'letter'}

    Returns
    -------
    list of Placement

    Raises
    ------
    HandcapError
        An unknown paper, or a patch larger than a page.
    """
    if paper not in PAPERS:
        raise HandcapError(f"paper {paper!r}: choose one of {', '.join(PAPERS)}")
    width, height = PAPERS[paper]
    pitch = pattern.pitch * 1000
    m = MARGIN * pitch
    placements, page, x, y, shelf = [], 0, PAGE_MARGIN, PAGE_MARGIN + _HEADER, 0.0
    for patch in pattern.patches:
        w, h = patch.cols * pitch + 2 * m, patch.rows * pitch + 2 * m + LABEL
        if w > width - 2 * PAGE_MARGIN or h > height - 2 * PAGE_MARGIN - _HEADER:
            raise HandcapError(f"patch {patch.key} ({w:.0f} x {h:.0f} mm) does not fit on a {paper} page; use a "
                               "smaller pitch")
        if x + w > width - PAGE_MARGIN:
            x, y, shelf = PAGE_MARGIN, y + shelf + GAP, 0.0
        if y + h > height - PAGE_MARGIN:
            page, x, y, shelf = page + 1, PAGE_MARGIN, PAGE_MARGIN + _HEADER, 0.0
        placements.append(Placement(patch, page, x + m, y + m))
        x, shelf = x + w + GAP, max(shelf, h)
    return placements


def _page_figure(pattern: Pattern, placements, page: int, pages: int, font: Font, paper: str):
    # matplotlib's figure and PDF machinery load here, not with the command line (half a second).
    from matplotlib.figure import Figure
    from matplotlib.patches import PathPatch, Rectangle

    width, height = PAPERS[paper]
    fig = Figure(figsize=(width / 25.4, height / 25.4))
    ax = fig.add_axes((0, 0, 1, 1))
    ax.set_xlim(0, width)
    ax.set_ylim(height, 0)
    ax.set_axis_off()
    pitch = pattern.pitch * 1000
    owners = ", ".join(dict.fromkeys(p.patch.owner for p in placements))
    ax.text(PAGE_MARGIN, PAGE_MARGIN, f"handcap coded patches - {owners} - page {page + 1}/{pages} - "
            f"{pitch:g} mm squares, {font.name} - print at 100 % (actual size)",
            fontsize=7, va="top", ha="left", family="DejaVu Sans")
    # Scale bar: black and white 5 mm cells, SCALE_BAR mm long, under the title.
    bar_y = PAGE_MARGIN + 5.0
    for k in range(int(SCALE_BAR / 5)):
        ax.add_patch(Rectangle((PAGE_MARGIN + 5 * k, bar_y), 5, 2, facecolor="black" if k % 2 == 0 else "white",
                               edgecolor="black", linewidth=0.2, gid=f"scale-{k}"))
    ax.text(PAGE_MARGIN + SCALE_BAR + 2, bar_y + 1, f"{SCALE_BAR:g} mm", fontsize=6, va="center",
            family="DejaVu Sans")
    for place in placements:
        backing, white, ink = patch_drawing(place.patch, pitch, font)
        x0, y0, x1, y1 = backing
        ax.add_patch(Rectangle((place.x + x0, place.y + y0), x1 - x0, y1 - y0, facecolor="black",
                               edgecolor="0.6", linewidth=0.15, gid=f"backing-{place.patch.key}"))
        for wx0, wy0, wx1, wy1 in white:
            ax.add_patch(Rectangle((place.x + wx0, place.y + wy0), wx1 - wx0, wy1 - wy0, facecolor="white",
                                   edgecolor="none", linewidth=0))
        for path in ink:
            ax.add_patch(PathPatch(path.transformed(_shift(place.x, place.y)), facecolor="black",
                                   edgecolor="none", linewidth=0))
        ax.text(place.x + x0, place.y + y1 + 0.6, place.patch.key, fontsize=5, va="top", ha="left",
                color="0.3", family="DejaVu Sans")
    return fig


def _shift(x, y):
    from matplotlib.transforms import Affine2D

    return Affine2D().translate(x, y)


def write_sheets(pattern: Pattern, font: Font, pdf=None, svg_stem=None, *, paper: str = "a4") -> list[Path]:
    """Write the pages as one PDF and/or one SVG per page, atomically.

    Parameters
    ----------
    pattern : Pattern
    font : Font
        The glyphs' font.
    pdf : str, Path or None
        The PDF to write.
    svg_stem : str, Path or None
        SVG pages are written as ``STEM-1.svg``, ``STEM-2.svg``, ...
    paper : {'a4', 'letter'}

    Returns
    -------
    list of Path
        The files written.
    """
    from matplotlib import rc_context
    from matplotlib.backends.backend_pdf import PdfPages

    placements = layout_pages(pattern, paper)
    pages = max(p.page for p in placements) + 1 if placements else 0
    figures = [_page_figure(pattern, [p for p in placements if p.page == k], k, pages, font, paper)
               for k in range(pages)]
    written = []
    # Same pattern, same bytes: no dates, fixed ids; text as outlines so no font is needed to view the pages.
    with rc_context({"svg.hashsalt": "handcap", "svg.fonttype": "path", "pdf.fonttype": 42,
                     "pdf.compression": 6}):
        if pdf is not None:
            with atomic_output(pdf, None) as tmp:
                with PdfPages(tmp, metadata={"Creator": "handcap pattern", "CreationDate": None,
                                             "Producer": None}) as book:
                    for fig in figures:
                        book.savefig(fig)
            written.append(Path(pdf))
        if svg_stem is not None:
            stem = Path(svg_stem)
            for k, fig in enumerate(figures):
                out = stem.with_name(f"{stem.name}-{k + 1}.svg")
                with atomic_output(out, "wb") as fh:
                    fig.savefig(fh, format="svg", metadata={"Date": None, "Creator": "handcap pattern"})
                written.append(out)
    return written
