"""Step ``export``: a solved hand motion written for other tools (BVH, CSV of joint angles, C3D/TRC of joints,
MANO parameters)."""

from __future__ import annotations

from handcap.core.errors import HandcapError
from handcap.export import FORMATS, export_motion
from handcap.hand import hand_model_from_options
from handcap.io import check_not_input, read_hand_motion
from handcap.steps.step import Step


def export(motion, to, *, units: str = "cm", hand_model: str | None = None, mano_dir=None) -> Step:
    """Write ``motion`` in the format the suffix of ``to`` names (:data:`handcap.export.FORMATS`).

    Parameters
    ----------
    motion, to : str or Path
        Hand motion ``.npz`` (``handcap solve``); the file to write.
    units : {'cm', 'mm', 'm'}
        Length unit of a BVH file.
    hand_model, mano_dir : str or None
        The hand model (default: the motion's).

    Returns
    -------
    Step
    """
    check_not_input(to, motion)
    solved = read_hand_motion(motion)
    if solved.n_frames == 0:
        raise HandcapError(f"{motion}: holds no frames")
    hand = hand_model_from_options(hand_model, mano_dir, side=solved.side, recorded=solved.model, what=str(motion))
    warnings = export_motion(solved, hand, to, units=units)
    kind = FORMATS[str(to)[str(to).rfind("."):].lower()].split(":")[0]
    return Step((f"{to}: {solved.n_frames} frames at {solved.rate:g} Hz, {kind}",), tuple(warnings), (str(to),),
                None)
