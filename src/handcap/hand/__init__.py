"""Hand models: the built-in :class:`OpenHand` and a loader for a user's own MANO files.

Both share MANO's 16-joint tree and parameter layout (``betas`` 10,
``global_orient`` 3, ``hand_pose`` 45 axis-angle relative to the flat hand,
``transl`` 3) and the anatomical 27-DoF pose of :mod:`handcap.hand.anatomy`.
"""

from handcap.hand.anatomy import (
    JOINT_NAMES,
    PHI_LIMITS,
    PHI_NAMES,
    SEGMENT_NAMES,
    TIP_NAMES,
    hand_pose_from_phi,
    joint_frames,
    phi_from_hand_pose,
)
from handcap.hand.mano import ManoHand
from handcap.hand.model import HandModel, HandOutput
from handcap.hand.openhand import OpenHand
from handcap.hand.select import hand_model_from_options, load_hand_model

__all__ = [
    "JOINT_NAMES",
    "PHI_LIMITS",
    "PHI_NAMES",
    "SEGMENT_NAMES",
    "TIP_NAMES",
    "HandModel",
    "HandOutput",
    "ManoHand",
    "OpenHand",
    "hand_pose_from_phi",
    "joint_frames",
    "hand_model_from_options",
    "load_hand_model",
    "phi_from_hand_pose",
]
