"""The labeling model (handcap.labeling.model): saved and read back."""

import numpy as np

from handcap.labeling import LabelingModel, corrupt, label_take


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
