"""Cleaning of triangulated 3D marker trajectories (DexterCap section 3.3): ``handcap clean``.

    cleaned, report = clean_markers(markers, "dense-patches")

Triangulated markers carry two kinds of wrong samples, and gaps. DexterCap
removes the wrong samples with two heuristics and fills short gaps; each step
here is a pure function of positions ``(T, M, 3)`` (metres, NaN = missing)
that returns new positions and a ``(T, M)`` mask of the samples it removed or
filled, and :func:`clean_markers` runs them in this order:

1. :func:`remove_cluster_outliers`. A mislabelled corner is triangulated
   where the corner it was mistaken for lies, usually far from its patch-mates.
   In every frame the markers of one group (a printed patch, or a hand segment
   when the layout has no patches) keep the largest cluster of points that
   all lie within ``radius`` of each other; the rest are removed. The radius
   comes from the layout's template (see :func:`layout_groups`).
2. :func:`remove_window_outliers`. Spikes: in a sliding window every sample is
   compared with a local quadratic fitted to its neighbours (itself left out),
   and removed when it deviates by more than ``z`` robust standard deviations
   (1.4826 x the median absolute residual of the samples within two window
   lengths) and by more than ``floor`` metres.
3. Gap filling, each method with its own longest gap (frames), applied in
   turn to what is still missing: :func:`fill_rigid` (the rigid motion of the
   marker's patch, from patch-mates seen both in the gap frame and next to
   the gap), :func:`fill_linear` (short gaps; DexterCap fills one or two
   frames) and :func:`fill_spline` (a cubic spline in time). The rigid fill
   goes first because it is the most accurate where it applies: on synthetic
   patches with 0.5 mm noise its error stays at the noise level whatever the
   gap's length, while interpolation in time grows with the gap and with the
   speed of the hand. Only interior gaps are filled: nothing is extrapolated
   past the first or last sample of a marker, and a gap longer than a method's
   maximum is left to the next method or stays missing.

The groups and step 1 live in :mod:`~handcap.multiview.clean_groups`, step 2 in
:mod:`~handcap.multiview.clean_spikes` and step 3 in :mod:`~handcap.multiview.clean_gaps`; this module
holds :func:`clean_markers`, its :class:`CleanReport`, and names them all.

References
----------
Liang Y, Xu S, Zhang Y, Zhan B, Zhang H, Liu L. DexterCap: affordable and
automated capture of complex hand-object interactions (``papers/`` in the
shared folder), section 3.3.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from handcap.core.checks import check_frames, check_odd_window, check_positive
from handcap.core.errors import HandcapError
from handcap.core.markers import MarkerSequence
from handcap.multiview.clean_gaps import (MAX_LINEAR, MAX_LINEAR_S, MAX_RIGID, MAX_SPLINE, MAX_SPLINE_S,
                                          RIGID_MIN_SPREAD, RIGID_TOLERANCE, fill_linear, fill_rigid, fill_spline,
                                          gap_frames)
from handcap.multiview.clean_groups import (PATCH_MARGIN, PATCH_SCALE, SEGMENT_MARGIN, SEGMENT_SCALE, MarkerGroups,
                                            layout_groups, remove_cluster_outliers)
from handcap.multiview.clean_spikes import FLOOR, MAD_TO_STD, WINDOW, Z, remove_window_outliers


@dataclass(frozen=True, eq=False)
class CleanReport:
    """What :func:`clean_markers` removed and filled, as ``(T, M)`` boolean masks.

    Attributes
    ----------
    cluster_removed : samples away from the largest cluster of their group (step 1).
    outlier_removed : spikes found by the sliding window (step 2).
    rigid_filled, linear_filled, spline_filled : samples filled by each method (step 3).
    missing : samples missing in the result.
    groups : MarkerGroups or None
        The groups used in steps 1 and 3 (None without a layout).
    limits : tuple of 3 int
        The longest gaps, frames, the rigid, linear and spline fills were allowed (0: not used).
    """

    cluster_removed: np.ndarray
    outlier_removed: np.ndarray
    rigid_filled: np.ndarray
    linear_filled: np.ndarray
    spline_filled: np.ndarray
    missing: np.ndarray
    groups: MarkerGroups | None = None
    limits: tuple = ()

    def summary(self) -> str:
        """One line: samples removed and filled by each step (and the longest gaps each could fill), and those
        left missing."""
        n = self.counts()
        gaps = (" (gaps of up to {} / {} / {} frames)".format(*self.limits) if len(self.limits) == 3 else "")
        return (f"removed {n['cluster_removed']} samples away from their patch and {n['outlier_removed']} spikes; "
                f"filled {n['rigid_filled']} rigid, {n['linear_filled']} linear, {n['spline_filled']} spline{gaps}; "
                f"{n['missing']} of {self.missing.size} samples missing")

    def counts(self) -> dict:
        """Sample counts of every mask."""
        keys = ("cluster_removed", "outlier_removed", "rigid_filled", "linear_filled", "spline_filled", "missing")
        return {key: int(getattr(self, key).sum()) for key in keys}


def clean_markers(markers: MarkerSequence, layout=None, *, radius: float | None = None, window: int = WINDOW,
                  z: float = Z, floor: float = FLOOR, max_linear_frames: int | None = None,
                  max_rigid_frames: int = MAX_RIGID, max_spline_frames: int | None = None,
                  rigid_tolerance: float = RIGID_TOLERANCE) -> tuple[MarkerSequence, CleanReport]:
    """Remove wrong samples and fill gaps of triangulated markers (DexterCap section 3.3).

    Runs :func:`remove_cluster_outliers` (only with a layout), then
    :func:`remove_window_outliers`, :func:`fill_rigid` (only with a layout),
    :func:`fill_linear` and :func:`fill_spline`, each on the result of the
    one before.

    Parameters
    ----------
    markers : MarkerSequence
        Metres, NaN where missing.
    layout : MarkerLayout or str, optional
        Gives the patches (or segments) for clustering and the rigid fill.
    radius : float, optional
        Cluster radius in metres for every group (default: from the layout).
    window, z, floor
        See :func:`remove_window_outliers` (frames, robust standard deviations, metres).
    max_linear_frames, max_rigid_frames, max_spline_frames : int
        Longest gap, frames, each method fills (0: the method is not used). Linear and spline by default
        :data:`MAX_LINEAR_S` and :data:`MAX_SPLINE_S` of the take's frames (2 and 10 at 100 Hz, none at 4 Hz).
    rigid_tolerance : float
        Metres, see :func:`fill_rigid`.

    Returns
    -------
    cleaned : MarkerSequence
        Same names and rate; the residuals (if any) are NaN where removed or filled.
    report : CleanReport

    Raises
    ------
    HandcapError
        Unknown layout, bad window, threshold or gap length.
    """
    positions = markers.positions
    if max_linear_frames is None:
        max_linear_frames = gap_frames(MAX_LINEAR_S, markers.rate)
    if max_spline_frames is None:
        max_spline_frames = gap_frames(MAX_SPLINE_S, markers.rate)
    # Check every option before any work, also those of steps a missing layout skips.
    for value, what in ((max_linear_frames, "max_linear_frames"), (max_rigid_frames, "max_rigid_frames"),
                        (max_spline_frames, "max_spline_frames")):
        check_frames(value, what)
    check_odd_window(window)
    check_positive(z, "z (robust standard deviations)")
    check_positive(rigid_tolerance, "rigid tolerance (metres)")
    if radius is not None:
        check_positive(radius, "cluster radius (metres)")
    if not (np.isfinite(floor) and floor >= 0):
        raise HandcapError(f"floor must be a non-negative distance in metres, got {floor}")
    groups = None if layout is None else layout_groups(markers.names, layout, radius=radius, positions=positions)
    nothing = np.zeros(positions.shape[:2], bool)
    clustered = nothing
    if groups is not None:
        positions, clustered = remove_cluster_outliers(positions, groups)
    positions, spikes = remove_window_outliers(positions, window=window, z=z, floor=floor)
    rigid = nothing
    if groups is not None:
        positions, rigid = fill_rigid(positions, groups, max_gap_frames=max_rigid_frames, tolerance=rigid_tolerance)
    positions, linear = fill_linear(positions, max_gap_frames=max_linear_frames)
    positions, spline = fill_spline(positions, max_gap_frames=max_spline_frames)
    residuals = None
    if markers.residuals is not None:
        residuals = markers.residuals.copy()
        residuals[linear | rigid | spline] = np.nan
    cleaned = MarkerSequence(positions, markers.names, markers.rate, residuals)
    report = CleanReport(cluster_removed=clustered, outlier_removed=spikes, rigid_filled=rigid, linear_filled=linear,
                         spline_filled=spline, missing=cleaned.missing, groups=groups,
                         limits=(max_rigid_frames, max_linear_frames, max_spline_frames))
    return cleaned, report


__all__ = ["CleanReport", "MarkerGroups", "clean_markers", "fill_linear", "fill_rigid", "fill_spline",
           "layout_groups", "remove_cluster_outliers", "remove_window_outliers"]
__all__ += ["FLOOR", "MAD_TO_STD", "MAX_LINEAR", "MAX_LINEAR_S", "MAX_RIGID", "MAX_SPLINE", "MAX_SPLINE_S",
            "PATCH_MARGIN", "PATCH_SCALE",
            "RIGID_MIN_SPREAD", "RIGID_TOLERANCE", "SEGMENT_MARGIN", "SEGMENT_SCALE", "WINDOW", "Z"]
