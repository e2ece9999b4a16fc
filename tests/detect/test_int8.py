"""The corner network's and the refiner's 8-bit twins: the same corners as the float networks on rendered scenes,
ranges saved with the weights, and the float network wherever the twin cannot be built."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np
import pytest
import torch
from scipy.spatial import cKDTree

from handcap import HandcapError
from handcap.detect.corners import CornerNet, detect_corners
from handcap.detect import int8
from handcap.detect.int8 import (ENGINE, Int8CornerNet, Int8Refiner, activation_ranges, int8_corner_net, int8_refiner,
                                 refiner_ranges)
from handcap.detect.networks import load_corner_net, load_refiner, net_info, save_net
from handcap.detect.refine import CornerRefiner, locate_corners
from handcap.detect.train import train_corners, train_refiner

ROOT = Path(__file__).resolve().parents[2]
needs_engine = pytest.mark.skipif(ENGINE not in torch.backends.quantized.supported_engines,
                                  reason=f"this PyTorch has no {ENGINE} quantised engine")


@needs_engine
def test_the_shipped_twin_finds_the_float_networks_corners(scenes):
    float_net, twin = load_corner_net(), load_corner_net(int8=True)
    assert isinstance(twin, Int8CornerNet) and twin.reach() == float_net.reach()
    for scene in scenes:
        xy, score = detect_corners(float_net, scene.image)
        xy8, score8 = detect_corners(twin, scene.image)
        assert abs(len(xy8) - len(xy)) <= 0.03 * len(xy) + 2, (len(xy), len(xy8))
        gap, at = cKDTree(xy8).query(xy)
        # The same corners, placed within a few hundredths of a pixel (the corner network's error is ~0.3 px).
        assert (gap < 0.25).mean() > 0.97 and np.median(gap) < 0.05, np.percentile(gap, [50, 97])
        close = gap < 0.25
        change = np.abs(score8[at[close]] - score[close])
        assert np.median(change) < 0.02 and change.max() < 0.2, np.percentile(change, [50, 100])


@needs_engine
def test_ranges_are_measured_saved_and_loaded(scenes, tmp_path):
    net = load_corner_net()
    ranges = activation_ranges(net, [s.image for s in scenes[:2]])
    assert ranges.shape == (4 + 2 * len(net.body), 2)  # the input, stem, down, each body layer and sum, the head
    assert (ranges[:, 0] <= 0).all() and (ranges[:, 1] > 0).all()
    assert (ranges[1:-1, 0] == 0).all()  # after a ReLU (and the sums of two) nothing is negative
    net.ranges = ranges
    save_net(net, tmp_path / "c.npz", {"source": "a test"})
    again = load_corner_net(tmp_path / "c.npz")
    np.testing.assert_array_equal(again.ranges, ranges)
    assert net_info(tmp_path / "c.npz") == {"source": "a test"}
    assert isinstance(load_corner_net(tmp_path / "c.npz", int8=True), Int8CornerNet)


def test_without_ranges_or_engine_the_float_network_is_kept(monkeypatch):
    net = CornerNet()
    assert net.ranges is None and int8_corner_net(net) is net
    net.ranges = np.array([[0.0, 1.0]] * 10)
    monkeypatch.setattr(int8, "ENGINE", "an engine this PyTorch lacks")  # as on an ARM build (qnnpack only)
    assert int8_corner_net(net) is net


@needs_engine
def test_ranges_of_another_network_are_refused():
    net = CornerNet(dilations=(1, 2))
    net.ranges = np.array([[0.0, 1.0]] * 10)  # made for three body layers, not two
    with pytest.raises(HandcapError, match="activation ranges"):
        int8_corner_net(net)


@needs_engine
@pytest.mark.parametrize("what, load, kind, count", [("corners", load_corner_net, "CornerNet", 10),
                                                     ("refiner", load_refiner, "CornerRefiner", 5)])
def test_the_ranges_command_keeps_the_weights_and_their_notes(tmp_path, capsys, what, load, kind, count):
    pytest.importorskip("moderngl", reason="rendered scenes need moderngl (extra 'images')")
    tool = _tool()
    out = tmp_path / f"{what}.npz"
    assert tool.main(["--what", what, "--weights", str(tmp_path / "none.npz"), "--out", str(out)]) == 2
    assert f"no {kind} weights there" in capsys.readouterr().err and not out.exists()
    code = tool.main(["--what", what, "--scenes", "1", "--out", str(out)])
    printed = capsys.readouterr()
    if code == 2 and "OpenGL" in printed.err:
        pytest.skip(f"no headless OpenGL here: {printed.err}")
    assert code == 0 and f"{out}: {count} activation ranges from 1 scenes" in printed.out
    shipped, made = load(), load(out)  # the ranges only: the weights as they were
    for a, b in zip(shipped.state_dict().values(), made.state_dict().values()):
        assert torch.equal(a, b)
    assert made.ranges.shape == shipped.ranges.shape == (count, 2)
    info = net_info(out)
    assert info["source"] == net_info(ROOT / f"src/handcap/detect/weights/{what}.npz")["source"]
    assert f"1 rendered scenes (seed 5, pages 0.3): tools/corner_ranges.py --what {what}" in info["int8"]


def test_training_drops_the_ranges_of_the_old_weights(scenes):
    net = load_corner_net()
    assert net.ranges is not None  # the shipped weights carry them
    trained = train_corners(scenes[:1], steps=2, batch=4, net=net)
    assert trained.ranges is None and int8_corner_net(trained) is trained


@needs_engine
def test_the_shipped_refiners_twin_places_the_float_refiners_corners(scenes):
    corner_net, float_refiner, twin = load_corner_net(int8=True), load_refiner(), load_refiner(int8=True)
    assert isinstance(twin, Int8Refiner)
    gaps, changes = [], []
    for scene in scenes:
        xy, score = locate_corners(corner_net, float_refiner, scene.image)
        xy8, score8 = locate_corners(corner_net, twin, scene.image)
        assert abs(len(xy8) - len(xy)) <= 0.02 * len(xy) + 2, (len(xy), len(xy8))
        gap, at = cKDTree(xy8).query(xy)
        gaps.append(gap)
        changes.append(np.abs(score8[at] - score)[gap < 0.25])
    gap, change = np.concatenate(gaps), np.concatenate(changes)
    # The same corners within a few hundredths of a pixel (the refined corners' own error is ~0.15 px median).
    assert (gap < 0.25).mean() > 0.97 and np.median(gap) < 0.03, np.percentile(gap, [50, 97])
    assert np.median(change) < 0.02, np.percentile(change, [50, 100])


@needs_engine
def test_refiner_ranges_are_measured_on_its_crops_saved_and_loaded(scenes, tmp_path):
    net = load_refiner()
    ranges = refiner_ranges(net, load_corner_net(int8=True), [s.image for s in scenes[:1]])
    assert ranges.shape == (5, 2)  # the input crops and the four convolutions (the dense head stays in floats)
    assert ranges[0, 0] < 0 < ranges[0, 1] and (ranges[1:, 0] == 0).all() and (ranges[1:, 1] > 0).all()
    net.ranges = ranges
    save_net(net, tmp_path / "r.npz", {"source": "a test"})
    again = load_refiner(tmp_path / "r.npz")
    np.testing.assert_array_equal(again.ranges, ranges)
    assert isinstance(load_refiner(tmp_path / "r.npz", int8=True), Int8Refiner)
    with pytest.raises(HandcapError, match="no candidate"):
        refiner_ranges(net, load_corner_net(), [np.full((64, 64), 128, np.uint8)])


def test_a_refiner_without_ranges_or_engine_is_kept_and_wrong_ranges_are_refused(monkeypatch):
    net = CornerRefiner()
    assert net.ranges is None and int8_refiner(net) is net
    net.ranges = np.array([[0.0, 1.0]] * 4)  # one short
    if ENGINE in torch.backends.quantized.supported_engines:
        with pytest.raises(HandcapError, match="corner refiner: .* activation ranges for 5 activations"):
            int8_refiner(net)
    monkeypatch.setattr(int8, "ENGINE", "an engine this PyTorch lacks")
    assert int8_refiner(net) is net


def test_training_drops_the_refiners_old_ranges(scenes):
    net = load_refiner()
    assert net.ranges is not None  # the shipped weights carry them
    trained = train_refiner(scenes[:1], load_corner_net(), steps=2, batch=8, net=net)
    assert trained.ranges is None and int8_refiner(trained) is trained


def _tool():
    """tools/corner_ranges.py as a module."""
    spec = importlib.util.spec_from_file_location("corner_ranges", ROOT / "tools" / "corner_ranges.py")
    tool = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(tool)
    return tool


def test_the_twins_pickle_as_their_float_networks(scenes):
    # PyTorch's converted layers do not pickle; the twins are rebuilt from their float networks, so a detector
    # travels to worker processes (handcap detect --workers) and finds the same corners there.
    import pickle

    if not int8.available():
        pytest.skip("this PyTorch has no oneDNN engine: no integer twins")
    net, refiner = load_corner_net(int8=True), load_refiner(int8=True)
    again, refiner_again = pickle.loads(pickle.dumps((net, refiner)))
    assert type(again) is Int8CornerNet and type(refiner_again) is Int8Refiner
    xy, score = locate_corners(net, refiner, scenes[0].image)
    xy_again, score_again = locate_corners(again, refiner_again, scenes[0].image)
    assert len(xy) > 100
    np.testing.assert_array_equal(xy, xy_again)
    np.testing.assert_array_equal(score, score_again)
