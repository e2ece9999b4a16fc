"""The detector's scoring against rendered truth: a detector that reports the truth scores perfectly,
and a tag or a corner that is not where its name says counts as wrong."""

from __future__ import annotations

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
    assert "read right" in spoilt.summary()
