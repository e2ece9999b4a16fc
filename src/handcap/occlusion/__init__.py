"""Occluded markers and hand pose in real time, and gap filling of recorded takes.

After Pavllo et al. 2019, "Real-time neural network prediction for handling
two-hands mutual occlusions" (doi:10.1016/j.cagx.2019.100011)::

    filler = OcclusionFiller.load("glove-13", rate=100.0)      # shipped model, numpy only
    result = filler.update(frame)        # frame (M, 3) metres, NaN = occluded
    result.markers, result.filled, result.phi, result.global_orient, result.transl

    filled, report = fill_gaps(markers, "nn", model="glove-13", max_gap_s=0.5)   # a recorded take

    model = train_occlusion_model([read_take("rom.c3d")], "glove-13", seed=0)  # torch, a user's takes
    model.save("mine.npz")

Modules: :mod:`~handcap.occlusion.baselines` (LK, MA, AC),
:mod:`~handcap.occlusion.register` (Kabsch to the template),
:mod:`~handcap.occlusion.predictor` (autoencoder), :mod:`~handcap.occlusion.history` (the
network's error before a gap, learned and carried into it), :mod:`~handcap.occlusion.regressor`
(joint angles), :mod:`~handcap.occlusion.filler` (streaming, discontinuities, mirroring),
:mod:`~handcap.occlusion.fill` (batch), :mod:`~handcap.occlusion.evaluate` (Tables 3 and 4),
:mod:`~handcap.occlusion.takes` (a take with its poses), :mod:`~handcap.occlusion.train`,
:mod:`~handcap.occlusion.shipped` (the shipped weights).
"""

from handcap.occlusion.evaluate import joint_error_table, marker_error_table
from handcap.occlusion.fill import FILL_METHODS, FillReport, fill_gaps
from handcap.occlusion.filler import FillResult, OcclusionFiller
from handcap.occlusion.model import SHIPPED_MODELS, OcclusionModel
from handcap.occlusion.train import read_take, train_occlusion_model

__all__ = ["FILL_METHODS", "SHIPPED_MODELS", "FillReport", "FillResult", "OcclusionFiller", "OcclusionModel",
           "fill_gaps", "joint_error_table", "marker_error_table", "read_take", "train_occlusion_model"]
