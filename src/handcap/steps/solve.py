"""Steps of the hand solve: ``calibrate_markers`` (the attachment), ``solve`` (the motion) and ``shape``."""

from __future__ import annotations

import time

import numpy as np

from handcap.core.errors import HandcapError
from handcap.core.files import warnings_entry
from handcap.hand import hand_model_from_options
from handcap.hand.attachment import MarkerAttachment
from handcap.io import check_not_input, check_output, read_markers, read_scan_points, save_npz, write_hand_motion
from handcap.layouts import load_layout, sides_named
from handcap.quality import plausibility as q
from handcap.solve.motion import observed_markers
from handcap.solve import (betas_from_measurements, betas_from_scan, calibrate_attachment, calibrate_without_misfits,
                           hand_measurements, solve_hand)
from handcap.steps.step import Step


def calibrate_markers(path, out, *, layout: str, side: str | None = None, frames: slice | None = None, betas=None,
                      fit_shape: bool | None = None, estimate_offset: bool | None = None, units: str | None = None,
                      hand_model: str | None = None, mano_dir=None, drop_unseen: bool = False,
                      drop_misfit_mm: float | None = None) -> Step:
    """Calibrate the marker attachment from a calibration take (see :func:`handcap.solve.calibrate_attachment`).

    Parameters
    ----------
    path, out : str or Path
        Labeled markers of an open hand slowly turned; the attachment .npz to write.
    layout : str
        Marker layout: a shipped name or a .toml file.
    side : {'right', 'left'} or None
        Hand side (default: the one the markers' ``left:`` or ``right:`` prefixes name, else the layout's).
    frames : slice or None
        Frames of the take to use (default all).
    betas : ndarray (10,) or None
        Known shape values.
    fit_shape, estimate_offset : bool or None
        Estimate the shape values / each marker's height off the skin (None: decided from the layout).
    units : {'mm', 'cm', 'm'} or None
        Unit of the input's coordinates, overriding what the file says.
    hand_model, mano_dir : str or None
        The hand model (see :func:`handcap.hand.hand_model_from_options`; default openhand).
    drop_unseen : bool
        Calibrate only the layout's markers that the take shows at least once, with a warning that counts the
        others (dense patches: corners that no camera pair saw); without it such a marker is an error.
    drop_misfit_mm : float or None
        Calibrate again without the markers whose mean calibration residual exceeds this many millimetres, with a
        warning that names them: corners of a patch that reaches over a joint move with two bones and fit neither
        (a layout made from a template with ``layout new --pattern``).
    """
    check_not_input(out, path)
    marker_layout = load_layout(layout, side=side)
    markers = read_markers(path, units=units, hand=[m.name for m in marker_layout.hand_markers])
    sides = sides_named(markers.names)
    if side is None and len(sides) > 1:
        raise HandcapError("the take holds markers of both hands (left:... and right:...): give --side right or "
                           "--side left to calibrate one")
    named = sides.pop() if len(sides) == 1 else None
    if side is None and named is not None and named != marker_layout.side:
        marker_layout = load_layout(layout, side=named)  # a left hand's take (left:...) is a left hand's
    disagree = [] if side is None or named in (None, side) else [
        f"--side {side}, but the markers are named {named}:...: calibrated on the {side} hand as asked (the mirror "
        f"image of the hand they name)"]
    dropped = []
    if drop_unseen:
        wanted = marker_layout.names
        observed = observed_markers(markers, wanted)[0]  # prefixes allowed
        seen = np.isfinite(observed if frames is None else observed[frames]).all(axis=-1).any(axis=0)  # as used
        shown = {n for n, s in zip(wanted, seen) if s}
        dropped = [n for n in wanted if n not in shown]
        if len(dropped) == len(marker_layout.names):
            raise HandcapError(f"{path}: shows none of layout {marker_layout.name}'s markers")
        marker_layout = marker_layout.subset(shown)
    hand = hand_model_from_options(hand_model, mano_dir, side=marker_layout.side, recorded=None, what="the input")
    options = {"betas": betas, "frames": frames, "fit_shape": fit_shape, "estimate_offset": estimate_offset}
    total = len(marker_layout.names) + len(dropped)
    misfit = []
    if drop_misfit_mm is None:
        result = calibrate_attachment(markers, marker_layout, hand, **options)
    else:
        result, left_out, first = calibrate_without_misfits(markers, marker_layout, hand, limit_mm=drop_misfit_mm,
                                                            **options)
        if left_out:
            misfit = [f"{len(left_out)} markers fit the hand worse than {drop_misfit_mm:g} mm and are left out of the "
                      f"attachment ({', '.join(left_out[:4])}{' ...' if len(left_out) > 4 else ''}); calibration MRE "
                      f"{1000 * first:.2f} mm with them, {1000 * result.mre:.2f} mm without"]
    attachment, warnings = result.attachment, result.warnings
    misfit = disagree + misfit
    if misfit:
        attachment = q.attach(attachment, misfit)
        warnings = (*warnings, *misfit)
    if dropped:
        note = (f"{len(dropped)} of the layout's {total} markers were never seen in the calibration take"
                + ("'s frames used" if frames is not None else "")
                + f" ({', '.join(dropped[:3])}...): they are left out of the attachment")
        attachment = q.attach(attachment, [note])
        warnings = (*warnings, note)
    attachment.save(out)
    return Step((f"{out}: {result.summary()}",), warnings, (str(out),), result)


def solve(path, attachment, out, *, method: str = "lm", filter_cutoff: float | None = None, filter_order: int = 2,
          units: str | None = None, hand_model: str | None = None, mano_dir=None, keep_swaps: bool = False) -> Step:
    """Solve the hand motion of a labeled take with a calibrated attachment (see :func:`handcap.solve.solve_hand`).

    Parameters
    ----------
    path, attachment, out : str or Path
        Labeled markers, the attachment .npz of :func:`calibrate_markers`, the hand motion .npz to write.
    method : {'lm', 'adam'}
        The solver.
    filter_cutoff : float or None
        Low-pass the motion at this frequency, Hz.
    filter_order : int
        Butterworth order.
    units : {'mm', 'cm', 'm'} or None
        Unit of the input's coordinates, overriding what the file says.
    hand_model, mano_dir : str or None
        The hand model (default: the one the attachment was made with).
    keep_swaps : bool
        Solve labels the hand finds swapped as they are (default: exchanged, with a warning).
    """
    check_not_input(out, path, attachment)
    attached = MarkerAttachment.load(attachment)
    markers = read_markers(path, units=units, hand=attached.marker_names)
    hand = hand_model_from_options(hand_model, mano_dir, side=attached.side, recorded=attached.model,
                                   what=str(attachment))
    start = time.perf_counter()
    motion = solve_hand(markers, attached, hand, method=method, filter_cutoff=filter_cutoff, filter_order=filter_order,
                        mend_swaps=not keep_swaps)
    seconds = time.perf_counter() - start
    motion = motion.with_warnings(*markers.warnings)  # e.g. the unit of the input guessed: kept with the result
    write_hand_motion(motion, out)
    residuals = motion.marker_residuals
    line = (f"{out}: {motion.n_frames} frames in {seconds:.1f} s ({motion.n_frames / seconds:.0f} frames/s, "
            f"{method}), MRE {1000 * np.nanmean(residuals):.2f} ± {1000 * np.nanstd(residuals):.2f} mm"
            + (f", low-passed at {filter_cutoff:g} Hz" if filter_cutoff else ""))
    return Step((line,), motion.warnings, (str(out),), motion)


def shape(out, *, scan=None, lengths: dict | None = None, side: str = "right", hand_model: str | None = None,
          mano_dir=None) -> Step:
    """Estimate the 10 shape values from a scan or from measured lengths, and write them with their warnings.

    Parameters
    ----------
    out : str or Path
        .npz to write (``betas (10,)``).
    scan : str, Path or None
        Scan of an open hand: a mesh (.ply .obj .stl ...) or .npz with points, metres.
    lengths : dict of str to float, or None
        Measured lengths in metres, by the names of :data:`handcap.solve.MEASUREMENTS`.
    side : {'right', 'left'}
    hand_model, mano_dir : str or None
        The hand model (default openhand).
    """
    hand = hand_model_from_options(hand_model, mano_dir, side=side, recorded=None, what="the input")
    if (scan is None) == (lengths is None):
        raise HandcapError("give either --scan or --lengths")
    check_output(out, scan)
    if scan:
        betas, chamfer = betas_from_scan(hand, read_scan_points(scan))
        note = f"Chamfer distance {1000 * chamfer:.2f} mm"
    else:
        betas = betas_from_measurements(hand, **lengths)
        note = "from " + ", ".join(lengths)
    warnings = tuple(q.shape_warnings(betas))
    save_npz(out, {"betas": betas, **warnings_entry(warnings)})
    m = hand_measurements(hand, betas)
    line = (f"{out}: betas {np.round(betas, 2).tolist()} ({note}); hand length {1000 * m['hand_length']:.1f} mm, "
            f"breadth {1000 * m['hand_breadth']:.1f} mm; " + (f"{len(warnings)} warning(s), see below" if warnings
                                                               else "no warnings"))
    return Step((line,), warnings, (str(out),), betas)
