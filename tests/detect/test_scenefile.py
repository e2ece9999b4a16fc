"""Scenes files: rendered scenes written once and read back bit for bit, joined from parts, bad files refused."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from handcap import HandcapError
from handcap.detect.scenefile import Scene, join_scenes, load_scenes, save_scenes


def _scene(rng, projected=True) -> Scene:
    h, w = rng.integers(40, 90, 2) * 2
    image = rng.integers(0, 256, (h, w)).astype(np.uint8)
    k, b = int(rng.integers(0, 9)), int(rng.integers(0, 4))
    names = np.array([f"R.p{i:02d}.c{rng.integers(99)}" for i in range(k)])
    return Scene(image, rng.uniform(0, w, (k, 2)), names, rng.uniform(0, w, (b, 4, 2)),
                 np.array(["AB", "C7", "Y0", "EΩ"][:b]), "0123456789ACEFHPUY",
                 {n: rng.uniform(0, w, 2) for n in names} if projected and k else None)


def _same(a: Scene, b: Scene) -> bool:
    return (np.array_equal(a.image, b.image) and np.array_equal(a.corners, b.corners)
            and list(a.corner_names) == list(b.corner_names) and np.array_equal(a.blocks, b.blocks)
            and list(a.block_text) == list(b.block_text) and a.alphabet == b.alphabet
            and (a.projected or {}).keys() == (b.projected or {}).keys()
            and all(np.array_equal(a.projected[n], b.projected[n]) for n in a.projected or {}))


def test_scenes_come_back_bit_for_bit_and_parts_join_into_the_whole(tmp_path):
    rng = np.random.default_rng(4)
    train, test = [_scene(rng, k % 2 == 0) for k in range(7)], [_scene(rng) for _ in range(2)]
    info = {"scenes": 7, "seed": 3}
    save_scenes(tmp_path / "all.npz", {"train": train, "test": test}, info)
    groups, got = load_scenes(tmp_path / "all.npz")
    assert got == info and len(groups["train"]) == 7 and len(groups["test"]) == 2
    assert all(_same(a, b) for a, b in zip(train + test, groups["train"] + groups["test"]))
    assert groups["train"][1].projected is None and groups["train"][0].projected is not None
    # Three parts (the test group only in the last) join into the same scenes.
    save_scenes(tmp_path / "p1.npz", {"train": train[:3]}, dict(info, part=[1, 3]))
    save_scenes(tmp_path / "p2.npz", {"train": train[3:4]}, dict(info, part=[2, 3]))
    save_scenes(tmp_path / "p3.npz", {"train": train[4:], "test": test}, dict(info, part=[3, 3]))
    join_scenes([tmp_path / f"p{k}.npz" for k in (1, 2, 3)], tmp_path / "joined.npz")
    joined, got = load_scenes(tmp_path / "joined.npz")
    assert got == info
    assert all(_same(a, b) for a, b in zip(train + test, joined["train"] + joined["test"]))
    # Parts out of order, missing, or of another whole are refused.
    with pytest.raises(HandcapError, match="expected part"):
        join_scenes([tmp_path / "p2.npz", tmp_path / "p1.npz", tmp_path / "p3.npz"], tmp_path / "x.npz")
    with pytest.raises(HandcapError, match="expected part"):
        join_scenes([tmp_path / "p1.npz", tmp_path / "p3.npz"], tmp_path / "x.npz")
    save_scenes(tmp_path / "q2.npz", {"train": train[3:4]}, dict(info, seed=4, part=[2, 3]))
    with pytest.raises(HandcapError, match="expected part"):
        join_scenes([tmp_path / "p1.npz", tmp_path / "q2.npz", tmp_path / "p3.npz"], tmp_path / "x.npz")
    assert not (tmp_path / "x.npz").exists()


def test_bad_scenes_files_are_one_clear_error(tmp_path):
    with pytest.raises(HandcapError, match="no scenes file"):
        load_scenes(tmp_path / "missing.npz")
    (tmp_path / "junk.npz").write_bytes(b"PK\x03\x04 not really a zip")
    with pytest.raises(HandcapError, match="not a scenes file"):
        load_scenes(tmp_path / "junk.npz")
    np.savez(tmp_path / "other.npz", x=np.zeros(3))
    with pytest.raises(HandcapError, match="not a scenes file"):
        load_scenes(tmp_path / "other.npz")
    rng = np.random.default_rng(0)
    save_scenes(tmp_path / "one.npz", {"train": [_scene(rng)]})
    with np.load(tmp_path / "one.npz") as data:
        arrays = dict(data)
    arrays["train.png"] = np.zeros_like(arrays["train.png"])  # an image that no longer decodes
    np.savez(tmp_path / "broken.npz", **arrays)
    with pytest.raises(HandcapError, match="does not decode"):
        load_scenes(tmp_path / "broken.npz")
    # A scene without corners or blocks is kept as it is.
    empty = dataclasses.replace(_scene(rng), corners=np.zeros((0, 2)), corner_names=np.array([], str),
                                blocks=np.zeros((0, 4, 2)), block_text=np.array([], str), projected=None)
    save_scenes(tmp_path / "empty.npz", {"train": [empty]})
    back = load_scenes(tmp_path / "empty.npz")[0]["train"][0]
    assert _same(empty, back) and back.corners.shape == (0, 2) and back.blocks.shape == (0, 4, 2)


def _trained_once(args):
    """``handcap.detect.train`` after one run of its command with ``args`` (skipped where nothing renders)."""
    pytest.importorskip("moderngl", reason="rendered scenes need moderngl (extra 'images')")
    from handcap.detect import train

    try:
        assert train.main(args) == 0
    except HandcapError as err:
        pytest.skip(f"no headless OpenGL here: {err}")
    return train


def test_the_training_command_renders_into_the_scenes_file_once(tmp_path, monkeypatch):
    args = ["--what", "corners", "--scenes", "2", "--test-scenes", "1", "--steps", "2", "--threads", "1",
            "--scenes-file", str(tmp_path / "scenes.npz"), "--out", str(tmp_path / "w")]
    train = _trained_once(args)
    first = np.load(tmp_path / "w" / "corners.npz")["w.head.weight"]
    groups, info = load_scenes(tmp_path / "scenes.npz")
    assert len(groups["train"]) == 2 and len(groups["test"]) == 1 and info["scenes"] == 2

    def no_rendering(*args, **kwargs):
        raise AssertionError("rendered again")

    monkeypatch.setattr(train, "corner_scenes", no_rendering)
    assert train.main(args) == 0  # read back, not rendered: the same scenes give the same weights
    assert np.array_equal(np.load(tmp_path / "w" / "corners.npz")["w.head.weight"], first)
    assert train.main(args + ["--lr", "0.02"]) == 0  # the learning rate is used and recorded
    with np.load(tmp_path / "w" / "corners.npz") as saved:
        assert not np.array_equal(saved["w.head.weight"], first) and "--lr 0.02" in str(saved["info.source"])
    with pytest.raises(HandcapError, match="holds scenes made with"):
        train.main([a if a != "2" else "3" for a in args])
    with pytest.raises(HandcapError, match="--seconds plans one network"):
        train.main(["--what", "refiner", "--seconds", "5", "--out", str(tmp_path / "w")])


def test_the_reader_trains_from_its_scenes_file_and_is_scored_afterwards(tmp_path, monkeypatch):
    args = ["--what", "reader", "--scenes", "2", "--steps", "2", "--threads", "1", "--cut", "--no-score",
            "--scenes-file", str(tmp_path / "scenes.npz"), "--out", str(tmp_path / "w")]
    train = _trained_once(args)
    groups, info = load_scenes(tmp_path / "scenes.npz")
    assert len(groups["train"]) == 2 and info == {"what": "reader", "scenes": 2, "seed": 0, "cut": True}
    with np.load(tmp_path / "w" / "reader.npz") as saved:
        first, unscored = saved["w.turn.weight"], str(saved["info.score"])
    assert "not scored" in unscored

    def no_rendering(*args, **kwargs):
        raise AssertionError("rendered again")

    monkeypatch.setattr(train, "reader_scenes", no_rendering)
    assert train.main(args) == 0  # read back, not rendered
    assert np.array_equal(np.load(tmp_path / "w" / "reader.npz")["w.turn.weight"], first)
    with pytest.raises(HandcapError, match="holds scenes made with"):
        train.main([a for a in args if a != "--cut"])
    for other in (["--vary", "0.5"], ["--wide", "0.5"]):  # varied glyphs or wider layouts are other scenes
        with pytest.raises(HandcapError, match="holds scenes made with"):
            train.main(args + other)
    monkeypatch.undo()
    # No steps: the weights are kept, their gate is set on validation scenes, and the chain of commands recorded.
    assert train.main(["--what", "reader", "--steps", "0", "--test-scenes", "1", "--threads", "1",
                       "--init", str(tmp_path / "w" / "reader.npz"), "--out", str(tmp_path / "s")]) == 0
    with np.load(tmp_path / "s" / "reader.npz") as saved:
        assert np.array_equal(saved["w.turn.weight"], first)
        assert "right" in str(saved["info.score"]) and "; then " in str(saved["info.source"])
        assert "--cut" in str(saved["info.source"])


def test_a_scenes_file_splits_into_parts_of_about_equal_size_that_join_into_it(tmp_path, capsys):
    from handcap.detect.scenefile import main, split_scenes
    rng = np.random.default_rng(7)
    train, test = [_scene(rng) for _ in range(9)], [_scene(rng) for _ in range(3)]
    info = {"scenes": 9, "seed": 1}
    whole = tmp_path / "all.npz"
    save_scenes(whole, {"train": train, "test": test}, info)
    before = whole.read_bytes()
    parts = split_scenes(whole, 3)
    assert [p.name for p in parts] == ["all.part1of3.npz", "all.part2of3.npz", "all.part3of3.npz"]
    sizes = np.array([p.stat().st_size for p in parts])
    assert sizes.max() < 1.6 * sizes.min()  # twelve random images of 80-180 px a side
    assert [load_scenes(p)[1]["part"] for p in parts] == [[1, 3], [2, 3], [3, 3]]
    assert main(["join", str(tmp_path / "joined.npz")] + [str(p) for p in parts]) == 0
    joined, got = load_scenes(tmp_path / "joined.npz")
    assert got == info and whole.read_bytes() == before
    assert all(_same(a, b) for a, b in zip(test + train, joined["test"] + joined["train"]))
    # Every part holds a scene, however the sizes fall; a part is not split again; too many parts is refused.
    assert all(sum(map(len, load_scenes(p)[0].values())) >= 1 for p in split_scenes(whole, 12))
    assert main(["split", str(parts[0]), "2"]) == 2 and "join the parts first" in capsys.readouterr().err
    with pytest.raises(HandcapError, match="cannot split 12 scenes into 13 parts"):
        split_scenes(whole, 13)


@pytest.fixture()
def made(monkeypatch):
    """The scene makers ``reader_scenes`` builds, as (seed, font, alphabet, layout), without rendering a scene."""
    from handcap.detect import samples

    made = []

    class Maker:
        def __init__(self, seed, *, font=None, alphabet=None, layout=None, **kw):
            made.append((seed, font, alphabet, layout))

        def scene(self):
            return object()

        def close(self):
            pass

    monkeypatch.setattr(samples, "SceneMaker", Maker)
    monkeypatch.setattr(samples, "PageMaker", Maker)
    return made


def test_wider_layouts_change_only_the_random_layouts_drawn(made):
    """``reader_scenes(..., wide=S)`` swaps a share S of the random glyph layouts for wide ones, drawn from their own
    stream: the scenes with handcap's layout, and every other draw, stay as they were."""
    from handcap.detect import samples

    runs = {}
    for wide in (0.0, 0.6):
        made.clear()
        assert len(samples.reader_scenes(96, 4, [None, "f"], wide=wide)) == 96
        runs[wide] = list(made)
    plain, wide = runs[0.0], runs[0.6]
    assert [m[:3] for m in plain] == [m[:3] for m in wide] and len(plain) > 12
    changed = [b for a, b in zip(plain, wide) if a[3] != b[3]]
    assert all(a[3] is None for a, b in zip(plain, wide) if b[3] is None)  # handcap's layout kept
    assert 0.3 < len(changed) / sum(m[3] is not None for m in plain) < 0.9
    assert any(b[3].underline_span is not None for b in changed)


def test_the_share_of_random_layouts_is_the_one_asked_for(made):
    """``reader_scenes(..., layouts=S)``: a share S of the groups of scenes gets a random glyph layout. The default
    (0.5) alternates the groups, as before the option; 0 and 1 give handcap's layout only or random ones only."""
    from handcap.detect import samples

    share = {}
    for layouts in (0.0, 0.5, 0.85, 1.0):
        made.clear()
        assert len(samples.reader_scenes(600, 4, [None, "f"], layouts=layouts)) == 600
        random = [m[3] is not None for m in made]
        share[layouts] = np.mean(random)
        if layouts == 0.5:  # groups of 3 alphabets x 2 fonts, every other one random
            assert random[:18] == [False] * 6 + [True] * 6 + [False] * 6
    assert share[0.0] == 0.0 and share[1.0] == 1.0 and 0.4 < share[0.5] < 0.6 and 0.75 < share[0.85] < 0.95
    with pytest.raises(HandcapError, match="must be 0 to 1"):
        samples.reader_scenes(10, 4, [None], layouts=1.5)
