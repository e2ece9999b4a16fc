"""Pick a hand model by name: ``--hand-model openhand``, ``mano:/path`` or ``mano``.

:func:`load_hand_model` reads one spec string; :func:`hand_model_from_options`
joins the command line's ``--hand-model`` and ``--mano-dir`` with the model a
result was made with (an attachment or a motion records ``openhand`` or
``mano``), so a MANO attachment is never solved with the OpenHand by mistake.
"""

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
#: Model names that results record (``MarkerAttachment.model``, ``HandMotion.model``).
MODEL_NAMES = ("openhand", "mano")


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


def hand_model_from_options(spec: str | None = None, mano_dir=None, *, side: str = "right",
                            recorded: str | None = None, what: str = "the input") -> HandModel:
    """The hand model chosen by ``--hand-model`` and ``--mano-dir``, checked against a recorded one.

    Parameters
    ----------
    spec : str, optional
        ``"openhand"``, ``"mano"`` or ``"mano:/path"`` (as :func:`load_hand_model`).
        Default: ``"mano"`` when ``mano_dir`` is given, else ``recorded`` if
        given, else ``"openhand"``.
    mano_dir : path, optional
        Folder of ``MANO_RIGHT.pkl`` / ``MANO_LEFT.pkl`` (or one of the files);
        overrides ``HANDCAP_MANO_DIR``. Only with the MANO model.
    side : {"right", "left"}
    recorded : {"openhand", "mano"}, optional
        The model that ``what`` was made with; another choice is refused.
    what : str
        Names the input that recorded the model, for messages.

    Returns
    -------
    HandModel

    Raises
    ------
    HandcapError
        A MANO folder or file that is missing or unreadable, an unset
        ``HANDCAP_MANO_DIR``, ``mano_dir`` with the OpenHand, or a choice that
        differs from ``recorded``.
    """
    if spec is not None and not isinstance(spec, str):
        raise HandcapError(f"hand model must be a string such as 'openhand', got {type(spec).__name__}")
    if recorded is not None and recorded not in MODEL_NAMES:
        raise HandcapError(f"{what} was made with an unknown hand model {recorded!r}; handcap knows "
                           f"{', '.join(MODEL_NAMES)}")
    kind = None if spec is None else spec.strip().partition(":")[0]
    if kind is None:
        kind = "mano" if mano_dir is not None else (recorded or "openhand")
        spec = kind
    if recorded is not None and kind != recorded:
        raise HandcapError(f"{what} was made with the {recorded} hand model, not {kind}; use --hand-model {recorded}"
                           + (" with --mano-dir DIR or HANDCAP_MANO_DIR" if recorded == "mano" else ""))
    if mano_dir is not None:
        if kind != "mano" or ":" in spec:
            raise HandcapError("--mano-dir goes with --hand-model mano (or give --hand-model mano:DIR alone)")
        folder = Path(mano_dir).expanduser()
        if not folder.exists():
            raise HandcapError(f"MANO folder {mano_dir} does not exist; give the folder holding "
                               "MANO_RIGHT.pkl/MANO_LEFT.pkl (downloaded from https://mano.is.tue.mpg.de)")
        return ManoHand.load(folder, side)
    if kind == "mano" and ":" not in spec and not os.environ.get(MANO_DIR_VARIABLE, ""):
        raise HandcapError(f"the MANO hand model needs its files: give --mano-dir DIR or set {MANO_DIR_VARIABLE} "
                           "to the folder holding MANO_RIGHT.pkl/MANO_LEFT.pkl")
    return load_hand_model(spec, side)
