"""``handcap pattern``: printable coded patches and their template."""

from __future__ import annotations

from handcap.core.errors import HandcapError
from handcap.patterns.alphabet import ALPHABET
from handcap.patterns.session import HANDS, OBJECT_PATCHES
from handcap.patterns.sheet import PAPERS
from handcap.steps import pattern as pattern_step


def _list(text: str) -> tuple[str, ...]:
    return tuple(t.strip() for t in text.split(",") if t.strip()) if text not in ("", "none") else ()


def _cmd_pattern(a):
    if a.import_grids is not None:
        given = [flag for flag, value in (("--hands", a.hands), ("--objects", a.objects), ("--object", a.object),
                                          ("--extend", a.extend), ("--template", a.template), ("--only", a.only),
                                          ("--font", a.font), ("--check", a.check)) if value]
        if given:
            raise HandcapError(f"--import reads the template of patches printed already; {given[0]} does not go "
                               "with it (print them again afterwards with --template OUT/pattern.toml)")
        return pattern_step.import_pattern(a.out, a.import_grids, owners=a.owner or (), alphabet=a.alphabet,
                                           pitch_mm=5.0 if a.pitch is None else a.pitch, force=a.force)
    if a.owner:
        raise HandcapError("--owner gives the patches of an --import to hands and objects; give --import too")
    return pattern_step.pattern(a.out, hands=None if a.hands is None else _list(a.hands),
                                objects=None if a.objects is None else _list(a.objects), own=a.object or (),
                                alphabet=a.alphabet, pitch_mm=a.pitch, font=a.font, paper=a.paper,
                                template=a.template, extend=a.extend, only=_list(a.only or ""), svg=not a.no_svg,
                                force=a.force, check=a.check)


def add_pattern(verbs) -> None:
    p = verbs.add_parser("pattern", help="printable coded patches (PDF, SVG) and their template pattern.toml",
                         description="Write the coded checkerboard patches of a capture session: 19 per hand "
                                     "(knuckles, dorsum, palm) and the faces of its objects, every white square "
                                     "with a two-glyph tag unique in the session (the first glyph underlined), "
                                     "at exact physical size with a 50 mm scale bar; and pattern.toml, the "
                                     "template that handcap detect and the layouts use.")
    p.add_argument("--out", required=True, help="folder to write pattern.toml, pattern.pdf and pattern-N.svg into")
    p.add_argument("--hands", help=f"hands that wear patches: right,left, right, left or none (default "
                                   f"{','.join(HANDS)}; none with --extend)")
    p.add_argument("--objects", help=f"standard objects with patches, comma-separated from "
                                     f"{', '.join(OBJECT_PATCHES)}, or none (default all; none with --extend)")
    p.add_argument("--object", action="append", metavar="NAME=FACE:RxC,...",
                   help="an object of your own and the patch of each face, rows x columns of squares, e.g. "
                        "mug=side:3x12,lid:3x3 (repeat for more objects); track it with track-object "
                        "--markers 'mug:*'")
    p.add_argument("--extend", metavar="PATTERN_TOML",
                   help="add to a session already printed: the new pattern.toml keeps its patches and tags, the new "
                        "patches get tags it does not use, and the PDF prints the new ones only")
    p.add_argument("--alphabet", help=f"glyphs of the tags (default {ALPHABET}, or those of --extend; DexterCap's "
                                      "patches use 0123456789ACEFHPUY)")
    p.add_argument("--pitch", type=float, help="side of a square, mm (default 5, or that of --extend)")
    p.add_argument("--font", help="a bold monospace .ttf/.otf font for the glyphs (default: DejaVu Sans Mono Bold, "
                                  "shipped with matplotlib)")
    p.add_argument("--paper", choices=tuple(PAPERS), default="a4", help="page size (default %(default)s)")
    p.add_argument("--template", help="print the patches of this pattern.toml instead of making a new template")
    p.add_argument("--only", metavar="PATCHES",
                   help="print only these patches, OWNER:NAME comma-separated (shell patterns such as "
                        "'right:index_*' work): a worn patch printed again with --template")
    p.add_argument("--import", dest="import_grids", metavar="JSON",
                   help="write pattern.toml for patches printed already by another generator, from its template: "
                        "DexterCap's JSON of patch grids, {name: [\"9F**CF\", ...]} (** for a black square); the "
                        "alphabet is the glyphs its tags use unless --alphabet")
    p.add_argument("--owner", action="append", metavar="PATCHES=OWNER",
                   help="with --import: the patches whose name matches the shell pattern belong to this hand side or "
                        "object, e.g. 'cube_*=cube' (repeat; the first that matches wins; default: right)")
    p.add_argument("--check", action="store_true",
                   help="also render photographs of the printed patches in their font and read them back with the "
                        "shipped networks: how well handcap detect reads this print (a few seconds)")
    p.add_argument("--no-svg", action="store_true", help="write the PDF only")
    p.add_argument("--force", action="store_true", help="write into a folder that already holds files")
    p.set_defaults(run=_cmd_pattern)
