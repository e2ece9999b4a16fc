"""Online labeling of unlabeled finger markers: GMM spatial model, N-best assignments, Kalman, Viterbi.

Implements Alexanderson S., O'Sullivan C., Beskow J. (2016) Robust online
motion capture labeling of finger markers, Proc. Motion in Games, doi:10.1145/2994258.2994264
(``../shared/papers/online-labeling-of-finger-markers.md``), plus tracking
hypotheses, several hands, scoring and a corruption tool.
"""

from handcap.labeling.corrupt import corrupt, move_rigid_set
from handcap.labeling.frame import HandFrameFinder
from handcap.labeling.kalman import KalmanBatch, KalmanSettings
from handcap.labeling.model import LabelingModel
from handcap.labeling.multihand import MultiHandLabeler
from handcap.labeling.online import OnlineLabeler
from handcap.labeling.rigid_set import RigidSet, objects_from_take
from handcap.labeling.take import LabelResult, label_take
from handcap.labeling.murty import k_best_assignments
from handcap.labeling.score import LabelScore, score_labels
from handcap.labeling.spatial import SpatialModel

__all__ = ["HandFrameFinder", "KalmanBatch", "KalmanSettings", "LabelResult", "LabelScore", "LabelingModel",
           "MultiHandLabeler", "OnlineLabeler", "RigidSet", "SpatialModel", "corrupt", "k_best_assignments",
           "label_take", "move_rigid_set", "objects_from_take", "score_labels"]
