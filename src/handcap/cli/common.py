"""Argument helpers shared by the verbs: units, frames, shape values, the hand model, marker names."""

from __future__ import annotations

from handcap.core.errors import HandcapError


def add_units(parser, what: str = "the input's coordinates") -> None:
    """``--units mm|cm|m``: the unit of a file that says the wrong one (see handcap.io._units)."""
    from handcap.io import UNITS
    parser.add_argument("--units", choices=UNITS, default=None,
                        help=f"unit of {what}, overriding what the file says (default: the file's; an implausible "
                             f"one is replaced by the only unit that fits, with a warning)")


def frames_arg(text: str | None):
    """``A:B`` (frames, either end optional) -> slice."""
    if text is None:
        return None
    try:
        a, b = text.split(":")
        return slice(int(a) if a else None, int(b) if b else None)
    except ValueError:
        raise HandcapError(f"--frames must be A:B with frame numbers (either may be left out), got {text!r}") from None


def betas_arg(text: str | None):
    """10 comma-separated numbers, or a .npz holding ``betas``."""
    import numpy as np
    if text is None:
        return None
    if text.endswith(".npz"):
        from handcap.io import load_npz
        return np.asarray(load_npz(text, ("betas",), "file with betas")["betas"], dtype=float).reshape(10)
    try:
        values = [float(v) for v in text.split(",")]
    except ValueError:
        raise HandcapError(f"--betas must be 10 comma-separated numbers or a .npz file, got {text!r}") from None
    if len(values) != 10:
        raise HandcapError(f"--betas needs 10 values, got {len(values)}")
    return np.array(values)


def add_hand_model(p, default: str = "openhand") -> None:
    """``--hand-model`` and ``--mano-dir`` for a verb that uses the hand model."""
    p.add_argument("--hand-model", metavar="MODEL",
                   help=f"openhand (built in), mano (your MANO files: --mano-dir or HANDCAP_MANO_DIR) or mano:DIR "
                        f"(default: {default})")
    p.add_argument("--mano-dir", metavar="DIR", help="folder holding MANO_RIGHT.pkl/MANO_LEFT.pkl (implies "
                                                     "--hand-model mano; default: $HANDCAP_MANO_DIR)")


def hand_model(args, side: str, *, recorded: str | None = None, what: str = "the input"):
    """The hand model of ``--hand-model``/``--mano-dir`` (checked against the model ``what`` was made with)."""
    from handcap.hand import hand_model_from_options
    return hand_model_from_options(args.hand_model, args.mano_dir, side=side, recorded=recorded, what=what)


def motion_file_warnings(motion_path, markers_path=None):
    """The warnings stored in a hand motion file, and those plus the checks of the motion (and of its fit to the
    markers it was solved from, when given), without repeats."""
    import numpy as np

    from handcap.core.errors import merge_warnings
    from handcap.io import read_hand_motion, read_markers
    from handcap.quality import plausibility as q
    motion = read_hand_motion(motion_path)
    found = q.motion_warnings(motion)
    if markers_path is not None and motion.marker_fit is not None:
        from handcap.solve.motion import observed_markers
        observed, _ = observed_markers(read_markers(markers_path), list(motion.marker_names))
        found += q.residual_warnings(np.linalg.norm(motion.marker_fit - observed, axis=-1), names=motion.marker_names,
                                     what=f"MRE against {markers_path}")
    return motion.warnings, merge_warnings(motion.warnings, found)
