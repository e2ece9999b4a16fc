"""Step ``pattern``: printable coded patches (PDF, SVG pages) and their template ``pattern.toml``."""

from __future__ import annotations

from fnmatch import fnmatchcase
from pathlib import Path

from handcap.core.errors import HandcapError
from handcap.core.files import check_output_folder
from handcap.patterns.alphabet import ALPHABET, lookalike_warning
from handcap.patterns.foreign import DEFAULT_OWNER, import_template
from handcap.patterns.glyphs import load_font
from handcap.patterns.pattern import Pattern
from handcap.patterns.session import HANDS, own_object, session_pattern
from handcap.patterns.sheet import write_sheets
from handcap.steps.step import Step

DEFAULT_OBJECTS = ("cuboid", "cylinder", "sphere", "cube2x2")
#: Photographs of the printed pages that ``check`` renders and reads back.
CHECK_PHOTOS = 8
#: Share of their visible tags the shipped networks must read right (and none wrong) before the font is said to
#: read poorly. handcap's own page reads 100 % in the benchmark, held-out fonts 98-99.7 %.
CHECK_READ = 0.95


def pattern(out, *, hands=None, objects=None, own=(), alphabet: str | None = None, pitch_mm: float | None = None,
            font=None, paper: str = "a4", template=None, extend=None, only=(), svg: bool = True,
            force: bool = False, check: bool = False) -> Step:
    """Write a session's coded patches into folder ``out``: ``pattern.toml``, ``pattern.pdf``, ``pattern-N.svg``.

    Parameters
    ----------
    out : str or Path
        Folder to write into (new or empty, or ``force``).
    hands : sequence of {'right', 'left'}, optional
        Hands that wear the 19 patches (default both; none with ``extend``).
    objects : sequence of str, optional
        Objects whose faces carry patches (see :data:`handcap.patterns.session.OBJECT_PATCHES`; default all
        four; none with ``extend``).
    own : sequence of str
        Objects of the user's own, each ``NAME=FACE:RxC[,FACE:RxC...]``
        (:func:`handcap.patterns.session.own_object`).
    alphabet : str, optional
        Glyphs of the tags (default handcap's 27, or those of ``extend``).
    pitch_mm : float, optional
        Side of a square, millimetres (default 5, or that of ``extend``).
    font : str, Path or None
        A .ttf/.otf font for the glyphs (default: DejaVu Sans Mono Bold).
    paper : {'a4', 'letter'}
    template : str, Path or None
        Print this ``pattern.toml`` instead of making one (``hands``, ``objects``, ``alphabet`` and
        ``pitch_mm`` are then taken from it).
    extend : str, Path or None
        The ``pattern.toml`` of patches already printed: the new template holds them, unchanged, and the new
        hands and objects with tags they do not use; the pages print the new patches only.
    only : sequence of str
        Print only the patches whose ``OWNER:NAME`` matches one of these (shell patterns such as
        ``right:index_*``): a worn patch printed again. The template still holds every patch.
    svg : bool
        Also write one SVG per page.
    force : bool
        Write into a folder that holds files.
    check : bool
        Also render :data:`CHECK_PHOTOS` photographs of the printed patches in their font and read them back with
        the shipped networks and the template (:func:`_check`): how well ``detect`` reads this print.
    """
    folder = check_output_folder(out, template, extend, force=force)
    if template is not None and extend is not None:
        raise HandcapError("--template prints a template as it is and --extend adds to one; give one of them")
    base = Pattern.load(extend) if extend is not None else None
    if template is not None:
        chosen = Pattern.load(template)
    else:
        own_objects = [own_object(spec) for spec in own]
        names = [name for name, _ in own_objects]
        if len(set(names)) != len(names):
            raise HandcapError(f"object {next(n for n in names if names.count(n) > 1)!r} is given twice; give each "
                               "object once, with all its faces")
        hands = tuple(hands) if hands is not None else () if base else HANDS
        objects = tuple(objects) if objects is not None else () if base else DEFAULT_OBJECTS
        if base is not None and not (hands or objects or own_objects):
            raise HandcapError(f"--extend {extend}: nothing to add; give --hands, --objects or --object")
        alphabet = alphabet or (base.alphabet if base else ALPHABET)
        pitch_mm = pitch_mm if pitch_mm is not None else base.pitch * 1000 if base else 5.0
        if not 0.5 <= pitch_mm <= 100:
            raise HandcapError(f"--pitch {pitch_mm} mm: give the side of a square in millimetres, 0.5 to 100")
        chosen = session_pattern(hands, objects, own=dict(own_objects), alphabet=alphabet, pitch=pitch_mm / 1000,
                                 base=base)
    glyph_font = load_font(font, chosen.alphabet)
    warnings = lookalike_warning(chosen.alphabet)
    if template is None:
        font_name = base.font if base is not None and base.font else glyph_font.name
        if font_name != glyph_font.name:
            warnings.append(f"the new patches are printed in {glyph_font.name} and those of {extend} in {font_name} "
                            "(give --font to match them); the detector reads both, a little less surely in a font "
                            "it did not learn")
        chosen = Pattern(chosen.patches, chosen.alphabet, chosen.pitch, font_name)
    printed = chosen if base is None else Pattern(chosen.patches[len(base.patches):], chosen.alphabet, chosen.pitch,
                                                  chosen.font)
    if only:
        printed = _only(printed, only)
    folder.mkdir(parents=True, exist_ok=True)
    toml_path = chosen.save(folder / "pattern.toml") if template is None else None
    written = write_sheets(printed, glyph_font, folder / "pattern.pdf", folder / "pattern" if svg else None,
                           paper=paper)
    outputs = ([str(toml_path)] if toml_path else []) + [str(p) for p in written]
    pages = sum(p.suffix == ".svg" for p in written)
    count = f" ({pages} page{'s' if pages > 1 else ''})" if pages else ""
    lines = (chosen.summary(),
             f"wrote {', '.join(Path(p).name for p in outputs)} in {folder}{count}",
             "print the PDF at 100 % (actual size) and check its 50 mm scale bar with a ruler")
    if only:
        lines += (f"the PDF prints {len(printed.patches)} of the template's {len(chosen.patches)} patches (--only): "
                  f"{', '.join(p.key for p in printed.patches[:6])}"
                  + (f" and {len(printed.patches) - 6} more" if len(printed.patches) > 6 else ""),)
    elif base is not None:
        new = len(printed.patches)
        lines += (f"{len(base.patches)} patches of {extend} kept, their tags unchanged; the PDF prints the {new} new "
                  f"one{'s' if new > 1 else ''} ({', '.join(printed.owners)}). Detect the whole session with the new "
                  f"{toml_path}",)
    if check:
        line, doubt = _check(printed, chosen, font, glyph_font.name)
        lines += (line,)
        warnings += doubt
    return Step(lines, tuple(warnings), tuple(outputs), chosen)


def import_pattern(out, source, *, owners=(), alphabet: str | None = None, pitch_mm: float = 5.0,
                   force: bool = False) -> Step:
    """Write ``pattern.toml`` into folder ``out`` from another generator's template of patches already printed.

    Parameters
    ----------
    out : str or Path
        Folder to write into (new or empty, or ``force``).
    source : str or Path
        The generator's JSON of patch grids (DexterCap's ``{patch_name: [row, ...]}``;
        :func:`handcap.patterns.foreign.read_grids`).
    owners : sequence of str
        ``GLOB=OWNER`` rules: the patches whose name matches belong to that hand side or object (the first rule that
        matches wins; the others belong to ``right``).
    alphabet : str, optional
        The printed glyphs (default: those the tags use).
    pitch_mm : float
        Side of a printed square, millimetres.
    force : bool
        Write into a folder that holds files.
    """
    folder = check_output_folder(out, source, force=force)
    if not 0.5 <= pitch_mm <= 100:
        raise HandcapError(f"--pitch {pitch_mm} mm: give the side of a square in millimetres, 0.5 to 100")
    imported, warnings = import_template(source, owners=owners, alphabet=alphabet, pitch=pitch_mm / 1000)
    folder.mkdir(parents=True, exist_ok=True)
    path = imported.save(folder / "pattern.toml")
    counts = {}
    for p in imported.patches:
        counts[p.owner] = counts.get(p.owner, 0) + 1
    lines = (imported.summary(),
             f"imported {len(imported.patches)} patches from {source}: "
             + ", ".join(f"{owner} {n}" for owner, n in counts.items())
             + ("" if owners else f" (every patch to {DEFAULT_OWNER}: give --owner 'cube_*=cube' and the like to "
                                  "give patches to objects)"),
             f"wrote {path}; read the printed patches with handcap detect --pattern {path} (no PDF: they are "
             "printed already; handcap pattern --template prints them again in handcap's font and layout)")
    return Step(lines, tuple(lookalike_warning(imported.alphabet) + warnings), (str(path),), imported)


def _check(printed: Pattern, whole: Pattern, font, font_name: str) -> tuple[str, list[str]]:
    """Photographs of the ``printed`` patches rendered in ``font`` (squares 24-32 px, tilted up to 20 degrees, a
    little curl and blur, no occluder) and read back with the shipped networks and the ``whole`` template: the
    summary line, and a warning where fewer than :data:`CHECK_READ` of the visible tags read right or any wrong."""
    from handcap.detect.evaluation import evaluate_detector  # loads torch
    from handcap.detect.networks import load_checker, load_corner_net, load_reader, load_refiner  # loads torch
    from handcap.detect.pipeline import Detector  # loads torch
    from handcap.detect.scenes import PageLook, PageMaker  # loads torch

    maker = PageMaker(0, pattern=printed, font=font, look=PageLook(square_px=(24.0, 32.0), tilt_deg=(0.0, 20.0),
                                                                   curl=(0.0, 0.5), occluders=(0, 0), glint=0.0))
    detector = Detector(load_corner_net(int8=True), load_reader(), whole, refiner=load_refiner(int8=True),
                        checker=load_checker())
    score = evaluate_detector(detector, [maker.scene() for _ in range(CHECK_PHOTOS)])
    right = score.right / max(score.blocks, 1)
    line = (f"check: {CHECK_PHOTOS} photographs of the printed patches rendered in {font_name} (squares 24-32 px, "
            f"tilted up to 20 degrees) and read back with the shipped networks: {score.summary()}")
    if right >= CHECK_READ and not score.wrong:
        return line, []
    return line, [f"the shipped networks read {100 * right:.1f} % of the tags printed in {font_name} right, "
                  f"{score.wrong} wrong, in rendered photographs: a bold monospace font with open, distinct glyphs "
                  "reads best (DejaVu Sans Mono Bold is the default)"]


def _only(pattern: Pattern, only) -> Pattern:
    """The patches of ``pattern`` whose key matches one of the shell patterns ``only``; each must match one."""
    for want in only:
        if not any(fnmatchcase(p.key, want) for p in pattern.patches):
            raise HandcapError(f"--only {want!r}: no patch to print is called so (patches are OWNER:NAME, e.g. "
                               f"{pattern.patches[0].key}; patterns such as 'right:index_*' work)")
    return Pattern(tuple(p for p in pattern.patches if any(fnmatchcase(p.key, w) for w in only)), pattern.alphabet,
                   pattern.pitch, pattern.font)
