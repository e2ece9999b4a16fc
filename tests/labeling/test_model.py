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
