"""Rendered images of printed patches agree with their exact corner truth.

Independent checks: OpenCV's cornerSubPix finds the rendered checkerboard corners where the truth says;
the renderer's depth-buffer visibility agrees with the ray-casting visibility of handcap.synth.visibility;
the patch samples sit on the skin at the layout's corners.
"""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from handcap.core.camera import Camera
from handcap.patterns import session_pattern
from handcap.patterns.glyphs import load_font
from handcap.hand import OpenHand
from handcap.layouts import load_layout
from handcap.synth.decals import corner_sides, patch_skin
from handcap.synth.textures import build_atlas, patch_texture
from handcap.synth.cameras import cage_rig
from handcap.synth.visibility import camera_visibility

pytest.importorskip("moderngl", reason="the renderer needs moderngl (extra 'images')")
from handcap.synth.images import MAX_VIEW_ANGLE, ImageStyle, PatchRenderer  # noqa: E402

PATTERN = session_pattern(("right",), ())
FONT = load_font(None, PATTERN.alphabet)



def test_texture_edges_lie_where_the_grid_says():
    patch = PATTERN.patch("right:dorsum_proximal")
    tex = patch_texture(patch, FONT, 48, ink=False).astype(float) / 255
    # White square (0, 0) spans texel edges 24..72 in x and y (the margin is half a square): its area is exact.
    assert abs(tex[10:90, 48].sum() - 48) < 1e-6 and abs(tex[48, 10:90].sum() - 48) < 1e-6
    assert abs(tex[:24].sum()) < 1e-9 and tex[24:72, 24:72].min() == 1.0


def _flat_scene(distance, ink):
    patch = PATTERN.patch("right:dorsum_proximal")
    atlas = build_atlas([patch], FONT, ink=ink)
    turn = cv2.Rodrigues(np.array([0.3, -0.2, 0.1]))[0]
    r = np.r_[-0.5, np.arange(patch.rows + 1), patch.rows + 0.5]
    c = np.r_[-0.5, np.arange(patch.cols + 1), patch.cols + 0.5]
    rr, cc = np.meshgrid(r, c, indexing="ij")
    grid = np.stack([cc * 0.005, rr * 0.005, np.zeros_like(rr)], -1) @ turn.T
    camera = Camera("c", (960, 768), np.array([[1100.0, 0, 470], [0, 1100, 390], [0, 0, 1]]),
                    np.array([-0.15, 0.05, 0.001, -0.001, 0.0]), np.zeros(3), np.array([-0.022, -0.016, distance]))
    return patch, atlas, grid, camera


@pytest.mark.parametrize("ink", [False, True])
def test_rendered_corners_are_where_the_truth_says(gl_ok, ink):
    patch, atlas, grid, camera = _flat_scene(0.12, ink)
    renderer = PatchRenderer(atlas, np.zeros((1, 3), int), ImageStyle.clean())
    try:
        shot = renderer.render(camera, np.full((3, 3), 10.0), [grid], np.random.default_rng(0))
    finally:
        renderer.close()
    assert shot.image.shape == (768, 960) and shot.visible.all()
    inner = np.array([0 < r < patch.rows and 0 < c < patch.cols for r, c in patch.vertices()])
    truth = shot.xy[inner].astype(np.float32)
    start = truth + np.random.default_rng(1).uniform(-1.5, 1.5, truth.shape).astype(np.float32)
    found = cv2.cornerSubPix(shot.image, start.reshape(-1, 1, 2).copy(), (5, 5), (-1, -1),
                             (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 50, 1e-4)).reshape(-1, 2)
    error = np.linalg.norm(found - truth, axis=1)
    # Glyphs near a corner pull cornerSubPix's gradient window a little; the bare checkerboard is exact.
    assert np.median(error) < (0.06 if ink else 0.05) and error.max() < 0.15
    assert np.abs((found - truth).mean(axis=0)).max() < 0.02  # no offset of the texture or the projection


@pytest.fixture(scope="module")
def posed():
    hand = OpenHand("right")
    rng = np.random.default_rng(3)
    betas = rng.normal(0, 0.5, 10)
    phi = np.zeros((1, 27))
    phi[0, 3:] = rng.uniform(0.0, 0.5, 24)
    out = hand.forward(betas, np.zeros((1, 3)), hand.hand_pose_from_phi(phi), np.array([[0.0, 0.0, 1.0]]))
    skin = patch_skin(load_layout("dense-patches"), PATTERN.patches, hand, betas)
    return hand, betas, out.vertices[0], skin


def test_patch_samples_sit_on_the_skin_at_the_layout_corners(posed):
    hand, _, _, skin = posed
    rest = skin.grids(hand.forward(np.zeros(10)).vertices, hand.faces)
    layout = {m.name: np.asarray(m.position) for m in load_layout("dense-patches").markers}
    gaps = []
    for patch, r, c, grid in zip(skin.patches, skin.rows, skin.cols, rest):
        for vr, vc in patch.vertices():
            name = patch.corner_name(vr, vc, owner=False)
            if name in layout:
                node = grid[np.flatnonzero(np.isclose(r, vr))[0], np.flatnonzero(np.isclose(c, vc))[0]]
                gaps.append(np.linalg.norm(node - layout[name]))
    # The layout gives skin spots; the printed corner lies marker_radius (0.5 mm) above them.
    assert len(gaps) == len(layout) and np.allclose(gaps, 0.0005, atol=2e-5)


def test_printed_patches_keep_their_pitch_on_any_hand():
    """Tape does not stretch with the hand: a large hand (first shape value 2) and a small one (-2) carry squares
    of the printed 5 mm; attached as the layout places them on the template they measured 5.70 and 4.64 mm."""
    hand = OpenHand("right")
    layout = load_layout("dense-patches")
    for first, grown in ((2.0, 5.70), (-2.0, 4.64)):
        betas = np.r_[first, np.zeros(9)]
        rest = hand.forward(betas).vertices
        as_placed, printed = (patch_skin(layout, PATTERN.patches, hand, betas, pitch=pitch) for pitch in (None, 0.005))
        sides = [np.concatenate([corner_sides(g, r, c) for g, r, c in zip(s.grids(rest, hand.faces), s.rows, s.cols)])
                 for s in (as_placed, printed)]
        assert abs(1000 * np.median(sides[0]) - grown) < 0.05
        assert abs(np.median(sides[1]) - 0.005) < 0.01 * 0.005
        means = [np.mean(corner_sides(g, r, c)) for g, r, c in zip(printed.grids(rest, hand.faces), printed.rows,
                                                                    printed.cols)]
        # Every patch but the fingertips' smallest (1 x 3 squares over the nail's curve) within 1 % of the pitch.
        assert sum(abs(m - 0.005) > 0.00005 for m in means) <= 2, np.round(1000 * np.array(means), 3)


def test_visibility_agrees_with_ray_casting(gl_ok, posed):
    hand, _, vertices, skin = posed
    atlas = build_atlas(PATTERN.patches, FONT, square=24)
    renderer = PatchRenderer(atlas, hand.faces, ImageStyle(occluders=(0, 0)),
                             coords=list(zip(skin.rows, skin.cols)))
    grids = skin.grids(vertices, hand.faces)
    corners, normals = [], []
    for patch, r, c, g in zip(skin.patches, skin.rows, skin.cols, grids):
        ri, ci = np.searchsorted(r, patch.vertices()[:, 0]), np.searchsorted(c, patch.vertices()[:, 1])
        corners.append(g[ri, ci])
        normals.append(np.cross(g[ri + 1, ci] - g[ri - 1, ci], g[ri, ci + 1] - g[ri, ci - 1]))
    corners, normals = np.concatenate(corners), np.concatenate(normals)
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    rig = cage_rig(6, resolution=(640, 512), target=(0.0, 0.0, 1.0), seed=1)
    try:
        shots = [renderer.render(camera, vertices, grids, np.random.default_rng(k)) for k, camera in enumerate(rig)]
    finally:
        renderer.close()
    # The same rule by exact ray casting: in the image, facing the camera within 75 degrees, no skin in between.
    rays = camera_visibility(corners, rig, vertices, hand.faces, normals=normals, max_view_angle=MAX_VIEW_ANGLE)
    rendered = np.array([shot.visible for shot in shots])
    assert rendered.sum() > 300 and rays.sum() > 300
    assert np.mean(rendered == rays) > 0.97
    for shot, camera in zip(shots, rig):
        assert np.allclose(shot.xy, camera.project(corners)[0])


def test_synth_images_writes_frames_and_their_truth(gl_ok, tmp_path):
    from handcap.cli import main
    from handcap.patterns import Pattern

    args = ["synth", "--layout", "dense-patches", "--motion", "random", "--frames", "2", "--cameras", "3",
            "--images", "--image-scale", "0.2", "--object", "none"]
    assert main(args + ["--out", str(tmp_path / "a")]) == 0
    assert main(args[:1] + args[3:] + ["--out", str(tmp_path / "b")]) == 0  # --images: dense-patches by default
    truth = np.load(tmp_path / "a" / "image_truth.npz")
    # The images are a fifth of the cameras' size: image_cameras.toml is the rig that filmed them (it projects the
    # corners to their pixels), cameras.toml the full-size rig of the capture's own detections.
    from handcap.core.camera_rig import CameraRig

    small, full = (CameraRig.load(tmp_path / "a" / f) for f in ("image_cameras.toml", "cameras.toml"))
    np.testing.assert_array_equal(small.sizes, truth["image_size"])
    np.testing.assert_allclose(full.sizes, 5 * truth["image_size"], atol=3)  # 2448 x 2048 -> 490 x 410
    seen = truth["visible"][0]
    np.testing.assert_allclose(small.project(truth["positions"][0])[0][seen], truth["all_xy"][0][seen], atol=1e-6)
    pattern = Pattern.load(tmp_path / "a" / "pattern.toml")
    names = list(truth["marker_names"])
    assert names == [n for p in pattern.patches for n in p.corner_names()]
    assert truth["all_xy"].shape == (2, 3, len(names), 2) and truth["visible"].sum() == len(truth["frame"]) > 50
    # Every visible tag's four corners are the template's corners of that tag, at their true pixels.
    for k in range(0, len(truth["block_text"]), 7):
        patch, r, c = pattern.locate(str(truth["block_text"][k]))
        ids = [names.index(patch.corner_name(*v)) for v in patch.block_vertices(r, c)]
        np.testing.assert_array_equal(truth["block_xy"][k],
                                      truth["all_xy"][truth["block_frame"][k], truth["block_camera"][k], ids])
    for cam in truth["camera_names"]:
        for frame in range(2):
            a = (tmp_path / "a" / "images" / cam / f"{frame:06d}.png").read_bytes()
            assert a == (tmp_path / "b" / "images" / cam / f"{frame:06d}.png").read_bytes()  # same seed, same bytes
            image = cv2.imread(str(tmp_path / "a" / "images" / cam / f"{frame:06d}.png"), cv2.IMREAD_UNCHANGED)
            assert image.dtype == np.uint8 and image.shape == tuple(truth["image_size"][0][::-1])
    # A phone's camera: the same take, its grey levels encoded as sRGB; decoded they are the linear ones (to the
    # rounding of both, at most 1.2 levels at white), and the truth is the same.
    from handcap.detect.response import linear_light

    assert main(args + ["--image-response", "srgb", "--out", str(tmp_path / "c")]) == 0
    np.testing.assert_array_equal(np.load(tmp_path / "c" / "image_truth.npz")["all_xy"], truth["all_xy"])
    for cam in truth["camera_names"]:
        linear, encoded = (cv2.imread(str(tmp_path / k / "images" / cam / "000001.png"), cv2.IMREAD_UNCHANGED)
                           for k in ("a", "c"))
        assert np.abs(linear_light(encoded).astype(int) - linear).max() <= 2
        assert encoded.mean() > linear.mean() + 20  # the printed black and the shadows come out grey


def test_a_cameras_srgb_response_follows_the_standard():
    from dataclasses import replace

    from handcap.synth.images import camera_effects

    light = np.array([[0.0, 0.002, 0.2159, 0.5, 1.0]], np.float32)
    rng = np.random.default_rng(0)
    linear = camera_effects(light, ImageStyle.clean(), rng)
    srgb = camera_effects(light, replace(ImageStyle.clean(), response="srgb"), rng)
    assert linear.tolist() == [[0, 1, 55, 128, 255]]
    assert srgb.tolist() == [[0, 7, 128, 188, 255]]  # IEC 61966-2-1: 0.2159 of white is its middle grey


def test_synth_images_needs_a_patch_layout(tmp_path, capsys):
    from handcap.cli import main

    assert main(["synth", "--layout", "glove-13", "--motion", "random", "--frames", "2", "--cameras", "3",
                 "--images", "--out", str(tmp_path / "x")]) == 2
    assert "printed patches" in capsys.readouterr().err
    assert not (tmp_path / "x").exists()  # refused before anything is written
    assert main(["synth", "--layout", "dense-patches", "--images", "--image-scale", "3", "--out",
                 str(tmp_path / "y")]) == 2
    assert "--image-scale" in capsys.readouterr().err
    from handcap.core.errors import HandcapError
    from handcap.steps.synth import synth

    with pytest.raises(HandcapError, match="--image-response 'log'"):
        synth(tmp_path / "z", images=True, image_response="log")
    assert not (tmp_path / "z").exists()


def test_cameras_not_triggered_together_film_the_take_at_their_own_moments(gl_ok, tmp_path):
    from handcap import HandcapError
    from handcap.synth.config import SynthConfig
    from handcap.synth.filming import Clocks, film_capture
    from handcap.synth.scene import synthesize

    capture = synthesize(SynthConfig(layout="dense-patches", motion="random", frames=5, cameras=3, object="none",
                                     rate=60.0), progress=False)
    film_capture(capture, tmp_path / "a", scale=0.2, progress=False)
    clocks = Clocks((0, 1, 2), 2)  # each camera at 30 Hz, started half a frame after the one before
    film_capture(capture, tmp_path / "b", scale=0.2, progress=False, clocks=clocks)
    every, own = np.load(tmp_path / "a" / "image_truth.npz"), np.load(tmp_path / "b" / "image_truth.npz")
    assert own["all_xy"].shape[0] == clocks.frames(5) == 2 and float(own["rate"]) == 30.0
    np.testing.assert_array_equal(own["camera_offsets"], [0.0, 0.5, 1.0])
    for c, start in enumerate(clocks.starts):
        np.testing.assert_array_equal(own["all_xy"][:, c], every["all_xy"][start::2, c][:2])
        assert sorted(p.name for p in (tmp_path / "b" / "images" / f"cam_{c}").iterdir()) == ["000000.png",
                                                                                                "000001.png"]
    np.testing.assert_array_equal(own["positions"], every["positions"][0::2][:2])  # at the first camera's moments
    assert "camera_offsets" not in every
    with pytest.raises(HandcapError, match="do not fit"):
        film_capture(capture, tmp_path / "c", scale=0.2, progress=False, clocks=Clocks((0, 5, 0), 1))


def test_a_held_object_wears_its_patches_and_the_detector_names_them(gl_ok, tmp_path):
    # A cuboid held in a grasp, 3 cameras, 3 moments: its faces' patches (handcap pattern's) are drawn, its corners
    # are in the truth after the hand's, on its moving surface, and the shipped detector names them at their truth.
    from dataclasses import replace

    from handcap.detect.networks import load_checker, load_corner_net, load_reader, load_refiner
    from handcap.detect.pipeline import Detector  # loads torch
    from handcap.patterns import Pattern
    from handcap.synth.config import SynthConfig
    from handcap.synth.filming import Clocks, film_capture, region_rig
    from handcap.synth.object_patches import LIFT
    from handcap.synth.objects import make_object
    from handcap.synth.scene import synthesize
    from scipy.spatial.transform import Rotation

    config = SynthConfig(layout="dense-patches", motion="grasp", frames=11, rate=4.0, cameras=3, object="cuboid",
                         seed=3)
    capture = synthesize(config, progress=False)
    hand = capture.truth["positions"][:, :len(capture.hand_motion.marker_names)]
    capture = replace(capture, rig=region_rig(capture.rig, hand[np.isfinite(hand).all(axis=-1)]))
    film_capture(capture, tmp_path, progress=False, clocks=Clocks((0, 0, 0), 5))  # moments 0, 5 and 10
    truth = np.load(tmp_path / "image_truth.npz")
    pattern = Pattern.load(tmp_path / "pattern.toml")
    names = [str(n) for n in truth["marker_names"]]
    held = [p for p in pattern.patches if p.owner == "cuboid"]
    theirs = [n for p in held for n in p.corner_names()]
    assert len(held) == 6 and names[-len(theirs):] == theirs
    mine = np.array([n.startswith("cuboid:") for n in names])
    # On the cuboid's surface as it moves (its own signed distance, in its frame at each moment).
    obj, motion = make_object("cuboid", seed=config.seed), capture.object_motion
    for k, t in enumerate((0, 5, 10)):
        turn = Rotation.from_rotvec(motion.rotation[t]).as_matrix()
        local = (truth["positions"][k, mine] - motion.translation[t]) @ turn  # R^T (x - t)
        np.testing.assert_allclose(obj.signed_distance(local), LIFT, atol=1e-9)
    detector = Detector(load_corner_net(int8=True), load_reader(), pattern, refiner=load_refiner(int8=True),
                        checker=load_checker())
    named = right = 0
    for c, camera in enumerate(truth["camera_names"]):
        for k in range(3):
            found = detector.image(cv2.imread(str(tmp_path / "images" / camera / f"{k:06d}.png"), cv2.IMREAD_GRAYSCALE))
            for name, xy in zip(found.names, found.corners):
                if name is not None and name.startswith("cuboid:"):
                    named += 1
                    right += np.linalg.norm(truth["all_xy"][k, c, names.index(name)] - xy) < 1.5
    seen = int(truth["visible"][:, :, mine].sum())
    assert seen > 200 and named > 0.5 * seen and right == named  # 326 of 399 named, all within 1.5 px


@pytest.mark.parametrize("motion", ["turn-cube", "rotate-cube"])
def test_the_cubes_facelet_patches_turn_with_its_layers(gl_ok, tmp_path, motion):
    # The hand turns R (or turns the whole cube about): every facelet patch's corner is where the tracker's
    # description puts it, carried by its cubie's rotation and the cube's pose (the truth's own, not the filming
    # code's).
    from handcap.objects import load_articulated
    from handcap.synth.config import SynthConfig
    from handcap.synth.filming import Clocks, film_capture
    from handcap.synth.scene import synthesize

    frames = {"moves": "R"} if motion == "turn-cube" else {"frames": 26}
    capture = synthesize(SynthConfig(layout="dense-patches", motion=motion, rate=10.0, cameras=2, seed=1, **frames),
                         progress=False)
    n = len(capture.hand_motion.phi)
    film_capture(capture, tmp_path, scale=0.2, progress=False, clocks=Clocks((0, 0), n - 1))  # first and last
    truth = np.load(tmp_path / "image_truth.npz")
    names = [str(m) for m in truth["marker_names"]]
    cube = load_articulated("cube2x2-patches")
    turned = capture.truth.get("cube_cubie_rotation", np.tile(np.eye(3), (n, 8, 1, 1)))  # whole: unturned
    from scipy.spatial.transform import Rotation

    for k, t in enumerate((0, n - 1)):
        pose = Rotation.from_rotvec(capture.object_motion.rotation[t]).as_matrix()
        for part_index, part in enumerate(cube.parts):
            want = (part.markers @ turned[t, part_index].T) @ pose.T + capture.object_motion.translation[t]
            got = truth["positions"][k, [names.index(m) for m in part.marker_names]]
            np.testing.assert_allclose(got, want, atol=2e-6)
    # R turned the right layer a quarter: its cubies' corners moved relative to the cube, the left layer's did not.
    assert np.allclose(turned[-1, :4], turned[0, :4])
    assert np.allclose(turned[-1], turned[0]) == (motion == "rotate-cube")
    assert truth["visible"][:, :, [n.startswith("cube2x2:") for n in names]].any()


def test_decal_cells_folded_flat_are_not_drawn():
    # A decal's cell folded flat at a joint squeezes its texture into nothing; llvmpipe's anisotropic filter took
    # 100 s over one image of such a hand instead of 0.1 s. Those triangles (under 1e-10 m^2, far under a pixel)
    # are left out; the rest of the patch is drawn.
    from handcap.synth.images import MIN_TRIANGLE_AREA, _drawable

    rr, cc = np.meshgrid(np.arange(4.0), np.arange(5.0), indexing="ij")
    grid = np.stack([cc * 1e-3, rr * 1e-3, np.zeros_like(rr)], axis=-1)  # 1 mm cells
    grid[1] = grid[0] + [0.0, 1e-7, 0.0]  # row 1 folded onto row 0
    faces = np.array([[r * 5 + c, r * 5 + c + 1, (r + 1) * 5 + c] for r in range(3) for c in range(4)]
                     + [[r * 5 + c + 1, (r + 1) * 5 + c + 1, (r + 1) * 5 + c] for r in range(3) for c in range(4)])
    kept = _drawable(grid.reshape(-1, 3), faces)
    a, b, c = (grid.reshape(-1, 3)[faces[:, k]] for k in range(3))
    area = 0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1)
    assert len(kept) == len(faces) - 8 and (area < MIN_TRIANGLE_AREA).sum() == 8
    assert {tuple(f) for f in kept} == {tuple(f) for f in faces[area >= MIN_TRIANGLE_AREA]}
