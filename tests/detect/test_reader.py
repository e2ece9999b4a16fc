"""The block reader: views that turn with the corners, alphabet checks, a tiny training run, weights files."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from handcap import HandcapError
from handcap.detect.corners import CornerNet
from handcap.detect.reader import GLYPHS, NONE, BlockReader, block_views, read_blocks, reader_heads, tag_probability
from handcap.detect.train import load_reader, reader_samples, save_net, train_reader


def _image():
    rng = np.random.default_rng(0)
    image = (rng.random((120, 160)) * 60).astype(np.uint8)
    image[40:80, 60:100] = 220
    image[50:60, 65:75] = 30  # a mark near the square's top-left, to tell the turns apart
    return image, np.array([[59.5, 39.5], [99.5, 39.5], [99.5, 79.5], [59.5, 79.5]])


def test_views_turn_with_the_corner_order():
    image, quad = _image()
    base = block_views(image, quad[None])[0]
    assert base.shape == (32, 32) and base[11:15, 8:12].mean() < base[20:26, 20:26].mean() - 0.5  # the mark
    for shift in range(1, 4):
        turned = block_views(image, np.roll(quad, -shift, axis=0)[None])[0]
        # Starting the corners one later turns the view a quarter counterclockwise.
        np.testing.assert_allclose(turned, np.rot90(base, shift), atol=0.05)


def test_read_blocks_refuses_glyphs_it_does_not_know():
    image, quad = _image()
    with pytest.raises(HandcapError, match="knows no glyph"):
        read_blocks(BlockReader(), image, quad[None], "AB\u00e9")
    text, corners, rotation, score = read_blocks(BlockReader(), image, quad[None], "0123456789")
    assert corners.shape == (1, 4, 2) and rotation.shape == score.shape == (1,)
    assert text[0] == "" or all(ch in "0123456789" for ch in text[0])


def test_a_reading_over_every_turn_does_not_depend_on_the_first_corner(scenes):
    reader = load_reader()  # the shipped weights
    scene = max(scenes, key=lambda s: len(s.blocks))
    quads = scene.blocks[:12]
    text, corners, rotation, score = read_blocks(reader, scene.image, quads, scene.alphabet, turns=4)
    assert (text != "").sum() >= 6
    for turns, shifts in ((4, (1, 2, 3)), (2, (2,))):
        text, corners, _, score = read_blocks(reader, scene.image, quads, scene.alphabet, turns=turns)
        for shift in shifts:
            again, at, _, score_again = read_blocks(reader, scene.image, np.roll(quads, -shift, axis=1), scene.alphabet,
                                                    turns=turns)
            np.testing.assert_array_equal(again, text)
            np.testing.assert_allclose(score_again, score, rtol=1e-4, atol=1e-6)
            np.testing.assert_allclose(at[text != ""], corners[text != ""])  # the same corners in reading order
    # One view alone is not turn-free: its confidences change when the corners start elsewhere.
    one = read_blocks(reader, scene.image, quads, scene.alphabet, turns=1)[3]
    other = read_blocks(reader, scene.image, np.roll(quads, -1, axis=1), scene.alphabet, turns=1)[3]
    assert np.abs(one - other).max() > 1e-3
    with pytest.raises(HandcapError, match="1, 2 or 4 turns"):
        read_blocks(reader, scene.image, quads, scene.alphabet, turns=3)


def test_the_probability_of_a_given_tag_is_the_readers_score_of_its_own_reading(scenes):
    reader = load_reader()  # the shipped weights
    scene = max(scenes, key=lambda s: len(s.blocks))
    quads = np.asarray(scene.blocks[:12], dtype=np.float64)
    text, _, rotation, score = read_blocks(reader, scene.image, quads, scene.alphabet)
    read = np.flatnonzero(text != "")
    assert len(read) >= 6
    np.testing.assert_allclose(tag_probability(reader, scene.image, quads[read], scene.alphabet, text[read],
                                               rotation[read]), score[read], rtol=1e-5)
    # The same tag a quarter turn off, or another tag, is less likely than the reading.
    turned = tag_probability(reader, scene.image, quads[read], scene.alphabet, text[read], (rotation[read] + 1) % 4)
    assert (turned < score[read]).all()
    other = [scene.alphabet[(scene.alphabet.index(t[0]) + 1) % len(scene.alphabet)] + t[1] for t in text[read]]
    other = tag_probability(reader, scene.image, quads[read], scene.alphabet, other, rotation[read])
    assert (other < score[read]).all()
    with pytest.raises(HandcapError, match="not two glyphs"):
        tag_probability(reader, scene.image, quads[:1], scene.alphabet, ["A"], [0])
    with pytest.raises(HandcapError, match="one tag and one rotation"):
        tag_probability(reader, scene.image, quads[:2], scene.alphabet, [text[read[0]]] * 2, [0, 4])


def test_heads_read_once_give_what_the_network_gives_again(scenes):
    reader = load_reader()  # the shipped weights
    scene = max(scenes, key=lambda s: len(s.blocks))
    quads = np.asarray(scene.blocks[:12], dtype=np.float64)
    heads = reader_heads(reader, scene.image, quads, scene.alphabet)
    for got, want in zip(read_blocks(reader, scene.image, quads, scene.alphabet, heads=heads),
                         read_blocks(reader, scene.image, quads, scene.alphabet)):
        np.testing.assert_array_equal(got, want)
    # A part of the blocks, with their part of the heads: the probability of other tags and turns than those read
    # is what the network gives when it looks at that part alone.
    part = np.arange(1, len(quads), 2)
    tags = [scene.alphabet[k % len(scene.alphabet)] * 2 for k in range(len(part))]
    turns = np.arange(len(part)) % 4
    np.testing.assert_allclose(
        tag_probability(reader, scene.image, quads[part], scene.alphabet, tags, turns,
                        heads=tuple(h[part] for h in heads)),
        tag_probability(reader, scene.image, quads[part], scene.alphabet, tags, turns), rtol=1e-4, atol=1e-9)
    with pytest.raises(HandcapError, match="1, 2 or 4 turns"):
        reader_heads(reader, scene.image, quads, scene.alphabet, turns=3)


def test_samples_label_the_turn_and_the_glyphs(scenes):
    views, first, second, turn = reader_samples(scenes, 64, np.random.default_rng(0))
    tags = turn < 4
    assert views.shape == (64, 32, 32) and 10 < tags.sum() < 64
    assert (first[~tags] == NONE).all() and (second[~tags] == NONE).all()
    assert set(GLYPHS[i] for i in first[tags]) <= set("0123456789ACEFHPUY")


def test_blocks_with_a_corner_moved_are_shown_as_no_block(scenes):
    same = reader_samples(scenes, 64, np.random.default_rng(0), displaced=0.0)
    np.testing.assert_array_equal(same[0], reader_samples(scenes, 64, np.random.default_rng(0))[0])
    views, first, second, turn = reader_samples(scenes, 64, np.random.default_rng(0), displaced=1.0)
    assert (turn == 4).all() and (first == NONE).all() and (second == NONE).all()
    assert not np.allclose(views, same[0])  # the moved corners change what the reader sees


def test_views_processed_as_a_phone_does(scenes):
    # phone=0 draws exactly the default views; phone=1 processes every view's surroundings (its labels still
    # drawn as before for the first view, whose draws come first).
    plain = reader_samples(scenes, 32, np.random.default_rng(1))
    for a, b in zip(plain, reader_samples(scenes, 32, np.random.default_rng(1), phone=0.0)):
        np.testing.assert_array_equal(a, b)
    views, first, second, turn = reader_samples(scenes, 32, np.random.default_rng(1), phone=1.0)
    assert (first[0], second[0], turn[0]) == (plain[1][0], plain[2][0], plain[3][0])
    assert not np.allclose(views[0], plain[0][0])
    assert np.isfinite(views).all() and (turn[turn < 4] >= 0).all()


def test_a_few_reader_steps_lower_the_loss_and_repeat_exactly(scenes, tmp_path):
    from handcap.detect.reader import reader_loss
    views, *labels = reader_samples(scenes, 48, np.random.default_rng(5))
    batch = [torch.from_numpy(x) for x in labels]
    torch.manual_seed(0)
    before = reader_loss(BlockReader().eval()(torch.from_numpy(views)[:, None]), *batch).item()
    net = train_reader(scenes, steps=12, batch=24, seed=2)
    after = reader_loss(net(torch.from_numpy(views)[:, None]), *batch).item()
    assert after < 0.95 * before
    net = train_reader(scenes, steps=3, batch=8, seed=2)
    again = train_reader(scenes, steps=3, batch=8, seed=2)
    assert all(torch.equal(a, b) for a, b in zip(net.state_dict().values(), again.state_dict().values()))
    save_net(net, tmp_path / "r.npz")
    loaded = load_reader(tmp_path / "r.npz")
    assert all(torch.equal(a, b) for a, b in zip(net.state_dict().values(), loaded.state_dict().values()))
    save_net(CornerNet(), tmp_path / "c.npz")
    with pytest.raises(HandcapError, match="not a BlockReader"):
        load_reader(tmp_path / "c.npz")


def test_cut_scenes_give_the_same_views_and_views_drawn_in_workers_repeat(scenes):
    for scene in scenes:
        cut = scene.cropped()
        assert cut.image.size < scene.image.size and len(cut.blocks) == len(scene.blocks)
        np.testing.assert_allclose(block_views(cut.image, cut.blocks), block_views(scene.image, scene.blocks),
                                   atol=1e-3)
        assert all(np.allclose(cut.projected[k] + scene.corners[0] - cut.corners[0], v)
                   for k, v in scene.projected.items())
    cut = [s.cropped() for s in scenes]
    one = train_reader(cut, steps=3, batch=8, seed=4, workers=2)
    again = train_reader(cut, steps=3, batch=8, seed=4, workers=2)
    other = train_reader(cut, steps=3, batch=8, seed=5, workers=2)
    state = [(a.state_dict(), b.state_dict(), c.state_dict()) for a, b, c in [(one, again, other)]][0]
    assert all(torch.equal(state[0][k], state[1][k]) for k in state[0])
    assert not all(torch.equal(state[0][k], state[2][k]) for k in state[0])


def test_the_gate_keeps_at_most_the_allowed_share_of_wrong_readings():
    from handcap.detect.evaluation import gate_for

    rng = np.random.default_rng(0)
    score = rng.uniform(0, 1, 5000)
    outcome = np.where(rng.uniform(0, 1, 5000) < score ** 8, 1, -1)  # confident readings are mostly right
    outcome[rng.uniform(0, 1, 5000) < 0.1] = 0  # unread ones do not count
    gate = gate_for(outcome, score, max_wrong=0.01)
    kept = (score >= gate) & (outcome != 0)
    assert (outcome[kept] == -1).mean() <= 0.01
    lower = (score >= np.max(score[score < gate])) & (outcome != 0)  # one reading more: too many wrong
    assert (outcome[lower] == -1).mean() > 0.01 or lower.sum() == kept.sum() + 1
    assert gate_for(np.array([-1, -1]), np.array([0.9, 0.8]), 0.001) == 1.0


def test_a_reading_with_a_glyph_whose_look_alike_is_printed_needs_a_surer_reader():
    """DexterCap's 22-glyph alphabet prints S and 5, Z and 2 and 7: a tag with one of them is trusted alone only at
    LOOKALIKE_GATE; its other tags, and every tag of an alphabet without look-alikes, at the reader's own gate."""
    from handcap.detect.pipeline import LOOKALIKE_GATE, Detector
    from handcap.patterns.alphabet import DEXTERCAP_ALPHABET

    reader = BlockReader()
    reader.min_score = 0.9
    theirs = Detector(CornerNet(), reader, alphabet="0123456789ACEHNPRSTVXZ")
    text = np.array(["S4", "40", "7A", "AC", "02", "", "Z9"])
    assert np.array_equal(theirs.gates(text), [LOOKALIKE_GATE, 0.9, LOOKALIKE_GATE, 0.9, LOOKALIKE_GATE, 0.9,
                                               LOOKALIKE_GATE])
    assert (Detector(CornerNet(), reader, alphabet=DEXTERCAP_ALPHABET).gates(np.array(["57", "2A"])) == 0.9).all()
    reader.min_score = 0.9995  # a reader surer than the look-alike gate keeps its own
    assert (theirs.gates(np.array(["S4", "40"])) == 0.9995).all()


def test_without_a_template_only_readings_sure_in_an_unseen_font_are_reported(scenes):
    """No vote can correct a reading made without a template: those reported score UNSEEN_FONT_GATE or more, and
    they are the readings the reader's own gate keeps less those below it."""
    from handcap.detect.networks import load_corner_net, load_refiner
    from handcap.detect.pipeline import UNSEEN_FONT_GATE, Detector
    from handcap.detect.train import load_reader as shipped_reader

    reader = shipped_reader()
    alone = Detector(load_corner_net(int8=True), reader, alphabet=scenes[0].alphabet,
                     refiner=load_refiner(int8=True))
    found = [alone.image(s.image) for s in scenes]
    scores = np.concatenate([f.block_score for f in found])
    assert len(scores) >= 5 and (scores >= UNSEEN_FONT_GATE).all()
    reader.min_score = 0.0  # every reading trusted by the reader: the detector still holds back the unsure ones
    assert [len(f.block_text) for f in found] == [len(alone.image(s.image).block_text) for s in scenes]


def test_each_view_is_normalised_by_its_own_levels():
    # Every view: zero median and unit 5-95 % spread, computed here from the warped view of each block alone.
    import cv2

    image, quad = _image()
    quads = np.stack([quad, quad + 7.3, np.roll(quad, 1, axis=0) - 4.1])
    views = block_views(image, quads)
    square = np.array([[4, 4], [28, 4], [28, 28], [4, 28]], np.float32) - 0.5
    for view, q in zip(views, quads):
        raw = cv2.warpPerspective(image.astype(np.float32), cv2.getPerspectiveTransform(q.astype(np.float32), square),
                                  (32, 32), flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
        lo, mid, hi = np.percentile(raw, (5, 50, 95))
        np.testing.assert_allclose(view, (raw - mid) / (hi - lo), rtol=1e-6, atol=1e-6)
    flat = block_views(np.full((60, 60), 90, np.uint8), quads[:1] - 30)
    assert np.isfinite(flat).all()
    assert block_views(image, quads[:0]).shape == (0, 32, 32)
