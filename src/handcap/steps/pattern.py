"""Step ``pattern``: printable coded patches (PDF, SVG pages) and their template ``pattern.toml``."""

from __future__ import annotations

from pathlib import Path

from handcap.core.errors import HandcapError
from handcap.core.files import check_output_folder
from handcap.patterns.alphabet import ALPHABET, lookalike_warning
from handcap.patterns.glyphs import load_font
from handcap.patterns.pattern import Pattern
from handcap.patterns.session import HANDS, session_pattern
from handcap.patterns.sheet import write_sheets
from handcap.steps.step import Step

DEFAULT_OBJECTS = ("cuboid", "cylinder", "sphere", "cube2x2")


def pattern(out, *, hands=HANDS, objects=DEFAULT_OBJECTS, alphabet: str = ALPHABET, pitch_mm: float = 5.0,
            font=None, paper: str = "a4", template=None, svg: bool = True, force: bool = False) -> Step:
    """Write a session's coded patches into folder ``out``: ``pattern.toml``, ``pattern.pdf``, ``pattern-N.svg``.

    Parameters
    ----------
    out : str or Path
        Folder to write into (new or empty, or ``force``).
    hands : sequence of {'right', 'left'}
        Hands that wear the 19 patches.
    objects : sequence of str
        Objects whose faces carry patches (see :data:`handcap.patterns.session.OBJECT_PATCHES`).
    alphabet : str
        Glyphs of the tags.
    pitch_mm : float
        Side of a square, millimetres.
    font : str, Path or None
        A .ttf/.otf font for the glyphs (default: DejaVu Sans Mono Bold).
    paper : {'a4', 'letter'}
    template : str, Path or None
        Print this ``pattern.toml`` instead of making one (``hands``, ``objects``, ``alphabet`` and
        ``pitch_mm`` are then taken from it).
    svg : bool
        Also write one SVG per page.
    force : bool
        Write into a folder that holds files.
    """
    folder = check_output_folder(out, template, force=force)
    if template is not None:
        chosen = Pattern.load(template)
    else:
        if not 0.5 <= pitch_mm <= 100:
            raise HandcapError(f"--pitch {pitch_mm} mm: give the side of a square in millimetres, 0.5 to 100")
        chosen = session_pattern(hands, objects, alphabet=alphabet, pitch=pitch_mm / 1000)
    glyph_font = load_font(font, chosen.alphabet)
    if template is None:
        chosen = Pattern(chosen.patches, chosen.alphabet, chosen.pitch, glyph_font.name)
    folder.mkdir(parents=True, exist_ok=True)
    toml_path = chosen.save(folder / "pattern.toml") if template is None else None
    written = write_sheets(chosen, glyph_font, folder / "pattern.pdf", folder / "pattern" if svg else None,
                           paper=paper)
    outputs = ([str(toml_path)] if toml_path else []) + [str(p) for p in written]
    pages = sum(p.suffix == ".svg" for p in written)
    count = f" ({pages} page{'s' if pages > 1 else ''})" if pages else ""
    lines = (chosen.summary(),
             f"wrote {', '.join(Path(p).name for p in outputs)} in {folder}{count}",
             "print the PDF at 100 % (actual size) and check its 50 mm scale bar with a ruler")
    return Step(lines, tuple(lookalike_warning(chosen.alphabet)), tuple(outputs), chosen)
