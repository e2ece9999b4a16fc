"""Step ``metrics``: the quality figures of a solved motion, printed and optionally written as JSON."""

from __future__ import annotations

import json

import numpy as np

from handcap.core.errors import HandcapError, merge_warnings
from handcap.hand import hand_model_from_options
from handcap.io import atomic_output, check_output, read_hand_motion, read_markers
from handcap.quality import plausibility as q
from handcap.report import metrics_table, motion_metrics
from handcap.solve.motion import observed_markers
from handcap.steps.step import Step


def metrics(motion, *, truth=None, markers=None, obj=None, object_mesh=None, attachment=None,
            leave_one_out: bool = False, out=None, hand_model: str | None = None, mano_dir=None) -> Step:
    """MRE, joint error, leave-one-marker-out error, MSNR, jerk, penetration, diversity and coherence of a motion.

    Parameters
    ----------
    motion : str or Path
        Hand motion .npz.
    truth, markers, obj, object_mesh, attachment : str, Path or None
        Ground truth, the labeled markers it was solved from, the object motion and mesh, the attachment (see
        :func:`handcap.report.motion_metrics`).
    leave_one_out : bool
        Solve again without each marker (slow).
    out : str, Path or None
        Also write the metrics (and the warnings) as JSON.
    hand_model, mano_dir : str or None
        The hand model (default: the motion's).

    Returns
    -------
    Step
        ``result`` is the dict of metrics, with its ``warnings``.
    """
    if out:
        check_output(out, motion, truth, markers, attachment, obj, object_mesh)
    hand = None
    if hand_model or mano_dir or (object_mesh and obj) or leave_one_out:
        solved = read_hand_motion(motion)  # the model is needed for the mesh: the one it was solved with
        hand = hand_model_from_options(hand_model, mano_dir, side=solved.side, recorded=solved.model,
                                       what=str(motion))
    figures = motion_metrics(motion, truth=truth, markers=markers, obj=obj, object_mesh=object_mesh,
                             attachment=attachment, leave_one_out=leave_one_out, hand=hand)
    stored, warnings = motion_file_warnings(motion, markers)
    warnings = merge_warnings(warnings, figures.pop("warnings", ()))
    figures["warnings"] = list(warnings)
    lines = (metrics_table(figures),
             f"{'quality':22s} " + (f"{len(warnings)} warning(s), {len(stored)} of them stored in {motion}; see below"
                                    if warnings else "no warnings"))
    if out:
        with atomic_output(out, "w") as fh:
            json.dump(figures, fh, indent=2)
    return Step(lines, warnings, (str(out),) if out else (), figures)


def motion_file_warnings(motion_path, markers_path=None) -> tuple[tuple[str, ...], tuple[str, ...]]:
    """The warnings stored in a hand motion file, and those plus the checks of the motion, without repeats.

    The checks include the fit to the markers the motion was solved from, when they are given and the
    motion has its ``marker_fit``.

    Parameters
    ----------
    motion_path : str or Path
        A hand motion ``.npz``.
    markers_path : str or Path, optional
        The marker file it was solved from (metres once read); its frames must match the motion's.

    Returns
    -------
    stored : tuple of str
        The warnings in the file.
    all : tuple of str
        ``stored`` and the warnings of the checks, each once.
    """
    motion = read_hand_motion(motion_path)
    found = q.motion_warnings(motion)
    if markers_path is not None and motion.marker_fit is not None:
        observed, _ = observed_markers(read_markers(markers_path), list(motion.marker_names))
        if observed.shape[0] != motion.n_frames:
            raise HandcapError(f"{markers_path} has {observed.shape[0]} frames and {motion_path} {motion.n_frames}: "
                               f"give the markers the motion was solved from")
        found += q.residual_warnings(np.linalg.norm(motion.marker_fit - observed, axis=-1), names=motion.marker_names,
                                     what=f"MRE against {markers_path}")
    return motion.warnings, merge_warnings(motion.warnings, found)
