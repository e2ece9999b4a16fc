"""The corner refiner: crops, merging of duplicates, training samples, a tiny training run, and the shipped
weights against the truth of rendered scenes (they must place corners closer than the corner network alone)."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from handcap import HandcapError
from handcap.detect.evaluation import score_corners
from handcap.detect.networks import WEIGHTS, load_corner_net, load_refiner
from handcap.detect.refine import (RADIUS, CornerRefiner, _merge, candidate_negatives, crops_at, false_candidates,
                                   locate_corners, refine_corners, refiner_loss)
from handcap.detect.samples import phone_look, refiner_samples
from handcap.detect.scenefile import Scene
from handcap.detect.train import save_net, train_refiner


def test_crops_are_the_pixels_around_each_centre_normalised():
    image = (np.random.default_rng(0).random((40, 50)) * 255).astype(np.uint8)
    centres = np.array([[20, 15], [0, 0], [49, 39], [3, 37]])
    crops = crops_at(image, centres)
    assert crops.shape == (4, 2 * RADIUS + 1, 2 * RADIUS + 1)
    raw = image[15 - RADIUS:15 + RADIUS + 1, 20 - RADIUS:20 + RADIUS + 1] / 255.0
    lo, mid, hi = np.percentile(raw, (5, 50, 95))
    np.testing.assert_allclose(crops[0], (raw - mid) / (hi - lo), atol=1e-5)
    # At the border the image is mirrored: the crop at (0, 0) is symmetric about its centre row and column.
    np.testing.assert_array_equal(crops[1], crops[1][::-1, ::-1])


def test_merging_keeps_the_best_of_each_cluster():
    xy = np.array([[10.0, 10.0], [10.5, 10.0], [11.2, 10.0], [30.0, 30.0], [30.2, 30.3]])
    score = np.array([0.6, 0.9, 0.8, 0.7, 0.5])
    kept, kept_score = _merge(xy, score)
    # 10.5 beats both of its neighbours; 11.2 is 0.7 from it, 10.0 is 0.5 from it; 30.0 beats 30.2.
    np.testing.assert_array_equal(kept, [[10.5, 10.0], [30.0, 30.0]])
    np.testing.assert_array_equal(kept_score, [0.9, 0.7])


def test_samples_point_at_the_corners_whatever_the_turn(scenes):
    rng = np.random.default_rng(1)
    negatives = [np.zeros((0, 2)) for _ in scenes]
    crops, is_corner, offset = refiner_samples(scenes, 400, rng, negatives)
    assert crops.shape == (400, 17, 17) and 0.4 < is_corner.mean() < 0.8
    pos = is_corner > 0.5
    assert (np.linalg.norm(offset[pos], axis=1) <= 1.5 + 0.71).all()
    assert (offset[~pos] == 0).all()


def test_a_phones_sharpening_rings_beside_an_edge_and_leaves_it_in_place(scenes):
    # A blurred vertical step, dark to light at x = 20.5: processed, it is steeper, overshoots on both sides
    # (where the mask is wide or strong enough), still crosses mid-grey between the same two pixels, and the
    # same seed gives the same image.
    x = np.arange(41)
    row = 40 + 160 / (1 + np.exp(-(x - 20.5) / 0.5))
    step = np.rint(np.tile(row, (31, 1))).astype(np.uint8)
    rings = 0
    for seed in range(8):
        out = phone_look(step, np.random.default_rng(seed)).astype(float)
        np.testing.assert_array_equal(out, phone_look(step, np.random.default_rng(seed)))
        middle = out[15]
        assert np.diff(middle).max() > np.diff(row).max() + 5, (seed, middle[18:24])
        assert middle[20] < 120 < middle[21], (seed, middle[18:24])
        rings += middle.max() > 205 and middle.min() < 35
    assert rings >= 3, rings
    # A share of the refiner's crops so processed: 0 draws exactly the crops drawn before the option existed.
    negatives = [np.zeros((0, 2)) for _ in scenes]
    plain = refiner_samples(scenes, 50, np.random.default_rng(4), negatives)
    for a, b in zip(plain, refiner_samples(scenes, 50, np.random.default_rng(4), negatives, phone=0.0)):
        np.testing.assert_array_equal(a, b)
    sharpened = refiner_samples(scenes, 50, np.random.default_rng(4), negatives, phone=1.0)
    assert not np.array_equal(plain[0], sharpened[0])


def _two_corner_scene():
    """A blank image with two printed corners: a visible one at (20, 20) and a hidden one at (40, 20)."""
    return Scene(np.zeros((60, 60), np.uint8), np.array([[20.0, 20.0]]), np.array(["a"]), np.zeros((0, 4, 2)),
                 np.zeros(0, "<U2"), "AB", {"a": np.array([20.0, 20.0]), "b": np.array([40.0, 20.0])})


def test_negatives_split_into_false_and_occluders_edges():
    scene = _two_corner_scene()
    candidates = np.array([[20.5, 20.0],   # at the visible corner: no negative
                           [22.5, 20.0],   # 2.5 px from the visible corner: neither (a corner seen from a pixel off)
                           [41.0, 20.0],   # 1 px from the hidden one: may show at a grazing angle, neither
                           [42.5, 20.0],   # 2.5 px from the hidden one: an occluder's edge
                           [40.0, 17.2],   # 2.8 px from it: an occluder's edge
                           [30.0, 40.0],   # far from both: false
                           [40.0, 16.5]])  # 3.5 px from the hidden one: false
    false, occluded = candidate_negatives(candidates, scene)
    np.testing.assert_array_equal(false, candidates[[5, 6]])
    np.testing.assert_array_equal(occluded, candidates[[3, 4]])
    # Without the hidden corners' projections there is no telling an occluder's edge: only the far ones.
    plain = Scene(scene.image, scene.corners, scene.corner_names, scene.blocks, scene.block_text, "AB")
    false, occluded = candidate_negatives(candidates, plain)
    assert len(occluded) == 0
    np.testing.assert_array_equal(false, candidates[2:])  # all those over 3 px from the visible corner


def test_occluders_edges_are_drawn_as_often_as_asked():
    scene = _two_corner_scene()
    scene = Scene((np.random.default_rng(0).random((60, 60)) * 255).astype(np.uint8), *list(vars(scene).values())[1:])
    far, edge = [np.array([[30.0, 40.0]])], [np.array([[42.0, 23.0]])]
    plain = refiner_samples([scene], 2000, np.random.default_rng(3), far)
    # With no share asked, the same draws as without them (the shipped weights' commands are unchanged).
    for a, b in zip(plain, refiner_samples([scene], 2000, np.random.default_rng(3), far, occluded=edge)):
        np.testing.assert_array_equal(a, b)
    crops, is_corner, _ = refiner_samples([scene], 2000, np.random.default_rng(3), far, occluded=edge,
                                          occluded_share=0.5)
    # Negatives are the 40 % of draws that are no corner; half of them now at the occluder's edge. The crops at
    # the two points differ, so count them by their distance to a crop at each (the flips and JPEG make copies).
    negatives = crops[is_corner == 0]
    assert 0.35 < len(negatives) / 2000 < 0.45
    at = [crops_at(scene.image, np.array(p, int)).reshape(1, -1) for p in ([[30, 40]], [[42, 23]])]
    views = [np.stack([v, v[:, ::-1], v[::-1], v[::-1, ::-1]]) for v in (a.reshape(17, 17) for a in at)]
    views = [np.concatenate([w, w.transpose(0, 2, 1)]).reshape(8, -1) for w in views]
    flat = negatives.reshape(len(negatives), -1)
    nearest = np.argmin([np.abs(flat[:, None] - w[None]).mean(axis=2).min(axis=1) for w in views], axis=0)
    assert 0.4 < nearest.mean() < 0.6, nearest.mean()


def test_a_few_training_steps_lower_the_loss_and_repeat_exactly(scenes, tmp_path):
    net = load_corner_net()
    negatives = [false_candidates(net, s) for s in scenes]
    assert all(len(n) for n in negatives)
    crops, is_corner, offset = refiner_samples(scenes, 64, np.random.default_rng(5), negatives)
    batch = (torch.from_numpy(crops)[:, None], torch.from_numpy(is_corner), torch.from_numpy(offset))
    torch.manual_seed(0)
    before = refiner_loss(CornerRefiner()(batch[0]), *batch[1:]).item()
    refiner = train_refiner(scenes, net, steps=150, batch=128, seed=2, lr=4e-3)
    with torch.no_grad():
        after = refiner_loss(refiner(batch[0]), *batch[1:]).item()
    assert after < 0.75 * before, (before, after)
    refiner = train_refiner(scenes, net, steps=3, batch=8, seed=2)
    again = train_refiner(scenes, net, steps=3, batch=8, seed=2)
    for a, b in zip(refiner.state_dict().values(), again.state_dict().values()):
        assert torch.equal(a, b)
    save_net(refiner, tmp_path / "r.npz")
    for a, b in zip(refiner.state_dict().values(), load_refiner(tmp_path / "r.npz").state_dict().values()):
        assert torch.equal(a, b)


@pytest.mark.skipif(not (WEIGHTS / "refiner.npz").is_file(), reason="no shipped refiner weights")
def test_shipped_refiner_places_corners_closer_than_the_network_alone(scenes):
    net, refiner = load_corner_net(), load_refiner()
    alone, refined = [], []
    for scene in scenes:
        for found, out in ((locate_corners(net, None, scene.image)[0], alone),
                           (locate_corners(net, refiner, scene.image)[0], refined)):
            out.append(score_corners(found, scene.corners)[1])
    alone, refined = np.concatenate(alone), np.concatenate(refined)
    assert len(refined) >= 0.95 * len(alone)  # about as many corners found
    assert np.median(refined) < 0.8 * np.median(alone) and np.median(refined) < 0.25


@pytest.mark.skipif(not (WEIGHTS / "refiner.npz").is_file(), reason="no shipped refiner weights")
def test_no_corner_where_an_edge_meets_the_image_border():
    # Black and white squares cut by the left edge: the mirrored crop there looks like a corner.
    image = np.full((96, 96), 30, np.uint8)
    image[16:40, 0:24] = 220
    image[40:64, 24:48] = 220
    refiner = load_refiner()
    xy, _ = refine_corners(refiner, image, np.array([[0.0, 40.0], [1.0, 16.0], [23.5, 39.5]]), min_score=0.0)
    assert len(xy) == 1 and np.linalg.norm(xy[0] - [23.5, 39.5]) < 0.5


def test_training_command_writes_weights_and_starts_from_others(scenes, tmp_path, capsys):
    from handcap.detect.train import main
    out = tmp_path / "w"
    threads = torch.get_num_threads()
    assert main(["--what", "refiner", "--scenes", "3", "--test-scenes", "1", "--steps", "2", "--out", str(out),
                 "--threads", str(threads + 1)]) == 0
    assert torch.get_num_threads() == threads  # --threads ends with the command (else a test run oversubscribes)
    first = load_refiner(out / "refiner.npz")
    assert main(["--what", "refiner", "--scenes", "3", "--test-scenes", "1", "--steps", "2", "--seed", "1",
                 "--init", str(out / "refiner.npz"), "--out", str(tmp_path / "again")]) == 0
    second = load_refiner(tmp_path / "again" / "refiner.npz")
    # Two small steps from the first weights stay near them; a new start would be far off.
    moved = max((a - b).abs().max().item() for a, b in zip(first.state_dict().values(), second.state_dict().values()))
    assert 0 < moved < 0.05
    with np.load(tmp_path / "again" / "refiner.npz") as data:
        assert "--init" in str(data["info.source"]) and "corners:" in str(data["info.score"])
    with pytest.raises(HandcapError, match="--what"):
        main(["--what", "all", "--init", str(out / "refiner.npz"), "--out", str(tmp_path / "x")])


def test_views_are_turned_back_before_they_are_averaged(scenes):
    # Each view's offset is turned back into the image's frame before the average: turned back wrongly
    # (a sign or an axis), the mean of eight views would land far from the corner, not nearer than one view.
    net = load_refiner()
    scene = scenes[0]
    one, p1 = refine_corners(net, scene.image, scene.corners + 0.3, min_score=0.0, views=1)
    eight, p8 = refine_corners(net, scene.image, scene.corners + 0.3, min_score=0.0, views=8)
    e1 = score_corners(one, scene.corners, match_px=1.0)[1]
    e8 = score_corners(eight, scene.corners, match_px=1.0)[1]
    assert len(e8) >= len(e1) > 20 and np.median(e8) <= np.median(e1) + 0.01
    with pytest.raises(HandcapError):
        refine_corners(net, scene.image, scene.corners, views=9)


def test_candidates_that_are_no_corner_give_none_and_no_error():
    # Candidates on pure noise: the first view turns them all away before the other views (nothing to look
    # at again), and the result is empty, not an error.
    noise = np.random.default_rng(0).integers(0, 255, (120, 160)).astype(np.uint8)
    xy = np.random.default_rng(1).uniform(10, 100, (40, 2))
    found, score = refine_corners(load_refiner(), noise, xy, min_score=0.99)
    assert found.shape == (0, 2) and score.shape == (0,)


def test_candidates_without_a_printed_corners_contrast_are_not_refined(monkeypatch):
    from handcap.detect import refine

    # A dim, noisy backdrop (a few grey levels of noise) with one printed corner in it.
    rng = np.random.default_rng(3)
    image = np.clip(70 + rng.normal(0, 4, (200, 240)), 0, 255).astype(np.uint8)
    image[60:100, 60:100], image[100:140, 100:140] = 220, 220  # two white squares meeting at (100, 100)
    image[60:100, 100:140], image[100:140, 60:100] = 25, 25
    backdrop = rng.uniform([20, 160], [220, 190], (300, 2))  # below the squares: backdrop only
    candidates = np.vstack([[[99.5, 99.5]], backdrop])
    keep = refine._contrasted(image, np.rint(candidates).astype(int))
    assert keep[0] and not keep[1:].any()
    # The refiner sees only what passes: its result is the same as on the printed corner alone.
    looked = []
    views = refine._views
    monkeypatch.setattr(refine, "_views", lambda net, img, centres, *a: looked.append(len(centres)) or views(
        net, img, centres, *a))
    found, _ = refine_corners(load_refiner(), image, candidates)
    assert looked[0] == 1
    alone, _ = refine_corners(load_refiner(), image, candidates[:1])
    np.testing.assert_allclose(found, alone)
