import numpy as np
import pytest

from handcap import HandcapError
from handcap.hand import OpenHand
from handcap.hand.attachment import MarkerAttachment
from handcap.layouts import SHIPPED, load_layout

GLOVE_NAMES = {"hand_top", "hand_left", "hand_right", "thumb_tip", "thumb_middle", "index_tip", "index_middle",
               "middle_tip", "middle_middle", "ring_tip", "ring_middle", "little_tip", "little_middle"}


@pytest.mark.parametrize("name", SHIPPED)
def test_shipped_layouts_load_and_attach_on_their_segments(name):
    layout = load_layout(name)
    hand = OpenHand()
    att = MarkerAttachment.from_layout(layout, hand)
    out = hand.forward()
    positions = att.positions(out.vertices, hand.faces)
    # Markers sit one marker radius off the skin, above their nominal skin point.
    dist = np.linalg.norm(positions - layout.positions(), axis=1)
    assert np.median(dist) == pytest.approx(layout.marker_radius, abs=2e-4)
    seg = hand.segment_of_vertex[hand.faces[att.triangles]]
    for i, m in enumerate(layout.markers):
        assert hand.segment_id(m.segment) in seg[i], m.name


def test_glove_layout_matches_the_real_glove():
    layout = load_layout("glove-13")
    assert set(layout.names) == GLOVE_NAMES
    assert layout.rigid == ("hand_top", "hand_left", "hand_right")
    p = dict(zip(layout.names, layout.positions()))
    # Inter-marker distances of the real triad (recording.tsv medians): 55.2, 44.8, 32.4 mm.
    d = lambda a, b: np.linalg.norm(p[a] - p[b]) * 1000  # noqa: E731
    assert d("hand_top", "hand_left") == pytest.approx(55.2, abs=3)
    assert d("hand_top", "hand_right") == pytest.approx(44.8, abs=3)
    assert d("hand_left", "hand_right") == pytest.approx(32.4, abs=3)


def test_dense_patches_has_19_patches_of_5mm_corners():
    layout = load_layout("dense-patches")
    patches = {m.patch for m in layout.markers}
    assert len(patches) == 19
    assert 300 <= len(layout) <= 600
    assert layout.marker_kind == "patch"
    pos = layout.positions()
    from scipy.spatial import cKDTree
    nearest, _ = cKDTree(pos).query(pos, k=2)
    assert np.median(nearest[:, 1]) == pytest.approx(0.005, abs=0.0006)


def test_left_layout_is_mirrored_and_attaches_to_the_left_hand():
    right, left = load_layout("tips-5"), load_layout("tips-5", side="left")
    assert left.side == "left"
    np.testing.assert_allclose(left.positions(), right.positions() * [1, 1, -1])
    hand = OpenHand("left")
    att = MarkerAttachment.from_layout(left, hand)
    out = hand.forward()
    pos = att.positions(out.vertices, hand.faces)
    np.testing.assert_allclose(pos, MarkerAttachment.from_layout(right, OpenHand()).positions(
        OpenHand().forward().vertices, OpenHand().faces) * [1, 1, -1], atol=1e-9)


def test_a_printed_patch_on_the_left_hand_is_not_mirrored():
    """Mirroring the positions alone would mirror the print: each patch corner takes the mirrored place of the
    corner in the same row and the opposite column (the patch's last column N - C), so its rows run along the
    hand as on the right and the print reads the right way round."""
    right, left = load_layout("dense-patches"), load_layout("dense-patches", side="left")
    where = {m.name: m.position for m in right.markers}
    assert len(left) == len(right) and left.segments == right.segments
    assert "thumb_proximal_r2c0" in left.names and "thumb_proximal_r2c0" not in right.names
    np.testing.assert_allclose(dict(zip(left.names, left.positions()))["thumb_distal_r1c0"],
                               where["thumb_distal_r1c3"] * [1, 1, -1])  # thumb_distal: 3 columns of squares
    np.testing.assert_allclose(dict(zip(left.names, left.positions()))["thumb_proximal_r2c0"],
                               where["thumb_proximal_r2c3"] * [1, 1, -1])
    # Seen from outside, a patch's columns run to the right of its rows on both hands: its normal row x column
    # points out of the skin (away from the skin point it is attached above).
    from handcap.core.geometry import closest_points_on_mesh
    from handcap.patterns import session_pattern
    from handcap.synth.decals import patch_skin

    for side in ("right", "left"):
        hand, pattern = OpenHand(side), session_pattern((side,), ())
        rest = hand.forward().vertices
        skin = patch_skin(load_layout("dense-patches"), pattern.patches, hand)
        outward = []
        for patch, r, c, g in zip(skin.patches, skin.rows, skin.cols, skin.grids(rest, hand.faces)):
            ri, ci = np.searchsorted(r, patch.vertices()[:, 0]), np.searchsorted(c, patch.vertices()[:, 1])
            normal = np.cross(g[ri + 1, ci] - g[ri - 1, ci], g[ri, ci + 1] - g[ri, ci - 1])
            above = g[ri, ci] - closest_points_on_mesh(g[ri, ci], rest, hand.faces)[0]
            outward.append(np.einsum("ij,ij->i", normal, above) > 0)
        assert np.mean(np.concatenate(outward)) > 0.95, side


def test_layout_file_round_trip(tmp_path):
    layout = load_layout("joints-19")
    layout.save(tmp_path / "mine.toml")
    again = load_layout(tmp_path / "mine.toml")
    assert again.names == layout.names and again.rigid == layout.rigid
    np.testing.assert_allclose(again.positions(), layout.positions(), atol=1e-6)
    layout.save(tmp_path / "again.toml")
    assert (tmp_path / "mine.toml").read_bytes() == (tmp_path / "again.toml").read_bytes()


def test_attachment_follows_pose_and_saves(tmp_path):
    import torch
    hand = OpenHand()
    att = MarkerAttachment.from_layout(load_layout("glove-13"), hand)
    phi = np.random.default_rng(0).uniform(0, 0.8, size=(3, 27))
    out = hand.forward(phi=phi)
    pos = att.positions(out.vertices, hand.faces)
    assert pos.shape == (3, 13, 3)
    pos_t = att.positions(torch.tensor(out.vertices), hand.faces)
    np.testing.assert_allclose(pos_t.numpy(), pos, atol=1e-12)
    att.save(tmp_path / "attachment.npz")
    back = MarkerAttachment.load(tmp_path / "attachment.npz")
    np.testing.assert_allclose(back.positions(out.vertices, hand.faces), pos)


@pytest.mark.parametrize("text, message", [
    ("name = 'x'\n", "lacks 'markers'"),
    ("[markers.a]\nsegment = 'elbow'\n", "unknown segment"),
    ("rigid = ['b']\n[markers.a]\nsegment = 'palm'\n", "rigid markers not in the layout"),
    ("[markers.a]\nsegment = 'palm'\nposition = [0, 1]\n", "three numbers"),
    ("marker_radius = 2.0\n[markers.a]\nsegment = 'palm'\n", "marker_radius"),
    ("[markers.a\nsegment = 'palm'\n", "not valid TOML"),
    ("side = 'up'\n[markers.a]\nsegment = 'palm'\n", "side must be"),
])
def test_bad_layout_files(tmp_path, text, message):
    path = tmp_path / "bad.toml"
    path.write_text(text)
    with pytest.raises(HandcapError, match=message):
        load_layout(path)


def test_unknown_layout_name():
    with pytest.raises(HandcapError, match="unknown layout"):
        load_layout("glove-14")


def test_object_markers_are_allowed_but_not_attached():
    from handcap.layouts import LayoutMarker, MarkerLayout
    layout = MarkerLayout("x", "right", (LayoutMarker("a", "object:cube"),
                                         LayoutMarker("b", "palm", np.zeros(3) + [0.05, 0.02, 0])))
    att = MarkerAttachment.from_layout(layout, OpenHand())
    assert att.marker_names == ("b",)
