"""Layouts written by users: the commented template and ``check_layout`` (``handcap layout new|check``)."""

import re
import warnings

import numpy as np
import pytest

from handcap import HandcapError
from handcap.cli import main
from handcap.core.errors import HandcapWarning
from handcap.core.markers import MarkerSequence
from handcap.hand.anatomy import SEGMENT_NAMES
from handcap.io import write_markers
from handcap.layouts import (SHIPPED, LayoutMarker, MarkerLayout, check_layout, layout_template, load_layout)
from handcap.layouts.check import MAX_SEGMENT_DISTANCE, match_names
from handcap.synth.scene import SynthConfig, synthesize


@pytest.fixture(scope="module")
def glove_take():
    """A synthetic glove-13 take (open hand slowly turned) with the truth's names, metres."""
    capture = synthesize(SynthConfig(layout="glove-13", motion="calibration", frames=40, ghost_rate=0, seed=3),
                         progress=False)
    return capture.markers


def quiet_check(*args, **kwargs):
    with warnings.catch_warnings(record=True) as issued:
        warnings.simplefilter("always", HandcapWarning)
        result = check_layout(*args, **kwargs)
    assert [str(w.message) for w in issued if w.category is HandcapWarning] == list(result.warnings)
    return result


def edited(layout, **changes):
    """``layout`` with some markers replaced: name -> LayoutMarker (or None to drop it)."""
    markers = []
    for m in layout.markers:
        new = changes.get(m.name, m)
        if new is not None:
            markers.append(new)
    return markers


# -- the template ---------------------------------------------------------------------------------------------
@pytest.mark.parametrize("name", SHIPPED)
def test_template_loads_back_as_the_same_layout(name, tmp_path):
    layout = load_layout(name)
    path = tmp_path / "mine.toml"
    path.write_text(layout_template(layout))
    back = load_layout(path)
    assert back == MarkerLayout(layout.name, layout.side, back.markers, layout.rigid, layout.marker_radius,
                                layout.marker_kind)
    assert back.names == layout.names and back.segments == layout.segments
    np.testing.assert_array_equal(back.positions(), layout.positions())
    assert [m.patch for m in back.markers] == [m.patch for m in layout.markers]


def test_template_explains_every_field_and_lists_every_segment():
    text = layout_template(load_layout("glove-13"))
    comments = "\n".join(line for line in text.splitlines() if line.startswith("#"))
    for word in ("name", "side", "marker_radius", "marker_kind", "rigid", "segment", "position", "prefix",
                 "calibrate-markers", "estimate", "synth", "wrist"):
        assert word in comments, word
    listed = re.findall(r"^#\s{10,}(\w+)\s{2,}", comments, flags=re.M)
    assert listed == list(SEGMENT_NAMES)


def test_template_marks_markers_without_positions(tmp_path):
    layout = load_layout("tips-5")
    markers = edited(layout, index_tip=LayoutMarker("index_tip", "index_distal"))
    text = layout_template(MarkerLayout("mine", "right", tuple(markers), layout.rigid))
    block = text.split("[markers.index_tip]")[1].split("[markers.")[0]
    assert "position = " not in block and "estimated by calibrate-markers" in block


def test_template_without_positions_leaves_every_hand_marker_to_calibration(tmp_path):
    layout = load_layout("joints-19")
    path = tmp_path / "mine.toml"
    path.write_text(layout_template(layout, positions=False))
    back = load_layout(path)
    assert back.names == layout.names and back.rigid == layout.rigid
    assert np.isnan(back.positions()).all()
    result = quiet_check(back)
    assert result.estimated == layout.names and result.distance == {}


# -- checks without a take --------------------------------------------------------------------------------------
@pytest.mark.parametrize("name", SHIPPED)
def test_shipped_layouts_pass_with_positions_on_their_segments(name):
    result = quiet_check(load_layout(name))
    assert result.warnings == ()
    assert max(result.distance.values()) < 0.002  # shipped positions are skin spots of their segment
    assert "verdict   : usable" in result.summary()


def test_left_layout_is_checked_on_the_left_template():
    assert quiet_check(load_layout("glove-13", side="left")).warnings == ()


def test_position_on_the_wrong_finger_is_named_with_its_nearest_segment():
    layout = load_layout("tips-5")
    wrong = LayoutMarker("index_tip", "ring_distal", layout.markers[layout.names.index("index_tip")].position)
    result = quiet_check(MarkerLayout("mine", "right", tuple(edited(layout, index_tip=wrong)), layout.rigid))
    assert result.distance["index_tip"] > MAX_SEGMENT_DISTANCE
    assert len(result.warnings) == 1
    assert re.search(r"index_tip \d+ mm from ring_distal \(nearest segment: index_distal\)", result.warnings[0])


def test_positions_in_millimetres_are_refused():
    layout = load_layout("tips-5")
    markers = tuple(LayoutMarker(m.name, m.segment, m.position * 1000) for m in layout.markers)
    with pytest.raises(HandcapError, match="look like millimetres"):
        check_layout(MarkerLayout("mine", "right", markers, layout.rigid))


def test_markers_without_positions_are_listed_as_estimated():
    layout = load_layout("joints-19")
    markers = tuple(m if m.segment == "palm" else LayoutMarker(m.name, m.segment) for m in layout.markers)
    result = quiet_check(MarkerLayout("mine", "right", markers, layout.rigid))
    fingers = [m.name for m in layout.markers if m.segment != "palm"]
    assert result.estimated == tuple(fingers) and len(fingers) == 15
    assert set(result.distance) == {m.name for m in layout.markers if m.segment == "palm"}
    assert "estimated from the take by calibrate-markers: " in result.summary()


def test_two_rigid_markers_ask_for_a_wrist_marker():
    layout = load_layout("active-9")
    result = quiet_check(MarkerLayout("mine", "right", layout.markers, ("index_base", "pinky_base")))
    assert len(result.warnings) == 1
    assert "rigid set has 2 marker(s)" in result.warnings[0] and "add 'wrist'" in result.warnings[0]
    assert quiet_check(MarkerLayout("mine", "right", layout.markers, ("index_base", "pinky_base", "wrist"))
                       ).warnings == ()


def test_rigid_markers_in_a_line_or_on_two_segments_are_warned():
    layout = load_layout("joints-19")
    by = {m.name: m for m in layout.markers}
    # Three MCP knuckles lie nearly on one line across the hand.
    line = quiet_check(MarkerLayout("mine", "right", layout.markers, ("index_mcp", "middle_mcp", "ring_mcp")))
    assert line.rigid_spread < 0.005
    assert any("of one line" in w for w in line.warnings)
    mixed = quiet_check(MarkerLayout("mine", "right", layout.markers, ("hand_top", "hand_left", "index_pip")))
    assert by["index_pip"].segment == "index_proximal"
    assert any("several segments (index_proximal, palm)" in w for w in mixed.warnings)


def test_touching_spheres_and_a_look_alike_of_the_rigid_set_are_warned():
    layout = load_layout("joints-19")
    by = {m.name: m for m in layout.markers}
    ring = by["ring_mcp"].position
    # hand_top 5.8 mm from ring_mcp: two 6 mm spheres (3 mm radius) 1 mm apart at least, so closer than 7 mm.
    toward = (by["hand_top"].position - ring) / np.linalg.norm(by["hand_top"].position - ring)
    touching = LayoutMarker("hand_top", "palm", ring + 0.0058 * toward)
    result = quiet_check(MarkerLayout("mine", "right", tuple(edited(layout, hand_top=touching)), layout.rigid,
                                      layout.marker_radius))
    assert len(result.warnings) == 1
    assert "closer than their 7 mm spheres allow" in result.warnings[0]
    assert "hand_top-ring_mcp 5.8 mm" in result.warnings[0]
    # 10 mm apart the spheres are clear, but the triangle with ring_mcp looks like the rigid set's own.
    near = LayoutMarker("hand_top", "palm", ring + 0.010 * toward)
    result = quiet_check(MarkerLayout("mine", "right", tuple(edited(layout, hand_top=near)), layout.rigid,
                                      layout.marker_radius))
    assert len(result.warnings) == 1
    assert "rigid markers within 12 mm of another marker of their segment: hand_top-ring_mcp 10.0 mm" in \
        result.warnings[0]
    # The same spot is fine when hand_top is not a rigid marker: two markers 10 mm apart are no look-alike.
    assert quiet_check(MarkerLayout("mine", "right", tuple(edited(layout, hand_top=near)),
                                    ("hand_left", "hand_right", "middle_mcp"), layout.marker_radius)).warnings == ()
    glove = load_layout("glove-13")  # 14 mm spheres: its markers are all farther apart than 15 mm
    assert quiet_check(glove).warnings == ()


def test_no_rigid_set_is_a_warning_for_spheres_only():
    glove = load_layout("glove-13")
    assert any("no rigid set" in w for w in quiet_check(MarkerLayout("m", "right", glove.markers)).warnings)
    assert quiet_check(load_layout("dense-patches")).warnings == ()


# -- checks against a take ----------------------------------------------------------------------------------------
def test_synthetic_take_matches_with_a_subject_prefix_and_extras(glove_take):
    take = MarkerSequence(np.concatenate([glove_take.positions, glove_take.positions[:, :1]], axis=1),
                          [f"Sub1:{n}" for n in glove_take.names] + ["box1"], glove_take.rate)
    result = quiet_check(load_layout("glove-13"), take, take="take.c3d")
    assert result.warnings == ()
    assert result.matched == {n: f"Sub1:{n}" for n in glove_take.names}
    assert result.missing == () and result.extra == ("box1",)
    # The synthetic subject's triad is where its layout put it, up to the subject's shape and placement.
    for _, _, measured, nominal in result.rigid_distances:
        assert measured == pytest.approx(nominal, rel=0.2)
    summary = result.summary()
    assert "13 of 13 found in take.c3d (prefix Sub1: ignored)" in summary
    assert "in the take only: box1" in summary


def test_missing_names_get_the_takes_closest_name(glove_take):
    take = glove_take.renamed([n.replace("little", "pinky") for n in glove_take.names])
    result = quiet_check(load_layout("glove-13"), take)
    assert result.missing == ("little_middle", "little_tip")
    assert set(result.extra) == {"pinky_middle", "pinky_tip"}
    assert len(result.warnings) == 1
    assert "little_tip (the take has 'pinky_tip')" in result.warnings[0]


def test_no_name_in_common_is_an_error(glove_take):
    take = glove_take.renamed([f"M{i}" for i in range(glove_take.n_markers)])
    with pytest.raises(HandcapError, match="none of the layout's 13 names"):
        check_layout(load_layout("glove-13"), take)


def test_two_subjects_make_names_ambiguous(glove_take):
    take = MarkerSequence(np.concatenate([glove_take.positions] * 2, axis=1),
                          [f"L:{n}" for n in glove_take.names] + [f"R:{n}" for n in glove_take.names], glove_take.rate)
    with pytest.raises(HandcapError, match=r"several subjects in the take \(L, R\); .* \(e.g. L:hand_top\)"):
        check_layout(load_layout("glove-13"), take)
    # A layout that names one hand's markers in full is matched exactly; the other hand's are extra.
    layout = load_layout("glove-13")
    mine = MarkerLayout("left-subject", "right", tuple(LayoutMarker(f"L:{m.name}", m.segment, m.position)
                                                        for m in layout.markers), tuple(f"L:{r}" for r in layout.rigid))
    result = quiet_check(mine, take)
    assert len(result.matched) == 13 and result.extra == tuple(f"R:{n}" for n in glove_take.names)
    # Partly prefixed: the unprefixed names are ambiguous, and said so.
    half = MarkerLayout("half", "right", mine.markers[:3] + layout.markers[3:], mine.rigid)
    result = quiet_check(half, take)
    assert set(result.ambiguous) == set(layout.names[3:])
    assert any("several prefixed markers" in w for w in result.warnings)


def test_swapped_rigid_names_show_in_the_distances(glove_take):
    names = list(glove_take.names)
    i, j = names.index("hand_top"), names.index("hand_right")
    names[i], names[j] = names[j], names[i]
    result = quiet_check(load_layout("glove-13"), glove_take.renamed(names))
    assert any("rigid markers apart by other distances" in w and "hand_top-hand_left" in w for w in result.warnings)


def test_match_names_prefers_the_exact_name():
    matched, missing, extra, ambiguous = match_names(["a", "b", "c"], ["S:a", "b", "T:b", "x"])
    assert matched == {"a": "S:a", "b": "b"} and missing == ("c",) and extra == ("T:b", "x") and ambiguous == {}


# -- files and the command line ------------------------------------------------------------------------------------
def test_unknown_segment_suggests_the_right_one(tmp_path):
    path = tmp_path / "bad.toml"
    path.write_text('name = "bad"\nrigid = []\n[markers.a]\nsegment = "index_distel"\n')
    with pytest.raises(HandcapError, match="unknown segment 'index_distel'; did you mean 'index_distal'"):
        load_layout(path)


@pytest.mark.parametrize("text, message", [
    (b"\x00\x9f\xff binary", "not a text file"),
    (b'rigid = "a,b,c"\n[markers.a]\nsegment = "palm"\n', "rigid must be a list"),
    (b'[markers.a]\nsegment = "palm"\nposition = ["1", 2, 3]\n', "three numbers in metres"),
    (b'markers = 3\n', "markers must be tables"),
])
def test_broken_layout_files_are_one_line_errors(tmp_path, text, message):
    path = tmp_path / "bad.toml"
    path.write_bytes(text)
    with pytest.raises(HandcapError, match=message):
        load_layout(path)


def test_cli_new_then_check(tmp_path, glove_take, capsys):
    out = tmp_path / "mine.toml"
    assert main(["layout", "new", "--like", "glove-13", "--out", str(out)]) == 0
    assert load_layout(out).names == load_layout("glove-13").names
    before = out.read_bytes()
    assert main(["layout", "new", "--like", "tips-5", "--out", str(out)]) == 2
    assert "exists" in capsys.readouterr().err and out.read_bytes() == before
    take = tmp_path / "take.npz"
    write_markers(glove_take, take)
    assert main(["layout", "check", str(out), str(take)]) == 0
    assert "13 of 13 found" in capsys.readouterr().out


def test_cli_check_warns_and_strict_fails(tmp_path, glove_take, capsys):
    take = tmp_path / "take.npz"
    write_markers(glove_take.renamed([n.replace("little", "pinky") for n in glove_take.names]), take)
    assert main(["layout", "check", "glove-13", str(take)]) == 0
    err = capsys.readouterr().err
    assert err.count("handcap layout: warning:") == 1 and "little_tip (the take has 'pinky_tip')" in err
    assert main(["--strict", "layout", "check", "glove-13", str(take)]) == 2


def test_cli_check_unusable_layout_is_one_line(tmp_path, glove_take, capsys):
    bad = tmp_path / "mm.toml"
    layout = load_layout("tips-5")
    MarkerLayout("mm", "right", tuple(LayoutMarker(m.name, m.segment, m.position * 1000) for m in layout.markers),
                 layout.rigid).save(bad)
    assert main(["layout", "check", str(bad)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("handcap layout: error:") and "millimetres" in err[0]


@pytest.mark.parametrize("layout_name", ["glove-13", "joints-19", "active-9"])
def test_synthetic_subjects_raise_no_false_warning(layout_name):
    """Different hand shapes and marker placements (synth's subject seeds) are all plausible."""
    for subject in range(3):
        capture = synthesize(SynthConfig(layout=layout_name, motion="calibration", frames=20, ghost_rate=0,
                                         seed=subject, subject_seed=100 + subject), progress=False)
        result = quiet_check(load_layout(layout_name), capture.markers)
        assert result.warnings == (), (subject, result.warnings)


def test_real_glove_recording_passes(shared_data):
    from handcap.io import read_markers
    take = read_markers(shared_data / "markers" / "hand_embodiment_glove" / "recording.tsv")
    result = quiet_check(load_layout("glove-13"), take, take="recording.tsv")
    assert result.warnings == () and len(result.matched) == 13
    assert set(result.extra) == {"right_elbow", "right_shoulder", "back_top", "back_left", "back_right",
                                 "pillow_top", "pillow_left", "pillow_right"}
    # The layout's triad was measured on this recording (test_layouts): within 1 mm.
    for _, _, measured, nominal in result.rigid_distances:
        assert measured == pytest.approx(nominal, abs=0.001)


def test_cli_new_without_positions(tmp_path, capsys):
    out = tmp_path / "bare.toml"
    assert main(["layout", "new", "--like", "tips-5", "--no-positions", "--out", str(out)]) == 0
    assert "0 with positions" in capsys.readouterr().out
    assert np.isnan(load_layout(out).positions()).all()
    assert main(["layout", "new", "--like", "tips-5", "--out", str(tmp_path)]) == 2
    assert "is a folder" in capsys.readouterr().err
