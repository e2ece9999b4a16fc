"""Templates of patches printed by another generator (DexterCap's patch JSON) imported as handcap templates.

The grids, corner names and owners are checked against the rows as written; bad and fuzzed files give only
``HandcapError``; the command never writes into its input's folder and leaves the input as it was. Reading
rendered photographs through an imported template is in tests/detect/test_detect_command.py.
"""

from __future__ import annotations

import json

import numpy as np
import pytest

from handcap import HandcapError
from handcap.cli import main
from handcap.patterns import Pattern
from handcap.patterns.foreign import import_template, owner_rule, read_grids

#: A template as DexterCap's generator writes it (its docstring's example rows, and two faces of a cube).
DEXTERCAP = {"thumb_1": ["9F**CF**EF**", "**8L**9L**CL", "7S**8S**9S**"],
             "cube_up": ["A0**C0", "**E0**", "H0**N0"],
             "cube_down": ["A1 ** C1", "** E1 **", "H1 ** 91"]}


def _write(tmp_path, doc, name="patches.json"):
    path = tmp_path / name
    path.write_text(doc if isinstance(doc, str) else json.dumps(doc))
    return path


def test_the_grids_owners_and_corners_are_those_the_rows_give(tmp_path):
    pattern, warnings = import_template(_write(tmp_path, DEXTERCAP), owners=["cube_*=cube"])
    assert warnings == []
    assert [p.key for p in pattern.patches] == ["right:thumb_1", "cube:cube_up", "cube:cube_down"]
    thumb = pattern.patch("right:thumb_1")
    assert thumb.tags[0] == ("9F", "", "CF", "", "EF", "") and thumb.tags[1][5] == "CL"
    assert (thumb.rows, thumb.cols) == (3, 6)
    # Spaces between cells are read as cells too.
    assert pattern.patch("cube:cube_down").tags == (("A1", "", "C1"), ("", "E1", ""), ("H1", "", "91"))
    # Tag 8L at row 1, column 1: its corners in reading order are the vertices (1,1), (1,2), (2,2), (2,1).
    patch, r, c = pattern.locate("8L")
    assert (patch.key, r, c) == ("right:thumb_1", 1, 1)
    assert [patch.corner_name(*v) for v in patch.block_vertices(r, c)] == [
        "right:thumb_1_r1c1", "right:thumb_1_r1c2", "right:thumb_1_r2c2", "right:thumb_1_r2c1"]
    # The alphabet is the glyphs the tags use, digits first; the pitch is DexterCap's 5 mm.
    assert pattern.alphabet == "01789ACEFHLNS" and pattern.pitch == 0.005
    # Given, the alphabet is kept as it is (the generator's order).
    assert import_template(_write(tmp_path, DEXTERCAP), alphabet="0123456789ACEFHLNSPUY")[0].alphabet == \
        "0123456789ACEFHLNSPUY"
    # Without rules every patch is the right hand's; the first rule that matches wins.
    assert import_template(_write(tmp_path, DEXTERCAP))[0].owners == ("right",)
    ruled = import_template(_write(tmp_path, DEXTERCAP), owners=["cube_up=lid", "cube_*=cube", "*=left"])[0]
    assert [p.owner for p in ruled.patches] == ["left", "lid", "cube"]
    assert owner_rule(" cube_* = cube ") == ("cube_*", "cube")


def test_a_tag_printed_twice_names_no_corner_and_is_warned_of(tmp_path):
    """That generator's counter starts again after L * L - 2 tags: a repeated tag cannot say which square it is."""
    doc = {"a": ["9F**CF", "**8L**"], "b": ["9F**", "**CF"], "c": ["8L**"], "d": ["A0**", "**C0"]}
    pattern, warnings = import_template(_write(tmp_path, doc))
    assert pattern.locate("9F") is None and pattern.locate("CF") is None and pattern.locate("8L") is None
    assert [p.key for p in pattern.patches] == ["right:d"] and pattern.tags == ("A0", "C0")
    (twice, empty) = warnings
    assert "3 tags are printed on more than one square (6 squares; 9F on a r0c0, b r0c0;" in twice
    assert "3 patches are left without a tag of their own and are not in the template: a, b, c" in empty


def test_a_patch_keeps_the_corners_its_other_tags_give(tmp_path):
    doc = {"a": ["9F**CF", "**8L**"], "b": ["9F**A0"]}
    pattern, (warning,) = import_template(_write(tmp_path, doc))
    assert "1 tag is printed on more than one square" in warning
    a = pattern.patch("right:a")
    assert a.tags == (("", "", "CF"), ("", "8L", ""))
    assert "right:a_r1c1" in a.corner_names() and "right:a_r0c0" not in a.corner_names()


@pytest.mark.parametrize("text, match", [
    ("", "not valid JSON"),
    ('{"a": ["9F**CF"', "not valid JSON"),
    ("[1, 2]", "JSON object of patch grids"),
    ("{}", "JSON object of patch grids"),
    ('{"a": "9F**CF"}', "give its rows as a list"),
    ('{"a": []}', "give its rows as a list"),
    ('{"a": [7]}', "not a row of two-glyph cells"),
    ('{"a": ["9F*"]}', "not a row of two-glyph cells"),
    ('{"a": [""]}', "not a row of two-glyph cells"),
    ('{"a": [["9F", "C"]]}', "not a row of two-glyph cells"),
    ('{"a": ["9F**", "**"]}', "rows hold 1 and 2 cells"),
    ('{"a": ["****"]}', "no patch holds a tag"),
    ('{"a": ["9$**"]}', "reader knows no glyph '\\$'"),
    ('{"a": ["9f**"]}', "reader knows no glyph 'f'"),
    ('{"my patch": ["9F**"]}', "names take letters"),
    ('{"a": ["9F**"], "A": ["9F**"]}', "no patch keeps a tag"),
    ("[" * 100000 + "]" * 100000, "not valid JSON"),
])
def test_bad_templates_are_one_clear_error(tmp_path, text, match):
    with pytest.raises(HandcapError, match=match):
        import_template(_write(tmp_path, text))


def test_bad_alphabets_owners_and_files_are_one_clear_error(tmp_path):
    path = _write(tmp_path, DEXTERCAP)
    with pytest.raises(HandcapError, match="'L', 'N', 'S'|not in the alphabet"):
        import_template(path, alphabet="0123456789ACEFHPUY")
    with pytest.raises(HandcapError, match="PATCHES=OWNER"):
        import_template(path, owners=["cube_*"])
    with pytest.raises(HandcapError, match="names take letters"):
        import_template(path, owners=["*=my hand"])
    (tmp_path / "bin.json").write_bytes(b"\xff\xfe\x00garbage")
    with pytest.raises(HandcapError, match="not UTF-8"):
        read_grids(tmp_path / "bin.json")
    with pytest.raises(HandcapError, match="no such file"):
        read_grids(tmp_path / "missing.json")
    with pytest.raises(HandcapError, match="is a folder"):
        read_grids(tmp_path)


def test_fuzzed_templates_raise_only_handcap_errors(tmp_path):
    rng = np.random.default_rng(16)
    pieces = ['{', '}', '[', ']', '"a"', '"cube_up"', ':', ',', '"9F**CF"', '"**8L**"', '"9F"', '"**"', '"$%"',
              'null', '1e400', '-1', '"A0 ** C0"', '"x"', 'true', '""']
    read = 0
    for k in range(400):
        path = _write(tmp_path, "".join(rng.choice(pieces, rng.integers(1, 16))), f"f{k}.json")
        try:
            import_template(path)
            read += 1
        except HandcapError:
            pass
    raw = tmp_path / "raw.json"
    for _ in range(100):
        raw.write_bytes(rng.bytes(int(rng.integers(0, 300))))
        with pytest.raises(HandcapError):
            import_template(raw)
    assert read < 400


def test_the_import_command_writes_a_template_detect_reads_and_leaves_its_input(tmp_path, capsys):
    src = tmp_path / "theirs"
    src.mkdir()
    path = _write(src, DEXTERCAP)
    before = path.read_bytes()
    out = tmp_path / "ours"
    assert main(["pattern", "--import", str(path), "--owner", "cube_*=cube", "--pitch", "4.5", "--out",
                 str(out)]) == 0
    printed = capsys.readouterr().out
    assert "imported 3 patches" in printed and "right 1, cube 2" in printed
    assert sorted(p.name for p in out.iterdir()) == ["pattern.toml"]
    loaded = Pattern.load(out / "pattern.toml")
    assert loaded.pitch == pytest.approx(0.0045) and loaded.locate("8L")[0].key == "right:thumb_1"
    # 3 x 6 squares, white where r + c is even: 4 x 7 vertices less the two right ones no white square touches;
    # the 3 x 3 faces: all 16.
    assert len(loaded.corner_names()) == len(set(loaded.corner_names())) == 26 + 16 + 16
    assert path.read_bytes() == before
    # A template imported with its default owner says where the patches went.
    assert main(["pattern", "--import", str(path), "--out", str(tmp_path / "all")]) == 0
    assert "every patch to right" in capsys.readouterr().out


@pytest.mark.parametrize("extra, match", [
    (["--hands", "right"], "--hands does not go with it"),
    (["--check"], "--check does not go with it"),
    (["--template", "x.toml"], "--template does not go with it"),
    (["--owner", "cube_*"], "PATCHES=OWNER"),
    (["--pitch", "0.01"], "millimetres"),
])
def test_bad_import_arguments_exit_2_with_one_line(tmp_path, capsys, extra, match):
    path = _write(tmp_path, DEXTERCAP)
    assert main(["pattern", "--import", str(path), "--out", str(tmp_path / "out"), *extra]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and match in err[0]
    assert not (tmp_path / "out").exists()


def test_owner_without_import_and_output_beside_the_input_are_refused(tmp_path, capsys):
    path = _write(tmp_path, DEXTERCAP)
    assert main(["pattern", "--owner", "cube_*=cube", "--out", str(tmp_path / "out")]) == 2
    assert "give --import too" in capsys.readouterr().err
    assert main(["pattern", "--import", str(path), "--out", str(tmp_path), "--force"]) == 2
    assert "holds the input" in capsys.readouterr().err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["patches.json"]


def test_a_layout_of_the_imported_hand_patches_has_every_corner_on_its_segment(tmp_path):
    from handcap.patterns.layout import pattern_layout

    pattern, _ = import_template(_write(tmp_path, DEXTERCAP), owners=["cube_*=cube"])
    layout = pattern_layout(pattern, segments=["thumb_*=thumb_distal"], name="theirs")
    assert layout.side == "right" and layout.marker_kind == "patch" and layout.rigid == ()
    assert layout.names == tuple(pattern.patch("right:thumb_1").corner_names(owner=False))
    assert set(layout.segments) == {"thumb_distal"} and all(m.position is None for m in layout.markers)
    assert {m.patch for m in layout.markers} == {"thumb_1"}
    # handcap's own patches know their segments: the layout agrees with the shipped dense-patches on each corner
    # that one lists.
    from handcap.layouts import load_layout
    from handcap.patterns import session_pattern

    own = pattern_layout(session_pattern(("right", "left"), ()), side="left")
    dense = {m.name: m.segment for m in load_layout("dense-patches").markers}
    assert own.side == "left" and len(own) > len(dense)
    assert all(dense[m.name] == m.segment for m in own.markers if m.name in dense)
    assert sum(m.name in dense for m in own.markers) == len(dense)


@pytest.mark.parametrize("side, rules, match", [
    (None, [], "1 patches of the right hand have no segment: thumb_1"),
    (None, ["thumb_*=thumb_dist"], "no hand segment 'thumb_dist' \\(did you mean 'thumb_distal'\\?\\)"),
    (None, ["thumb_*"], "PATCHES=SEGMENT"),
    (None, ["thumb_1=thumb_distal", "index_*=index_distal"], "'index_\\*' matches no patch"),
    ("left", ["thumb_*=thumb_distal"], "no patch of the left hand"),
])
def test_layouts_of_patches_without_a_segment_or_a_hand_are_refused(tmp_path, side, rules, match):
    from handcap.patterns.layout import pattern_layout

    pattern, _ = import_template(_write(tmp_path, DEXTERCAP), owners=["cube_*=cube"])
    with pytest.raises(HandcapError, match=match):
        pattern_layout(pattern, side, rules)


def test_layout_new_from_a_pattern(tmp_path, capsys):
    from handcap.layouts import load_layout

    path = _write(tmp_path, DEXTERCAP)
    assert main(["pattern", "--import", str(path), "--owner", "cube_*=cube", "--out", str(tmp_path / "p")]) == 0
    template = tmp_path / "p" / "pattern.toml"
    before = template.read_bytes()
    out = tmp_path / "theirs.toml"
    assert main(["layout", "new", "--pattern", str(template), "--segment", "thumb_1=thumb_distal", "--out",
                 str(out)]) == 0
    assert "26 corners of 1 patches of the right hand" in capsys.readouterr().out
    layout = load_layout(str(out))
    assert len(layout) == 26 and set(layout.segments) == {"thumb_distal"} and layout.marker_kind == "patch"
    assert "handcap layout new --pattern" in out.read_text() and template.read_bytes() == before
    for args, match in ((["--segment", "thumb_1=thumb_distal"], "give --pattern too"),
                        (["--pattern", str(template), "--like", "glove-13"], "give one"),
                        (["--pattern", str(template)], "have no segment: thumb_1"),
                        (["--pattern", str(template), "--segment", "thumb_1=thumb_distal", "--side", "left"],
                         "no patch of the left hand")):
        assert main(["layout", "new", *args, "--out", str(tmp_path / "bad.toml")]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and match in err[0]
        assert not (tmp_path / "bad.toml").exists()
