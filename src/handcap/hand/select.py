"""Pick a hand model by name: ``--hand-model openhand``, ``mano:/path`` or ``mano``."""

from __future__ import annotations

import os
from pathlib import Path

from handcap.core.errors import HandcapError
from handcap.core.motion import check_side
from handcap.hand.mano import ManoHand
from handcap.hand.model import HandModel
from handcap.hand.openhand import OpenHand

#: Environment variable naming the folder of the user's MANO files, for the spec ``"mano"``.
MANO_DIR_VARIABLE = "HANDCAP_MANO_DIR"
HAND_MODEL_CHOICES = ("openhand", "mano", "mano:/path/to/models")


def load_hand_model(spec: str = "openhand", side: str = "right") -> HandModel:
    """The hand model named by ``spec``.

    Parameters
    ----------
    spec : str
        ``"openhand"``: the built-in :class:`OpenHand`.
        ``"mano:/path/to/models"``: :meth:`ManoHand.load` of that folder (or
        ``.pkl`` file). ``"mano"``: :meth:`ManoHand.load` of the folder in the
        environment variable ``HANDCAP_MANO_DIR``.
    side : {"right", "left"}

    Returns
    -------
    HandModel

    Raises
    ------
    HandcapError
        For an unknown spec, an unset ``HANDCAP_MANO_DIR`` or a missing or
        unreadable MANO file.
    """
    side = check_side(side)
    if not isinstance(spec, str):
        raise HandcapError(f"hand model must be a string such as 'openhand', got {type(spec).__name__}")
    kind, sep, location = spec.strip().partition(":")
    if kind == "openhand" and not sep:
        return OpenHand(side)
    if kind == "mano" and sep:
        if not location:
            raise HandcapError("hand model 'mano:' needs a folder, e.g. 'mano:/path/to/mano_v1_2/models'")
        return ManoHand.load(location, side)
    if kind == "mano":
        folder = os.environ.get(MANO_DIR_VARIABLE, "")
        if not folder:
            raise HandcapError(f"hand model 'mano' reads the folder in {MANO_DIR_VARIABLE}, which is not set; "
                               "set it to the folder holding MANO_RIGHT.pkl/MANO_LEFT.pkl "
                               "or use 'mano:/path/to/models'")
        if not Path(folder).expanduser().is_dir():
            raise HandcapError(f"{MANO_DIR_VARIABLE}={folder} is not a folder; set it to the folder "
                               "holding MANO_RIGHT.pkl/MANO_LEFT.pkl")
        return ManoHand.load(folder, side)
    raise HandcapError(f"unknown hand model {spec!r}; choose one of: {', '.join(HAND_MODEL_CHOICES)}")
