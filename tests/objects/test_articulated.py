"""Articulated-object descriptions: the shipped 2x2x2 cube, a user's hinge, and every bad file one clear line."""

import numpy as np
import pytest

from handcap import HandcapError
from handcap.objects.articulated import articulated_from_table, load_articulated
from handcap.objects.cube import FACES, HOME

HINGE = """
name = "hinge"
units = "mm"

[[parts]]
name = "base"
markers = { b1 = [0, 0, 0], b2 = [60, 0, 0], b3 = [0, 40, 5] }

[[parts]]
name = "lid"
markers = { l1 = [0, 0, 30], l2 = [60, 0, 30], l3 = [0, -40, 35] }

[[joints]]
type = "revolute"
parent = "base"
child = "lid"
axis = [2, 0, 0]
origin = [0, 0, 15]
limits_deg = [-5, 185]
"""


def test_the_shipped_cube_matches_the_move_algebra():
    cube = load_articulated("cube2x2")
    assert cube.name == "cube2x2" and len(cube.parts) == 8 and len(cube.marker_names) == 24
    # part k is the cubie at HOME[k]; its markers lie on its outer faces of the 5.6 cm cube
    centres = np.array([p.centre for p in cube.parts])
    assert (np.sign(centres) == HOME).all()
    for part, home in zip(cube.parts, HOME):
        assert np.allclose(np.abs(part.markers).max(axis=1), 0.028)
        assert (np.sign(part.markers) == home).all()
    assert set(cube.layers.axes) == set(FACES)
    for face, axis in cube.layers.axes.items():
        assert np.allclose(axis, FACES[face])
        # each face's layer holds four cubies at rest
        assert (centres @ axis > 0).sum() == 4


def test_a_user_hinge_from_its_toml(tmp_path):
    path = tmp_path / "hinge.toml"
    path.write_text(HINGE)
    hinge = load_articulated(path)
    assert [p.name for p in hinge.parts] == ["base", "lid"]
    assert hinge.part("lid").markers[1] == pytest.approx([0.06, 0.0, 0.03])  # millimetres to metres
    (joint,) = hinge.joints
    assert joint.kind == "revolute" and joint.parent == "base" and joint.child == "lid"
    assert joint.axis == pytest.approx([1.0, 0.0, 0.0]) and joint.origin == pytest.approx([0.0, 0.0, 0.015])
    assert joint.limits == pytest.approx((np.deg2rad(-5), np.deg2rad(185)))
    assert hinge.layers is None


@pytest.mark.parametrize("edit, message", [
    (lambda t: t.replace(", b3 = [0, 40, 5]", ""), "at least 3"),           # a part missing markers
    (lambda t: t.replace('child = "lid"', 'child = "door"'), "not a part"),
    (lambda t: t.replace("axis = [2, 0, 0]", "axis = [0, 0, 0]"), "no length"),
    (lambda t: t.replace('units = "mm"', 'units = "km"'), "units"),
    (lambda t: t.replace('units = "mm"', 'units = "m"'), "across"),         # 60 m: millimetres taken as metres
    (lambda t: t.replace("l1 =", "b1 ="), "named twice"),
    (lambda t: t.replace('type = "revolute"', 'type = "prismatic"'), "revolute or layers"),
    (lambda t: t.replace("[-5, 185]", "[185, -5]"), "low below high"),
    (lambda t: t.replace('name = "hinge"', ""), "name"),
    (lambda t: t.replace("axis = [2, 0, 0]", 'axis = "x"'), "three"),
])
def test_bad_descriptions_are_one_clear_line(tmp_path, edit, message):
    path = tmp_path / "bad.toml"
    path.write_text(edit(HINGE))
    with pytest.raises(HandcapError, match=message):
        load_articulated(path)


def test_a_cube_file_with_a_cubie_missing_markers(tmp_path):
    text = load_articulated.__globals__["SHIPPED"]["cube2x2"].read_text()
    broken = text.replace(", DBL_B = [-14, -14, -28]", "")
    path = tmp_path / "cube.toml"
    path.write_text(broken)
    with pytest.raises(HandcapError, match="'DBL' has 2 markers"):
        load_articulated(path)


def test_missing_or_garbage_files(tmp_path):
    with pytest.raises(HandcapError, match="no such"):
        load_articulated(tmp_path / "none.toml")
    rng = np.random.default_rng(0)
    for k in range(100):
        path = tmp_path / f"f{k}.toml"
        path.write_bytes(rng.integers(0, 256, rng.integers(1, 300)).astype(np.uint8).tobytes())
        with pytest.raises(HandcapError):
            load_articulated(path)
    part = {"name": "a", "markers": {"m": [1, 0, 0], "n": [0, 0, 0], "o": [0, 0, 1]}}
    for table in ([], {"name": "x", "parts": "p"}, {"name": "x", "parts": [1]},
                  {"name": "x", "parts": [{"name": "a", "markers": {"m": [1, 2], "n": [0, 0, 0], "o": [0, 0, 1]}}]},
                  {"name": "x", "units": ["m"], "parts": [part]}, {"name": "x", "parts": [part], "joints": 3},
                  {"name": "x", "parts": [part], "joints": [{"type": "revolute", "parent": ["a"], "child": "a"}]},
                  {"name": "x", "parts": [part], "joints": [{"type": "layers", "axes": {"R": "x"}}]}):
        with pytest.raises(HandcapError):
            articulated_from_table(table)
