"""The detector's scoring against rendered truth: a detector that reports the truth scores perfectly,
and a tag or a corner that is not where its name says counts as wrong."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from handcap.detect.evaluation import evaluate_detector
from handcap.detect.pipeline import ImageDetections
from handcap.patterns import session_pattern


class _Oracle:
    """Reports each scene's truth, optionally with one visible tag's corner moved 5 px and one hidden tag."""

    def __init__(self, scene, spoil: bool = False):
        self.pattern = session_pattern(("right",), (), alphabet=scene.alphabet)
        self.scene, self.spoil = scene, spoil

    def image(self, image):
        s = self.scene
        text, xy = list(s.block_text), np.array(s.blocks, float)
        corners = np.array(s.corners, float)
        if self.spoil:
            xy[0, 0] += 5.0
            corners[0] += 5.0
            # A tag the truth calls hidden (a corner behind the hand), reported at its true corners.
            tag, names = next((tag, names) for patch in self.pattern.patches for tag, r, c in patch.blocks()
                              for names in [[patch.corner_name(*v) for v in patch.block_vertices(r, c)]]
                              if tag not in text and all(n in s.projected for n in names))
            text.append(tag)
            xy = np.concatenate([xy, np.array([s.projected[n] for n in names])[None]])
        return ImageDetections(corners, np.ones(len(corners)), np.array(s.corner_names, object),
                               np.array(text), xy, np.ones(len(text)), 0)


def test_the_truth_scores_perfectly_and_a_moved_corner_is_wrong(scenes):
    scene = scenes[0]
    perfect = evaluate_detector(_Oracle(scene), [scene])
    assert perfect.blocks == len(scene.blocks) > 5 and perfect.right == perfect.read == perfect.blocks
    assert perfect.wrong == perfect.misnamed == 0 and perfect.named_right == perfect.corners == len(scene.corners)
    spoilt = evaluate_detector(_Oracle(scene, spoil=True), [scene])
    # The moved block is wrong; the hidden tag is right but not counted among the visible tags read right.
    assert spoilt.read == perfect.blocks + 1 and spoilt.wrong == 1 and spoilt.right == perfect.blocks - 1
    assert spoilt.misnamed == 1 and spoilt.named_right == len(scene.corners) - 1
    # The named corners' errors: none off in the truth; moved 0.5 px, each is off by 0.5 px (the 5 px one is wrong).
    assert len(perfect.named_px) == len(scene.corners) and np.all(perfect.named_px < 1e-9)
    nudged = evaluate_detector(_Nudged(scene), [scene])
    assert len(nudged.named_px) == len(scene.corners) - 1 and np.allclose(nudged.named_px, 0.5)
    assert "read right" in spoilt.summary()


class _Nudged(_Oracle):
    """The truth with every corner moved 0.3 px right and 0.4 px down, one of them 5 px."""

    def image(self, image):
        found = super().image(image)
        corners = found.corners + [0.3, 0.4]
        corners[0] += 5.0
        return replace(found, corners=corners)


class _Reader:
    """A detector without a template: reports a scene's visible tags at their corners, one of them turned a
    quarter (its corners out of reading order), and one tag the sheet does not hold."""

    pattern = None

    def __init__(self, scene):
        self.scene = scene

    def image(self, image):
        s = self.scene
        text, xy = list(s.block_text), np.array(s.blocks, float)
        xy[1] = np.roll(xy[1], 1, axis=0)
        text.append("QQ")
        xy = np.concatenate([xy, xy[:1] + 40.0])
        return ImageDetections(np.zeros((0, 2)), np.zeros(0), np.zeros(0, object), np.array(text), xy,
                               np.ones(len(text)), 0)


def test_another_generators_sheet_read_without_a_template_is_scored_by_position():
    from handcap.detect.scenes import SheetMaker
    from handcap.synth.pages import PageLook

    maker = SheetMaker(3, "0123456789ACEHNPRSTVXZ", rows=8, cols=10,
                       look=PageLook(square_px=(12.0, 14.0), tilt_deg=(0.0, 20.0), occluders=(0, 0)))
    plain = {(r, c) for r in range(8) for c in range(10) if (r + c) % 2 and (r % 4 == 0 or c in (0, 4, 8))}
    assert maker.plain == plain and len(maker.block_text) == 40 - len(plain) == len(set(maker.block_text))
    scene = maker.scene()
    assert len(scene.blocks) > 10
    score = evaluate_detector(_Reader(scene), [scene])
    assert (score.blocks, score.read, score.right, score.wrong) == (len(scene.blocks), len(scene.blocks) + 1,
                                                                    len(scene.blocks) - 1, 2)
    assert score.named == 0
