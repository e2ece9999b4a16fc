"""Plausibility of the result of each stage, the figures a summary shows, and attaching warnings to results
(issue 14)."""

from __future__ import annotations

from collections.abc import Iterable, Sequence

import numpy as np

from handcap.core.errors import merge_warnings, warn
from handcap.core.grid import MIN_SIDES, grid_sides
from handcap.hand.anthropometry import HAND_LENGTH as AVERAGE_HAND_LENGTH
from handcap.quality.fit_checks import residual_warnings, shape_warnings
from handcap.quality.limits import CAPTURE_SPREAD, MM, PITCH_TOLERANCE, REPROJECTION_PX, default_names, listed
from handcap.quality.motion_checks import (anthropometric_bone_lengths, bone_lengths, bone_warnings, jerk_spikes,
                                           jerk_warnings, size_warnings, speed_warnings, speeds, spread)


# -- results of whole stages -----------------------------------------------------------------------------


def marker_warnings(markers, *, hand=None) -> list[str]:
    """Checks of a marker take: the capture's extent, one hand's extent, marker speeds.

    Parameters
    ----------
    markers : MarkerSequence
    hand : sequence of str, optional
        Names of the markers of one hand (a layout's ``names``); with them, their extent must be a hand's.

    Returns
    -------
    list of str
    """
    out = size_warnings(markers.positions, plausible=CAPTURE_SPREAD, what="all markers")
    if hand is not None:
        short = list(markers.short_names)
        wanted = {str(n).split(":")[-1] for n in hand}
        idx = [i for i, n in enumerate(short) if n in wanted]
        if len(idx) >= 3:
            out += size_warnings(markers.positions[:, idx], what="the hand's markers")
    if not out:  # wrong units already said; speeds would repeat it
        out += speed_warnings(markers.positions, markers.rate, names=markers.names)
    return out


def clean_warnings(report, missing_before, *, limit: float = 0.1) -> list[str]:
    """Cleaning that removed more than ``limit`` of the observed samples.

    Spikes and points away from their patch are the exception in a capture; when cleaning removes a tenth
    of what was observed, the layout, the cluster radius or the outlier threshold does not fit the take.

    Parameters
    ----------
    report : CleanReport
        From :func:`handcap.multiview.clean.clean_markers` (``cluster_removed``, ``outlier_removed``: (T, M)).
    missing_before : ndarray of shape (T, M) bool
        The input's missing samples.
    limit : float
        Largest plausible fraction removed.

    Returns
    -------
    list of str
    """
    observed = int((~np.asarray(missing_before, dtype=bool)).sum())
    removed = int(np.sum(report.cluster_removed) + np.sum(report.outlier_removed))
    if not observed or removed <= limit * observed:
        return []
    return [f"cleaning removed {100 * removed / observed:.1f} % of the observed samples (plausible: <= "
            f"{100 * limit:g} %); the layout, --radius-mm or --z may not fit this take"]


def motion_warnings(motion, *, what: str = "solve MRE") -> list[str]:
    """Checks of a :class:`~handcap.core.motion.HandMotion`: MRE, shape at bounds, bones, jerk spikes.

    Parameters
    ----------
    motion : HandMotion
    what : str
        Names the residual figure.

    Returns
    -------
    list of str
    """
    out = []
    if motion.marker_residuals is not None:
        out += residual_warnings(motion.marker_residuals, names=motion.marker_names, what=what)
    out += shape_warnings(motion.betas)
    if motion.joints is not None:
        out += bone_warnings(motion.joints)
        out += jerk_warnings(motion.joints, motion.rate, what="joint")
    return out


def object_warnings(track, *, threshold: float, rate: float | None = None) -> list[str]:
    """Checks of a rigid object's track (:class:`handcap.objects.rigid.RigidTrack`).

    The residual of a rigid fit is the markers' noise; crowding against the inlier distance (more than
    half of it on average) means the object is not rigid or its markers are mislabelled. Also: markers never
    seen (left out), frames left unsolved, and jerk spikes of the object's origin.

    Parameters
    ----------
    track : RigidTrack
    threshold : float
        The RANSAC inlier distance used, metres.
    rate : float, optional
        Hz; default the motion's.

    Returns
    -------
    list of str
    """
    out = []
    left_out = track.left_out
    if left_out:
        asked = len(left_out) + len(track.motion.marker_names)
        out.append(f"object {track.motion.name!r}: {len(left_out)} of its {asked} markers are never seen in the take "
                   f"and are left out of it ({', '.join(left_out[:3])}{' ...' if len(left_out) > 3 else ''})")
    residual = track.mean_residual
    if np.isfinite(residual) and residual > 0.5 * threshold:
        out.append(f"object {track.motion.name!r}: mean residual {MM * residual:.2f} mm is more than half the "
                   f"inlier distance {MM * threshold:g} mm (plausible: <= {MM * 0.5 * threshold:g} mm); is the "
                   f"object rigid and are its markers labelled right?")
    n = track.motion.n_frames
    if n and len(track.unsolved) > 0.05 * n:
        out.append(f"object {track.motion.name!r}: no pose in {len(track.unsolved)} of {n} frames "
                   f"({100 * len(track.unsolved) / n:.0f} %; plausible: < 5 %) with fewer than 3 markers")
    out += jerk_warnings(track.motion.translation[:, None], rate or track.motion.rate,
                         what=f"object {track.motion.name!r}")
    return out


def triangulation_warnings(error_px, views, *, threshold_px: float, used=None, min_fraction: float = 0.5,
                           seen=None, min_views: int | None = None) -> list[str]:
    """Checks of triangulated markers: reprojection error against the inlier threshold, rejected views,
    markers rarely reconstructed.

    Parameters
    ----------
    error_px : ndarray of shape (T, M)
        Mean reprojection error over the inlier views, pixels; NaN where no point.
    views : ndarray of shape (T, M)
        Inlier views (0 where no point).
    threshold_px : float
        The inlier threshold used, pixels.
    used : ndarray of shape (N,) bool, optional
        Per detection: kept as an inlier.
    min_fraction : float
        Fewest plausible fraction of frames in which a marker is reconstructed.
    seen : ndarray of shape (T, M) int, optional
        Cameras that detected each marker in each frame: where none was seen by ``min_views``, the warning for
        no marker triangulated says so instead of blaming the cameras file.
    min_views : int, optional
        The inlier views a marker needed.

    Returns
    -------
    list of str
    """
    error_px = np.asarray(error_px, dtype=np.float64)
    out = []
    found = np.isfinite(error_px)
    if not found.any():
        most = int(np.max(seen, initial=0)) if seen is not None else None
        if most is not None and min_views is not None and 0 < most < min_views:
            fewer = int(np.sum(np.asarray(seen) == most))
            return [f"no marker was triangulated in any frame: none was seen by {min_views} cameras in one frame "
                    f"(--min-views {min_views}); at most {most} saw one ({fewer} marker-frames). Give --min-views "
                    f"{most} (then no view can be outvoted as an outlier), or film with more cameras overlapping"]
        return ["no marker was triangulated in any frame; check that the cameras file matches the detections"]
    mean = float(error_px[found].mean())
    if mean > 0.5 * threshold_px:
        out.append(f"mean reprojection error {mean:.2f} px is more than half the inlier threshold "
                   f"{threshold_px:g} px (plausible: <= {0.5 * threshold_px:g} px); the camera calibration may "
                   f"be off (units, distortion) or belong to another session")
    if used is not None:
        used = np.asarray(used, dtype=bool)
        rejected = 1 - used.mean() if used.size else 0.0
        if rejected > 0.25:
            out.append(f"{100 * rejected:.0f} % of the detections were rejected, as outliers or as views of markers "
                       f"too few cameras saw (plausible: <= 25 %)")
    return out


def camera_warnings(rms, *, names=None, limit: float = REPROJECTION_PX) -> list[str]:
    """Cameras whose calibration reprojects the board worse than ``limit`` pixels (RMS).

    Parameters
    ----------
    rms : float or ndarray of shape (C,)
        Reprojection RMS per camera, pixels.
    names : sequence of str, optional
    limit : float
        Default :data:`REPROJECTION_PX`.

    Returns
    -------
    list of str
    """
    rms = np.atleast_1d(np.asarray(rms, dtype=np.float64))
    bad = np.flatnonzero(~(rms <= limit))
    if not len(bad):
        return []
    labels = default_names(names, len(rms), "camera")
    return [f"reprojection RMS above {limit:g} px (plausible: <= {limit:g} px) for "
            f"{listed([labels[i] for i in bad], np.nan_to_num(rms[bad], nan=np.inf), 'px', 1.0)}; "
            f"check the board's size and the detections"]


#: Least adjacent-corner distances (pairs times frames) to judge the pitch by.
MIN_PITCH_SAMPLES = MIN_SIDES


def pitch_check(markers, pitch: float | None) -> tuple[dict, list[str]]:
    """The square side of the coded patches measured in 3D, against the pitch they were printed at.

    Every pair of adjacent corners of a patch (markers ``NAME_r{r}c{c}`` and ``NAME_r{r}c{c+1}`` or
    ``NAME_r{r+1}c{c}``) lies one printed square apart: a ruler in every frame. The median side is a
    figure of every summary; off the pitch by more than :data:`PITCH_TOLERANCE` (skin and tape bend and
    stretch less) it is a warning: a rig whose scale is off (its translations' units, or a calibration
    board whose square size was given wrong) or patches printed at another scale, which the other
    checks see only when the scale is off many times over.

    Parameters
    ----------
    markers : MarkerSequence
    pitch : float or None
        Side of the printed squares, metres (None: nothing to check).

    Returns
    -------
    figures : dict
        ``patch square (mm)`` and ``of the printed pitch (%)``; empty when fewer than
        :data:`MIN_PITCH_SAMPLES` distances were measured.
    warnings : list of str
    """
    if pitch is None:
        return {}, []
    sides = grid_sides(markers.positions, markers.names)
    if len(sides) < MIN_PITCH_SAMPLES:
        return {}, []
    side = float(np.median(sides))
    ratio = side / pitch
    figures = {"patch square (mm)": round(1000 * side, 3), "of the printed pitch (%)": round(100 * ratio, 1)}
    if abs(ratio - 1) <= PITCH_TOLERANCE:
        return figures, []
    return figures, [f"the coded patches' squares measure {1000 * side:.2f} mm (median of {len(sides)} distances "
                     f"between adjacent corners), {100 * ratio:.1f} % of the {1000 * pitch:g} mm they were printed "
                     "at: patches printed at another scale (print at 100 % and check the 50 mm bar), or a rig "
                     "whose scale is off (the units of its translations, or the calibration board's square size)"]


# -- the figures the checks look at, for summaries ------------------------------------------------------


def marker_figures(markers, *, hand=None) -> dict:
    """The figures :func:`marker_warnings` judges, for a summary (label -> value).

    Parameters
    ----------
    markers : MarkerSequence
    hand : sequence of str, optional
        Names of one hand's markers.

    Returns
    -------
    dict
        ``missing (%)``, ``extent (m)`` (median bounding-box diagonal of all markers), ``hand extent (m)``
        (with ``hand``), ``speed p99 (m/s)`` (99th percentile over every sample).
    """
    positions = markers.positions
    out = {"missing (%)": round(100 * float(np.isnan(positions[..., 0]).mean()), 2) if positions.size else None}
    with np.errstate(all="ignore"):
        extent = spread(positions)
        out["extent (m)"] = float(np.nanmedian(extent)) if np.isfinite(extent).any() else None
        if hand is not None:
            wanted = {str(n).split(":")[-1] for n in hand}
            idx = [i for i, n in enumerate(markers.short_names) if n in wanted]
            if len(idx) >= 2:
                extent = spread(positions[:, idx])
                out["hand extent (m)"] = float(np.nanmedian(extent)) if np.isfinite(extent).any() else None
        v = speeds(positions, markers.rate)
        out["speed p99 (m/s)"] = float(np.percentile(v[np.isfinite(v)], 99)) if np.isfinite(v).any() else None
    return out


def motion_figures(motion) -> dict:
    """The figures :func:`motion_warnings` judges, for a summary (label -> value).

    Parameters
    ----------
    motion : HandMotion

    Returns
    -------
    dict
        ``MRE (mm)``, ``largest |betas|``, ``hand length (mm)`` (from the bones), ``jerk spike frames``.
    """
    out = {}
    if motion.marker_residuals is not None and np.isfinite(motion.marker_residuals).any():
        out["MRE (mm)"] = MM * float(np.nanmean(motion.marker_residuals))
    out["largest |betas|"] = float(np.abs(motion.betas).max())
    if motion.joints is not None and np.isfinite(motion.joints).any():
        with np.errstate(all="ignore"):
            measured = np.nanmedian(bone_lengths(motion.joints), axis=0)
        out["hand length (mm)"] = MM * AVERAGE_HAND_LENGTH * float(np.median(measured / anthropometric_bone_lengths()))
        out["jerk spike frames"] = int(len(jerk_spikes(motion.joints, motion.rate)))
    return out


# -- attaching and summarising ------------------------------------------------------------------------


def attach(result, warnings: Iterable[str], *, issue: bool = True):
    """``result`` with ``warnings`` stored on it, each also issued as a :class:`~handcap.core.errors.HandcapWarning`.

    Parameters
    ----------
    result : MarkerSequence, HandMotion, ObjectMotion or MarkerAttachment
        Anything with ``with_warnings``.
    warnings : iterable of str
    issue : bool
        Also issue each with :func:`handcap.core.errors.warn` (the command line prints them once).

    Returns
    -------
    The same kind of object, with the warnings appended (repeats dropped).
    """
    lines = merge_warnings(list(warnings))
    if issue:
        for line in lines:
            warn(line, stacklevel=2)  # points at the caller of attach
    return result.with_warnings(*lines) if lines else result


def summary(title: str, figures, warnings: Sequence[str] = ()) -> str:
    """A compact, one-screen summary of a result: a title, aligned figures and the count of warnings.

    Parameters
    ----------
    title : str
        First line, e.g. the output path and what it holds.
    figures : dict of str to object, or sequence of (str, object)
        Label -> value; floats print with 4 significant digits, other values as they are; None is skipped.
    warnings : sequence of str
        Only counted here (the command line prints them on stderr).

    Returns
    -------
    str
        At most ``2 + len(figures)`` lines.
    """
    items = list(figures.items()) if isinstance(figures, dict) else list(figures)
    items = [(str(k), v) for k, v in items if v is not None]
    width = max([len(k) for k, _ in items] + [0])
    lines = [title]
    for key, value in items:
        text = f"{value:.4g}" if isinstance(value, (float, np.floating)) else str(value)
        lines.append(f"  {key:<{width}}  {text}")
    n = len(merge_warnings(list(warnings)))
    lines.append(f"  {'quality':<{width}}  " + (f"{n} warning(s), see below" if n else "no warnings"))
    return "\n".join(lines)
