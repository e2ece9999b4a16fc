"""The corner network's targets, decoding, tiling and training (a tiny run; the shipped weights are scored in
benchmarks/detect.py and by python -m handcap.detect.train)."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from handcap import HandcapError
from handcap.detect import corners
from handcap.detect.corners import CornerNet, corner_loss, detect_corners, find_corners, targets
from handcap.detect.samples import Batches, corner_batch
from handcap.detect.train import crops, load_corner_net, save_net, score_corners, train_corners


def _reference_targets(shape, corners, sigma=0.8):
    """The targets corner by corner: each corner's Gaussian skirt, its own cell set to 1, and in every cell
    within one cell of a corner the offset of the nearest such corner (the first on a tie)."""
    h, w = shape[0] // 2, shape[1] // 2
    heat, offset = np.zeros((h, w), np.float32), np.zeros((2, h, w), np.float32)
    best = np.full((h, w), np.inf)
    for x, y in corners:
        cx, cy = (x - 0.5) / 2, (y - 0.5) / 2
        for i in range(int(np.floor(cy)) - 2, int(np.floor(cy)) + 4):
            for j in range(int(np.floor(cx)) - 2, int(np.floor(cx)) + 4):
                if 0 <= i < h and 0 <= j < w:
                    d2 = (cx - j) ** 2 + (cy - i) ** 2
                    heat[i, j] = max(heat[i, j], np.float32(np.exp(-d2 / (2 * sigma ** 2))))
                    if d2 <= 1.0 + 1e-9 and d2 < best[i, j]:
                        best[i, j], offset[:, i, j] = d2, (2 * (cx - j), 2 * (cy - i))
        i, j = int(np.rint(cy)), int(np.rint(cx))
        if 0 <= i < h and 0 <= j < w:
            heat[i, j] = 1.0
    for x, y in corners:  # a later corner's skirt never lowers an earlier corner's peak
        i, j = int(np.rint((y - 0.5) / 2)), int(np.rint((x - 0.5) / 2))
        if 0 <= i < h and 0 <= j < w:
            heat[i, j] = 1.0
    return heat, offset, np.isfinite(best)


def test_targets_match_a_corner_by_corner_reference():
    rng = np.random.default_rng(5)
    for k in range(150):
        pts = rng.uniform(-4, 100, (int(rng.integers(0, 30)), 2))
        if len(pts) > 2:
            pts[1] = pts[0] + rng.normal(0, 0.4, 2)  # close pairs compete for cells
            pts[2] = np.round(pts[0] * 2) / 2 if k % 2 else pts[0]  # equal distances: the first corner wins
        got, want = targets((96, 96), pts), _reference_targets((96, 96), pts)
        np.testing.assert_allclose(got[0], want[0], atol=1e-6)
        np.testing.assert_allclose(got[1], want[1], atol=1e-6)
        np.testing.assert_array_equal(got[2], want[2])


def test_targets_decode_back_to_the_corners():
    rng = np.random.default_rng(0)
    corners = rng.uniform(4, 92, (12, 2))
    corners = corners[np.min(np.linalg.norm(corners[:, None] - corners[None] + np.eye(12)[..., None] * 99,
                                            axis=-1), axis=1) > 6]
    heat, offset, near = targets((96, 96), corners)
    xy, score = find_corners(heat, offset, threshold=0.5)
    pairs, error = score_corners(xy, corners, match_px=0.5)
    assert len(pairs) == len(corners) == len(xy) and error.max() < 1e-5
    # Each corner's own cell holds a peak near 1 and the offset that points at it.
    for x, y in corners:
        i, j = int(round((y - 0.5) / 2)), int(round((x - 0.5) / 2))
        assert heat[i, j] > 0.6 and near[i, j]
        assert np.allclose([2 * j + 0.5 + offset[0, i, j], 2 * i + 0.5 + offset[1, i, j]], [x, y], atol=1e-5)


def test_the_network_is_light_and_tiles_give_the_same_corners():
    torch.manual_seed(0)
    net = CornerNet()
    assert 8_000 < net.flops_per_pixel() < 12_000  # the "about 10 kFLOP per pixel"
    out = net(torch.zeros(1, 1, 64, 80))
    assert out.shape == (1, 3, 32, 40) and out[:, 1:].abs().max() <= 1.5
    image = (np.random.default_rng(1).random((300, 420)) * 255).astype(np.uint8)
    one = detect_corners(net, image, threshold=0.0, tile=1024)
    tiled = detect_corners(net, image, threshold=0.0, tile=128, halo=64)
    assert len(one[0]) > 100
    np.testing.assert_allclose(np.sort(one[0], axis=0), np.sort(tiled[0], axis=0), atol=1e-4)


def test_a_wider_network_keeps_its_reach_inside_the_tile_halo():
    torch.manual_seed(1)
    net = CornerNet(width=8, stem=8, dilations=(1, 2, 4, 8))
    assert net.reach() == 33 and CornerNet().reach() == 17
    image = (np.random.default_rng(2).random((260, 300)) * 255).astype(np.uint8)
    one = detect_corners(net, image, threshold=0.0, tile=1024)
    tiled = detect_corners(net, image, threshold=0.0, tile=128)  # the default halo follows the reach
    np.testing.assert_allclose(np.sort(one[0], axis=0), np.sort(tiled[0], axis=0), atol=1e-4)


def test_crops_drawn_in_worker_processes_repeat_for_a_seed(scenes):
    def draw(seed, count=3):
        loader = torch.utils.data.DataLoader(Batches(corner_batch, scenes, 4, seed), batch_size=None, num_workers=2)
        stream = iter(loader)
        return [next(stream) for _ in range(count)]

    first, again, other = draw(7), draw(7), draw(8)
    images, heat, offset, near = first[0]
    assert images.shape == (4, 1, 96, 96) and heat.shape == near.shape == (4, 48, 48)
    assert offset.shape == (4, 2, 48, 48) and near.dtype == torch.bool
    assert all(torch.equal(a, b) for x, y in zip(first, again) for a, b in zip(x, y))
    assert not torch.equal(first[0][0], first[1][0])  # the two workers draw different crops
    assert not torch.equal(first[0][0], other[0][0])


def test_the_network_runs_only_where_there_is_contrast(scenes, monkeypatch):
    # A rendered hand pasted into the corner of a large frame of plain, noisy backdrop: the backdrop's cells
    # are quiet, the hand's are not, and the shipped network finds the same corners as when run everywhere.
    net = load_corner_net()
    rng = np.random.default_rng(2)
    frame = np.clip(rng.normal(90, 2.0, (1200, 1600)), 0, 255).astype(np.uint8)
    hand = scenes[0].image
    frame[:hand.shape[0], :hand.shape[1]] = hand
    busy = corners._contrast_cells(corners.normalise(frame))
    cells = corners.CELL
    assert busy[:hand.shape[0] // cells, :hand.shape[1] // cells].mean() > 0.3
    assert not busy[-(-hand.shape[0] // cells) + 1:, :].any() and not busy[:, -(-hand.shape[1] // cells) + 1:].any()
    skipped = detect_corners(net, frame, threshold=0.1)
    monkeypatch.setattr(corners, "MIN_RANGE", -1.0)
    everywhere = detect_corners(net, frame, threshold=0.1)
    near = score_corners(everywhere[0], scenes[0].corners)[0][:, 0]
    assert len(near) > 20
    assert score_corners(skipped[0], everywhere[0][near], match_px=1e-3)[0].shape[0] == len(near)


def test_bad_images_are_one_clear_error():
    with pytest.raises(HandcapError, match="grey image"):
        detect_corners(CornerNet(), np.zeros((4, 4), np.uint8))
    with pytest.raises(HandcapError, match="grey image"):
        detect_corners(CornerNet(), np.zeros((40, 40, 3), np.uint8))


def test_scenes_hold_visible_corners_and_tags(scenes):
    for scene in scenes:
        assert scene.image.dtype == np.uint8 and len(scene.corners) > 20
        h, w = scene.image.shape
        assert (scene.corners >= 0).all() and (scene.corners[:, 0] <= w - 1).all()
        assert scene.blocks.shape[1:] == (4, 2) and len(scene.blocks) == len(scene.block_text)


def test_a_few_training_steps_lower_the_loss_and_repeat_exactly(scenes, tmp_path):
    rng = np.random.default_rng(0)
    images, corners = crops(scenes, 8, rng)
    made = [targets(images.shape[1:], c) for c in corners]
    batch = [torch.from_numpy(np.stack([m[k] for m in made])) for k in range(3)]
    torch.manual_seed(0)
    before = corner_loss(CornerNet()(torch.from_numpy(images)[:, None]), *batch).item()
    net = train_corners(scenes, steps=14, batch=8, seed=3)
    after = corner_loss(net(torch.from_numpy(images)[:, None]), *batch).item()
    assert after < 0.95 * before
    net = train_corners(scenes, steps=3, batch=4, seed=3)
    again = train_corners(scenes, steps=3, batch=4, seed=3)
    for a, b in zip(net.state_dict().values(), again.state_dict().values()):
        assert torch.equal(a, b)  # deterministic for a seed
    save_net(net, tmp_path / "c.npz", {"source": "test"})
    loaded = load_corner_net(tmp_path / "c.npz")
    for a, b in zip(net.state_dict().values(), loaded.state_dict().values()):
        assert torch.equal(a, b)
    (tmp_path / "bad.npz").write_bytes(b"not an npz")
    with pytest.raises(HandcapError):
        load_corner_net(tmp_path / "bad.npz")
    with pytest.raises(HandcapError, match="no CornerNet weights"):
        load_corner_net(tmp_path / "missing.npz")
