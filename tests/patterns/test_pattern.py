"""Coded-patch templates and printable pages: tags unique in a session, corners as the grid implies, exact size.

The PDF is measured back from its own vector data with pdfium (an independent PDF reader): the white
squares' sides and the spacing of their centres give the pitch, the scale bar's cells its length.
"""

from __future__ import annotations

import itertools
import re
import tomllib
import xml.etree.ElementTree as ET

import numpy as np
import pytest

from handcap import HandcapError
from handcap.cli import main
from handcap.patterns import (ALPHABET, DEXTERCAP_ALPHABET, HAND_PATCHES, Patch, Pattern, check_alphabet,
                            session_pattern, tag, tag_count, tag_index)
from handcap.patterns.alphabet import lookalike_warning, lookalikes
from handcap.patterns.glyphs import load_font
from handcap.patterns.pattern import checker_tags
from handcap.patterns.session import own_object
from handcap.patterns.sheet import write_sheets
from handcap.layouts import load_layout

pdfium = pytest.importorskip("pypdfium2", reason="pypdfium2 (test extra) reads the PDF back")
MM = 25.4 / 72  # millimetres per PDF point


def test_tags_are_a_bijection_whose_neighbours_differ_in_both_glyphs():
    for alphabet in (ALPHABET, DEXTERCAP_ALPHABET):
        n = len(alphabet)
        tags = [tag(k, alphabet) for k in range(n * n)]
        assert len(set(tags)) == n * n == tag_count(alphabet)
        assert {a + b for a, b in itertools.product(alphabet, repeat=2)} == set(tags)
        assert [tag_index(t, alphabet) for t in tags] == list(range(n * n))
        assert all(a[0] != b[0] and a[1] != b[1] for a, b in zip(tags, tags[1:]))
    assert len(ALPHABET) == 27 and len(DEXTERCAP_ALPHABET) == 18


@pytest.mark.parametrize("bad", ["", "A", "AA", "AB C", "AB*", "AB-", 'AB"', "AB\n"])
def test_bad_alphabets_are_refused(bad):
    with pytest.raises(HandcapError, match="alphabet"):
        check_alphabet(bad)


def test_tags_past_the_alphabet_and_foreign_glyphs_are_refused():
    with pytest.raises(HandcapError, match="only 324 tags"):
        tag(324, DEXTERCAP_ALPHABET)
    with pytest.raises(HandcapError, match="not two glyphs"):
        tag_index("0B", ALPHABET)


def test_a_session_of_two_hands_three_objects_and_the_cube_has_unique_tags(tmp_path):
    pattern = session_pattern()
    path = pattern.save(tmp_path / "pattern.toml")
    doc = tomllib.loads(path.read_text())  # read with the standard library, not our reader
    tags, white, owners = [], 0, set()
    for table in doc["patches"].values():
        grid = table["tags"]
        assert len(grid) == table["rows"] and all(len(row) == table["cols"] for row in grid)
        for r, row in enumerate(grid):
            for c, text in enumerate(row):
                assert bool(text) == ((r + c) % 2 == 0)  # a checkerboard: white squares carry the tags
                if text:
                    tags.append(text)
        white += (table["rows"] * table["cols"] + 1) // 2
        owners.add(table["owner"])
    assert owners == {"right", "left", "cuboid", "cylinder", "sphere", "cube2x2"}
    assert len(tags) == white == len(set(tags))
    assert 600 <= len(tags) <= 729  # the 700-800 tags for such a session, within 27**2
    assert len([t for t in doc["patches"].values() if t["owner"] == "right"]) == 19
    assert len([t for t in doc["patches"].values() if t["owner"] == "cube2x2"]) == 24
    assert Pattern.load(path) == pattern


def test_corners_are_the_grid_vertices_that_touch_a_white_square():
    patch = Patch("p", "o", "palm", checker_tags(3, 4, iter(tag(k) for k in range(6)).__next__))
    # Independent count: a vertex touches the squares (r-1..r, c-1..c) inside the grid.
    expected = [(r, c) for r in range(4) for c in range(5)
                if any((rr + cc) % 2 == 0 for rr in (r - 1, r) for cc in (c - 1, c) if 0 <= rr < 3 and 0 <= cc < 4)]
    assert [tuple(v) for v in patch.vertices()] == expected
    assert patch.corner_names()[0] == "o:p_r0c0" and patch.corner_name(2, 3, owner=False) == "p_r2c3"
    # Every inner vertex belongs to exactly two white squares, as in a checkerboard.
    uses = {}
    for _, r, c in patch.blocks():
        for v in patch.block_vertices(r, c):
            uses[v] = uses.get(v, 0) + 1
    assert set(uses) == set(expected)
    assert all(uses[(r, c)] == 2 for r in range(1, 3) for c in range(1, 4))
    assert patch.block_vertices(1, 2) == ((1, 2), (1, 3), (2, 3), (2, 2))


def test_the_dense_patches_layout_lists_the_rigid_corners_of_one_hand_of_the_pattern():
    layout = load_layout("dense-patches")
    pattern = session_pattern(("right",), ())
    printed = {n.split(":", 1)[1] for n in pattern.corner_names()}
    names = [m.name for m in layout.markers]
    assert set(names) <= printed and len(names) == len(set(names)) and len(names) > 0.65 * len(printed)
    assert {m.patch for m in layout.markers} == set(HAND_PATCHES)
    by_name = {m.name: np.asarray(m.position) for m in layout.markers}
    # Neighbouring corners of a patch lie one 5 mm square apart on the skin (the tape does not stretch).
    steps = []
    for patch in pattern.patches:
        for r, c in patch.vertices():
            here, right = patch.corner_name(r, c, owner=False), patch.corner_name(r, c + 1, owner=False)
            if here in by_name and right in by_name:
                steps.append(np.linalg.norm(by_name[right] - by_name[here]))
    assert len(steps) > 200 and 0.0045 < np.median(steps) < 0.0052 and np.min(steps) > 0.0035
    # Each patch reads unmirrored from outside the skin: column x row points into the hand.
    centre = np.mean(list(by_name.values()), axis=0)
    for patch in pattern.of_owner("right"):
        if patch.name.startswith(("dorsum", "palm")):
            grid = {(r, c): by_name[patch.corner_name(r, c, owner=False)] for r, c in patch.vertices()
                    if patch.corner_name(r, c, owner=False) in by_name}
            (r0, c0) = min(grid)
            dc = grid[max(k for k in grid if k[0] == r0)] - grid[(r0, c0)]
            dr = grid[max(k for k in grid if k[1] == c0)] - grid[(r0, c0)]
            outward = grid[(r0, c0)] - centre
            assert np.cross(dc, dr) @ outward < 0, patch.name


@pytest.mark.parametrize("text, match", [
    ("format = 'other'\n", "not a handcap pattern"),
    ("format = 'handcap-pattern'\n[patches.'a:b']\nname = 'b'\nowner = 'a'\nsegment = 'palm'\nrows = 1\ncols = 2\n"
     "tags = [['00', '']]\ncorners = ['a:b_r0c0']\n", "corners list"),
    ("format = 'handcap-pattern'\n[patches.'a:b']\nname = 'b'\nowner = 'a'\nsegment = 'palm'\nrows = 1\ncols = 3\n"
     "tags = [['00', '', '00']]\n", "on both"),
    ("format = 'handcap-pattern'\n[patches.'a:b']\nname = 'b'\nowner = 'a'\nsegment = 'palm'\nrows = 1\ncols = 1\n"
     "tags = [['0B']]\n", "not two glyphs"),
    ("format = 'handcap-pattern'\n[patches.'a:b']\nname = 'b'\nowner = 'a'\nrows = 1\ncols = 1\ntags = [['00']]\n",
     "missing or mistypes"),
    ("format = 'handcap-pattern'\npitch = 5\n[patches.'a:b']\nname = 'b'\nowner = 'a'\nsegment = 'palm'\nrows = 1\n"
     "cols = 1\ntags = [['00']]\n", "pitch"),
])
def test_broken_templates_are_one_clear_error(tmp_path, text, match):
    path = tmp_path / "pattern.toml"
    path.write_text(text)
    with pytest.raises(HandcapError, match=match):
        Pattern.load(path)


def test_a_binary_file_is_not_a_template(tmp_path):
    path = tmp_path / "pattern.toml"
    path.write_bytes(bytes(range(256)))
    with pytest.raises(HandcapError, match="not valid TOML"):
        Pattern.load(path)


MUG = {"side": (3, 12), "lid": (3, 3)}


def test_own_objects_are_read_from_their_spec():
    assert own_object("mug=side:3x12,lid:3x3") == ("mug", MUG)
    assert list(own_object(" drill-2=grip:4X6 , trigger:1x3 ")[1]) == ["grip", "trigger"]  # the order given
    pattern = session_pattern(("left",), (), own=dict([own_object("mug=side:3x12,lid:3x3")]))
    side = pattern.patch("mug:side")
    assert (side.rows, side.cols, side.segment) == (3, 12, "object:mug")
    assert len(pattern.of_owner("mug")) == 2 and len(pattern.tags) == len(set(pattern.tags)) == 188 + 18 + 5
    assert "mug:lid_r3c3" in pattern.corner_names()


@pytest.mark.parametrize("spec, match", [
    ("mug", "NAME=FACE:RxC"), ("mug=", "NAME=FACE:RxC"), ("mug=side", "not FACE:RxC"), ("mug=side:3", "not FACE:RxC"),
    ("mug=side:3x12,", "not FACE:RxC"), ("mug=side:0x3", "1 to 200"), ("mug=side:3x201", "1 to 200"),
    ("mug=side:3x3,side:2x2", "given twice"), ("left=back:3x3", "hand's or a standard object's"),
    ("cuboid=xp:4x4", "hand's or a standard object's"), ("my mug=side:3x3", "NAME=FACE:RxC"),
    ("mug=si/de:3x3", "not FACE:RxC"),
])
def test_bad_own_objects_are_one_clear_error(spec, match):
    with pytest.raises(HandcapError, match=match):
        own_object(spec)


def test_an_extended_session_keeps_its_tags_and_gives_the_new_patches_unused_ones():
    mug = {"mug": MUG}
    whole = session_pattern(("right",), ("cuboid",), own=mug)
    # Extending the first part of a session gives the session made whole at once.
    assert session_pattern((), ("cuboid",), own=mug, base=session_pattern(("right",), ())) == whole
    # A session whose tags are not the first ones: the left hand printed alone, the right hand added later.
    left = session_pattern(("left",), ("sphere",))
    left = Pattern(tuple(p for p in left.patches if p.owner == "left"), left.alphabet, left.pitch)  # tags after 0
    both = session_pattern(("right",), (), own=mug, base=left)
    assert both.patches[:19] == left.patches and both.owners == ("left", "right", "mug")
    new = {t for p in both.patches[19:] for row in p.tags for t in row if t}
    assert not new & set(left.tags) and len(both.tags) == len(set(both.tags)) == 2 * 188 + 23
    assert sorted(both.tags) == sorted(set(both.tags))
    # What cannot be added to a printed session.
    for kwargs, match in (({"hands": ("left",)}, "'left' already has patches"),
                          ({"own": {"right": MUG}}, "hand's or a standard object's"),
                          ({"pitch": 0.004, "own": mug}, "4 mm squares|5 mm squares"),
                          ({"alphabet": DEXTERCAP_ALPHABET, "own": mug}, "alphabet"),
                          ({"own": {"big": {"a": (40, 30)}}}, "uses 188 of the 729 tags .* need 600 more")):
        with pytest.raises(HandcapError, match=match):
            session_pattern(**{"hands": (), "objects": (), **kwargs}, base=left)


def _page_objects(pdf_path, page: int = 0):
    doc = pdfium.PdfDocument(str(pdf_path))
    pdf_page = doc[page]
    size = np.array(pdf_page.get_size()) * MM
    boxes = np.array([obj.get_bounds() for obj in pdf_page.get_objects()]) * MM  # left, bottom, right, top, mm
    return doc, size, boxes


@pytest.mark.parametrize("pitch_mm", [5.0, 4.0])
def test_the_pdf_measured_from_its_vector_data_has_the_nominal_pitch(tmp_path, pitch_mm):
    pattern = session_pattern(("right",), ("cuboid",), pitch=pitch_mm / 1000)
    write_sheets(pattern, load_font(None, pattern.alphabet), tmp_path / "p.pdf", tmp_path / "p")
    doc, size, boxes = _page_objects(tmp_path / "p.pdf")
    assert np.allclose(size, (210, 297), atol=0.01)
    w, h = boxes[:, 2] - boxes[:, 0], boxes[:, 3] - boxes[:, 1]
    squares = boxes[(np.abs(w - pitch_mm) < 0.25 * pitch_mm) & (np.abs(h - pitch_mm) < 0.25 * pitch_mm)]
    assert len(squares) > 100
    sides = np.r_[squares[:, 2] - squares[:, 0], squares[:, 3] - squares[:, 1]]
    assert abs(np.median(sides) / pitch_mm - 1) < 0.005
    # Centres of diagonal neighbours in a checkerboard lie (pitch, pitch) apart.
    centres = np.c_[squares[:, 0] + squares[:, 2], squares[:, 1] + squares[:, 3]] / 2
    d = np.abs(centres[:, None] - centres[None])
    diagonal = d[(np.abs(d[..., 0] - d[..., 1]) < 0.1 * pitch_mm) & (d[..., 0] > 0.5 * pitch_mm)
                 & (d[..., 0] < 1.5 * pitch_mm)]
    assert len(diagonal) > 100 and abs(np.median(diagonal) / pitch_mm - 1) < 0.005
    # The scale bar: ten 5 mm cells in a row (their bounds include a hairline outline), 50 mm in all.
    bar = boxes[(np.abs(w - 5) < 0.3) & (np.abs(h - 2) < 0.3)]
    assert len(bar) == 10
    assert abs((bar[:, 0].max() - bar[:, 0].min()) / 45 - 1) < 0.005
    assert len(doc) >= 1


def test_svg_pages_are_exact_size_and_pdf_bytes_repeat(tmp_path):
    whole = session_pattern(("left",), ())
    pattern = Pattern(whole.patches[:5], whole.alphabet, whole.pitch)
    font = load_font(None, pattern.alphabet)
    first = write_sheets(pattern, font, tmp_path / "a.pdf", tmp_path / "a")
    write_sheets(pattern, font, tmp_path / "b.pdf", tmp_path / "b")
    assert (tmp_path / "a.pdf").read_bytes() == (tmp_path / "b.pdf").read_bytes()
    assert (tmp_path / "a-1.svg").read_bytes() == (tmp_path / "b-1.svg").read_bytes()
    svg = ET.parse(first[1]).getroot()
    width, height = (float(svg.get(k).removesuffix("pt")) * MM for k in ("width", "height"))
    assert abs(width - 210) < 0.01 and abs(height - 297) < 0.01


def test_the_pattern_command(tmp_path, capsys):
    out = tmp_path / "sheets"
    assert main(["pattern", "--out", str(out), "--hands", "left", "--objects", "cuboid", "--no-svg"]) == 0
    assert "25 patches" in capsys.readouterr().out
    pattern = Pattern.load(out / "pattern.toml")
    assert len(pattern.of_owner("left")) == 19 and len(pattern.of_owner("cuboid")) == 6
    assert (out / "pattern.pdf").stat().st_size > 0 and sorted(p.name for p in out.iterdir()) == ["pattern.pdf",
                                                                                                  "pattern.toml"]
    before = (out / "pattern.toml").read_bytes()
    # Never over a folder with files, nor over its own template.
    assert main(["pattern", "--out", str(out)]) == 2
    assert main(["pattern", "--out", str(out), "--template", str(out / "pattern.toml"), "--force"]) == 2
    assert (out / "pattern.toml").read_bytes() == before
    again = tmp_path / "again"
    assert main(["pattern", "--out", str(again), "--template", str(out / "pattern.toml"), "--objects", "none"]) == 0
    assert sorted(p.name for p in again.iterdir())[:1] == ["pattern-1.svg"]
    assert (again / "pattern.pdf").exists() and not (again / "pattern.toml").exists()
    err = capsys.readouterr().err
    assert "Traceback" not in err


def test_the_pattern_command_extends_a_printed_session(tmp_path, capsys):
    first, later = tmp_path / "first", tmp_path / "later"
    assert main(["pattern", "--out", str(first), "--hands", "right", "--objects", "none", "--no-svg"]) == 0
    before = (first / "pattern.toml").read_bytes()
    assert main(["pattern", "--out", str(later), "--extend", str(first / "pattern.toml"), "--object",
                 "mug=side:3x12,lid:3x3", "--object", "drill=grip:4x6", "--objects", "cuboid", "--no-svg"]) == 0
    out = capsys.readouterr().out
    assert "19 patches of" in out and "prints the 9 new ones (cuboid, mug, drill)" in out
    assert (first / "pattern.toml").read_bytes() == before  # the printed session's template is untouched
    old, new = Pattern.load(first / "pattern.toml"), Pattern.load(later / "pattern.toml")
    assert new.patches[:19] == old.patches and new.owners == ("right", "cuboid", "mug", "drill")
    assert new == session_pattern(("right",), ("cuboid",), own={"mug": MUG, "drill": {"grip": (4, 6)}})
    # The PDF prints the new patches only: their names under them, none of the hand's.
    doc = pdfium.PdfDocument(str(later / "pattern.pdf"))
    text = " ".join(doc[k].get_textpage().get_text_range() for k in range(len(doc)))
    assert "mug:side" in text and "drill:grip" in text and "cuboid:zn" in text and "right:" not in text
    pages = len(doc)
    doc.close()
    assert pages == 1
    # Not into the printed session's folder, not with --template, and not with nothing to add.
    for args, match in ((["--out", str(first), "--force", "--object", "m=a:2x2"], "holds the input"),
                        (["--out", str(tmp_path / "x"), "--template", str(first / "pattern.toml")], "give one of"),
                        (["--out", str(tmp_path / "x")], "nothing to add"),
                        (["--out", str(tmp_path / "x"), "--hands", "right"], "already has patches"),
                        (["--out", str(tmp_path / "x"), "--object", "m=a:2x2", "--object", "m=b:2x2"], "given twice"),
                        (["--out", str(tmp_path / "x"), "--pitch", "4", "--object", "m=a:2x2"], "5 mm squares")):
        assert main(["pattern", "--extend", str(first / "pattern.toml"), *args]) == 2
        err = capsys.readouterr().err
        assert match in err and len(err.strip().splitlines()) == 1
    assert (first / "pattern.toml").read_bytes() == before and not (tmp_path / "x").exists()
    # A worn patch printed again: the PDF holds it alone.
    assert main(["pattern", "--out", str(tmp_path / "worn"), "--template", str(later / "pattern.toml"), "--only",
                 "mug:s*,right:index_distal", "--no-svg"]) == 0
    assert "prints 2 of the template's 28 patches (--only): right:index_distal, mug:side" in capsys.readouterr().out
    doc = pdfium.PdfDocument(str(tmp_path / "worn" / "pattern.pdf"))
    text = doc[0].get_textpage().get_text_range()
    doc.close()
    assert "right:index_distal" in text and "mug:side" in text and "mug:lid" not in text and "index_middle" not in text
    assert main(["pattern", "--out", str(tmp_path / "y"), "--template", str(later / "pattern.toml"), "--only",
                 "mug:handle"]) == 2
    assert "--only 'mug:handle': no patch" in capsys.readouterr().err and not (tmp_path / "y").exists()


def test_the_check_reads_the_print_back_and_warns_of_a_font_that_reads_poorly(tmp_path, capsys, monkeypatch):
    import matplotlib
    from pathlib import Path

    from handcap.steps import pattern as pattern_step

    monkeypatch.setattr(pattern_step, "CHECK_PHOTOS", 4)  # half the photographs, for the suite's time

    italic = Path(matplotlib.__file__).parent / "mpl-data" / "fonts" / "ttf" / "STIXGeneralItalic.ttf"
    figures = {}
    for name, font in (("default", []), ("italic", ["--font", str(italic)])):
        assert main(["pattern", "--out", str(tmp_path / name), "--hands", "none", "--objects", "cuboid,cylinder",
                     "--no-svg", "--check", *font]) == 0
        captured = capsys.readouterr()
        (line,) = [x for x in captured.out.splitlines() if x.startswith("check:")]
        right, visible = re.search(r"tags: ([0-9.]+) % of (\d+) visible read right", line).groups()
        figures[name] = float(right), int(visible), captured.err
    assert figures["default"][0] >= 95 and figures["default"][1] > 50 and "reads best" not in figures["default"][2]
    assert figures["italic"][0] < figures["default"][0] - 5  # read back against the truth of the rendered print
    assert f"read {figures['italic'][0]:.1f} % of the tags printed in STIXGeneral Italic right" in figures["italic"][2]


def test_alphabets_with_glyphs_fonts_draw_alike_are_warned_of(tmp_path, capsys):
    assert lookalikes(ALPHABET) == [] and lookalikes(DEXTERCAP_ALPHABET) == []
    assert lookalikes("Q0OD") == ["0O", "0D", "0Q", "OD", "OQ", "DQ"] and lookalike_warning("AB") == []
    assert "and 1 more" in lookalike_warning("0OQD@")[0]
    wide = "0123456789ABCDEFGHIJKLMNOPQRSTUVWXYZ"
    assert main(["pattern", "--out", str(tmp_path / "p"), "--hands", "left", "--objects", "none", "--no-svg",
                 "--alphabet", wide]) == 0
    err = capsys.readouterr().err
    assert "draw alike (0 and O, 0 and D, 0 and Q, O and D, O and Q, D and Q and 8 more)" in err
    assert main(["pattern", "--out", str(tmp_path / "q"), "--hands", "left", "--objects", "none", "--no-svg"]) == 0
    assert "draw alike" not in capsys.readouterr().err


@pytest.mark.parametrize("args, match", [
    (["--alphabet", DEXTERCAP_ALPHABET], "only 324 tags"),
    (["--alphabet", "AAB"], "appears twice"),
    (["--objects", "teapot"], "teapot"),
    (["--hands", "middle"], "right or left"),
    (["--pitch", "0"], "pitch"),
    (["--font", "/dev/null"], "font"),
])
def test_bad_pattern_arguments_exit_2_with_one_line(tmp_path, capsys, args, match):
    assert main(["pattern", "--out", str(tmp_path / "x"), *args]) == 2
    err = capsys.readouterr().err
    assert match in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "x").exists() or not any((tmp_path / "x").iterdir())
