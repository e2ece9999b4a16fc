"""Calibrating without the markers that fit no bone (``calibrate-markers --drop-misfit``).

A layout made from a template (``handcap layout new --pattern``) holds every printed corner of a patch. A patch that
reaches over a joint has corners that move with two bones and fit neither: their calibration residual stays
millimetres above the rest, and they drag their segment's pose, so their neighbours fit worse too.
:func:`calibrate_without_misfits` calibrates, leaves out the worst of the markers whose mean residual exceeds a limit
(those over half the worst residual), and calibrates again, until none is over the limit or the rounds run out. On
the image demo's takes read through an imported template it left out 19 of 479 corners; the joints then lay 1.44 mm
from the truth instead of 2.00 mm (README, "Patches printed by another generator").
"""

from __future__ import annotations

import warnings

import numpy as np

from handcap.core.errors import HandcapError
from handcap.solve.calibration import Calibration, calibrate_attachment

#: Default limit, millimetres: a corner on a bone fits within the triangulation's noise (DexterCap reports a
#: calibration MRE of 0.77 mm); one over a joint moves by several millimetres as the joint bends.
LIMIT_MM = 3.0
#: Most rounds (each calibrates again without the worst misfits).
ROUNDS = 6


def calibrate_without_misfits(markers, layout, hand=None, *, limit_mm: float = LIMIT_MM, rounds: int = ROUNDS,
                              **options) -> tuple[Calibration, list, float]:
    """:func:`~handcap.solve.calibrate_attachment`, again without the markers that fit worse than ``limit_mm``.

    Parameters
    ----------
    markers : MarkerSequence
        The calibration take, metres.
    layout : MarkerLayout
    hand : HandModel, optional
    limit_mm : float
        Largest mean calibration residual of a marker kept, millimetres.
    rounds : int
        Most calibrations after the first.
    **options
        Passed to :func:`~handcap.solve.calibrate_attachment` (``betas``, ``frames``, ``fit_shape``, ...).

    Returns
    -------
    calibration : Calibration
        The last calibration; its warnings are given (the earlier rounds' are not: they named the misfits).
    left_out : list of str
        The markers left out, worst first.
    first_mre : float
        The first calibration's MRE, metres (with every marker).

    Raises
    ------
    HandcapError
        A limit that is no positive number of millimetres, or every marker over it.
    """
    if not 0 < limit_mm < 1000:
        raise HandcapError(f"--drop-misfit {limit_mm} mm: give a residual in millimetres, e.g. {LIMIT_MM:g}")
    result, said = _quietly(calibrate_attachment, markers, layout, hand, **options)
    first, left_out = result.mre, []
    for _ in range(rounds):
        misfit = _misfits(result, limit_mm)
        if not misfit:
            break
        left_out += misfit
        layout = layout.subset(set(layout.names) - set(misfit))
        result, said = _quietly(calibrate_attachment, markers, layout, hand, **options)
    for w in said:
        warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
    return result, left_out, first


def _quietly(fn, *args, **kwargs):
    """``fn(*args, **kwargs)`` and the warnings it gave, held back (to be given where they still hold)."""
    with warnings.catch_warnings(record=True) as said:
        warnings.simplefilter("always")
        out = fn(*args, **kwargs)
    return out, list(said)


def _misfits(result: Calibration, limit_mm: float) -> list:
    """The markers to leave out in one round: of those whose mean residual exceeds ``limit_mm``, the ones over
    half the worst residual (its neighbours may fit again once the worst is gone); an error if every marker is over
    the limit."""
    with np.errstate(invalid="ignore"):
        per_marker = np.nan_to_num(np.nanmean(result.residuals, axis=0) * 1000)
    over = per_marker > limit_mm
    if over.all():
        raise HandcapError(f"every marker fits the hand worse than {limit_mm:g} mm (calibration MRE "
                           f"{1000 * result.mre:.1f} mm); check the labels and the layout's segments")
    worst = per_marker.max(initial=0.0)
    return [n for n, r, o in zip(result.attachment.marker_names, per_marker, over) if o and r > 0.5 * worst]
