"""The online labeler's deferred work (``defer``, ``idle()``): the live stream's way of paying for the filters'
step and the periodic re-alignment between frames, which must leave every label as it was."""

import numpy as np

from handcap.labeling import OnlineLabeler
from handcap.synth.scene import SynthConfig, synthesize


def test_deferred_work_gives_the_same_labels(joints_model):
    model = joints_model
    take = synthesize(SynthConfig(layout="joints-19", motion="grasp", frames=310, rate=120.0, seed=4,
                                  subject_seed=3), progress=False)
    points = take.points.padded()
    runs = []
    for defer, idle in ((False, False), (True, False), (True, True)):
        labeler = OnlineLabeler(model, hypotheses=2, adapt_every=38, defer=defer)
        labels = []
        for frame in points:
            labels.append(labeler.update(frame))
            if idle:
                labeler.idle()
        runs.append(np.array(labels))
    assert (runs[0] >= 0).mean() > 0.5  # most points labelled, the model re-aligned 8 times on the way
    assert np.array_equal(runs[0], runs[1]) and np.array_equal(runs[0], runs[2])
