"""The labeling model (handcap.labeling.model): saved and read back."""

import numpy as np

from handcap.labeling import LabelingModel, corrupt, label_take, score_labels


def test_model_round_trip(glove, tmp_path):
    take, model, _ = glove
    model.save(tmp_path / "model.npz")
    again = LabelingModel.load(tmp_path / "model.npz")
    unlabeled, _ = corrupt(take[2000:2300], seed=2)
    a = label_take(unlabeled, model).markers.positions
    b = label_take(unlabeled, again).markers.positions
    np.testing.assert_array_equal(a, b)


def test_labels_swapped_back_and_forth_in_training_are_left_out_of_the_tuning_and_a_warning(tmp_path):
    import pytest

    from handcap import MarkerSequence
    from handcap.core.errors import HandcapWarning
    from handcap.layouts import load_layout
    from handcap.synth.scene import SynthConfig, synthesize

    layout = load_layout("glove-13")
    take = synthesize(SynthConfig(layout="glove-13", motion="random", frames=300, seed=4),
                      progress=False).labeled_points(layout.names)
    clean = LabelingModel.train(take, layout.names, layout.rigid)
    assert clean.warnings == ()
    positions = take.positions.copy()
    a, b = take.index("thumb_tip"), take.index("index_tip")
    positions[::2, [a, b]] = take.positions[::2, [b, a]]  # swapped in every other frame
    with pytest.warns(HandcapWarning, match="thumb_tip, index_tip jump between frames"):
        model = LabelingModel.train(MarkerSequence(positions, take.names, take.rate), layout.names, layout.rigid)
    assert len(model.warnings) == 1 and "swapped" in model.warnings[0]
    # ... and the filters are tuned on the other labels, as on the clean take (not to the swaps' centimetres)
    assert model.kalman == clean.kalman
    model.save(tmp_path / "model.npz")
    assert LabelingModel.load(tmp_path / "model.npz").warnings == model.warnings


def test_a_model_labels_a_take_of_another_rate_with_the_takes_frame_time(monkeypatch):
    # A model trained at 100 Hz and takes at 30 Hz (synthetic joints-19, 2 ghosts/s, 5 % dropouts; the three
    # seeds tried). Stepping the training's 10 ms, each filter predicted a marker a third of the way it moved
    # between frames; stepping the take's 33 ms, more points are labelled right and fewer wrong (measured: 288.2
    # -> 294.3 correct % summed over the seeds, 3.29 -> 2.00 wrong %). The model itself is not changed.
    import pytest

    from handcap.core.errors import HandcapError
    from handcap.layouts import load_layout
    from handcap.synth.scene import SynthConfig, synthesize

    layout = load_layout("joints-19")

    def take(seed, frames, rate):
        config = SynthConfig(layout="joints-19", motion="random", object="none", frames=frames, rate=rate,
                             seed=seed, subject_seed=5, cameras=8)
        return synthesize(config, progress=False).labeled_points(layout.names)

    model = LabelingModel.train(take(11, 1200, 100.0), layout.names, layout.rigid)
    assert model.kalman.dt == 0.01 and model.at_rate(100.0) is model and model.at_rate(float("nan")) is model
    assert model.at_rate(30.0).kalman.dt == pytest.approx(1 / 30) and model.kalman.dt == 0.01
    assert model.at_rate(30.0).kalman.jerk == model.kalman.jerk
    with pytest.raises(HandcapError, match="positive"):
        model.at_rate(-30.0)
    takes = [corrupt(take(seed, 300, 30.0), ghost_rate=2.0, dropout=0.05, seed=0) for seed in (21, 22, 23)]
    scores = {}
    for fixed in (True, False):
        if not fixed:
            monkeypatch.setattr(LabelingModel, "at_rate", lambda self, rate: self)
        scores[fixed] = np.zeros(2)
        for points, truth in takes:
            s = score_labels(label_take(points, model).markers, truth)
            scores[fixed] += [s.fraction("correct"), s.fraction("erroneous")]
    assert scores[True][0] > scores[False][0] + 0.04
    assert scores[True][1] < 0.8 * scores[False][1]
