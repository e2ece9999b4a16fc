"""Plausibility of fits and labels: residuals, limits reached, shape values, labelled share, frames too few markers
fix (issue 14)."""

from __future__ import annotations


import numpy as np

from handcap.quality.limits import MIN_LABELED, MM, MRE_LIMIT, SHAPE_BOUND, default_names, listed


# -- fits: residuals, limits, shape -----------------------------------------------------------------


def residual_warnings(residuals, *, names=None, what: str = "MRE", limit: float = MRE_LIMIT) -> list[str]:
    """Mean marker error of a fit, overall and per marker, against ``limit``.

    Parameters
    ----------
    residuals : ndarray of shape (T, M)
        Distance between fitted and observed markers, metres; NaN where unobserved.
    names : sequence of str, optional
        The M marker names (for the per-marker warning).
    what : str
        Names the figure in the message, e.g. ``"solve MRE"`` or ``"calibration MRE"``.
    limit : float
        Metres (default :data:`MRE_LIMIT`).

    Returns
    -------
    list of str
        One warning when the mean over every observed sample exceeds ``limit``, and one naming the
        markers whose own mean exceeds it (at most one line each).
    """
    residuals = np.asarray(residuals, dtype=np.float64)
    if residuals.ndim == 1:
        residuals = residuals[None]
    seen = np.isfinite(residuals)
    if not seen.any():
        return []
    out = []
    mre = float(residuals[seen].mean())
    if mre > limit:
        out.append(f"{what} {MM * mre:.2f} mm is above {MM * limit:g} mm (plausible: <= {MM * limit:g} mm); "
                   f"check the labels, the layout's segments and the attachment")
    counts = seen.sum(axis=0)
    per_marker = np.where(counts > 0, np.where(seen, residuals, 0.0).sum(axis=0) / np.maximum(counts, 1), 0.0)
    bad = np.flatnonzero(per_marker > limit)
    if len(bad) and len(bad) < residuals.shape[1]:
        labels = default_names(names, residuals.shape[1])
        out.append(f"{what} of {len(bad)} marker(s) above {MM * limit:g} mm: "
                   f"{listed([labels[i] for i in bad], per_marker[bad])}")
    return out


def limit_warnings(values, limit: float, *, names=None, what: str = "shift from the layout position",
                   advice: str = "its layout position or segment may be wrong", scale: float = MM,
                   unit: str = "mm", tolerance: float = 1e-3) -> list[str]:
    """Markers whose value ended at the limit a fit allows it (it wanted to go further).

    For example the distance each calibrated marker moved from its layout position, against the cap
    ``handcap.solve.calibration.MAX_SHIFT``: a marker held at the cap did not find its place.

    Parameters
    ----------
    values : ndarray of shape (M,)
        The figure per marker (metres by default), NaN where undefined.
    limit : float
        The largest value the fit allows.
    names : sequence of str, optional
    what, advice : str
        Name the figure and say what to check, in the message.
    scale, unit : float, str
        How to print values (default millimetres).
    tolerance : float
        Relative: values within ``limit * (1 - tolerance)`` of the limit count as at it.

    Returns
    -------
    list of str
        At most one line, naming the markers at the limit.
    """
    values = np.abs(np.asarray(values, dtype=np.float64).ravel())
    stuck = np.flatnonzero(np.isfinite(values) & (values >= abs(limit) * (1 - tolerance)))
    if not len(stuck):
        return []
    labels = default_names(names, len(values))
    return [f"{len(stuck)} marker(s) at the limit of their {what} ({scale * limit:g} {unit}): "
            f"{listed([labels[i] for i in stuck], values[stuck], unit, scale)}; {advice}"]


def shape_warnings(betas, *, bound: float = SHAPE_BOUND) -> list[str]:
    """Shape values at or beyond ``bound`` standard deviations of adult hands.

    Parameters
    ----------
    betas : ndarray of shape (10,)
    bound : float
        Default :data:`SHAPE_BOUND` (the shape fit's bound).

    Returns
    -------
    list of str
        At most one line naming the values; the shape fit pushed against its bound (the model cannot
        take the hand's proportions), or a hand given outside the adult range.
    """
    betas = np.asarray(betas, dtype=np.float64).ravel()
    if not np.isfinite(betas).all():
        return [f"shape values (betas) are not finite: {np.round(betas, 2).tolist()}"]
    at = np.flatnonzero(np.abs(betas) >= bound * (1 - 1e-3))
    if not len(at):
        return []
    listed = ", ".join(f"betas[{i}] = {betas[i]:.2f}" for i in at)
    return [f"shape value(s) at or beyond +-{bound:g} standard deviations of adult hands: {listed} (plausible: "
            f"|betas| < {bound:g}); a fit that ends there could not take the hand's proportions (check the labels "
            f"and the layout)"]


# -- labels ---------------------------------------------------------------------------------------


def labeling_warnings(points, labeled, *, n_labels: int | None = None, lost_frames=(),
                      min_fraction: float = MIN_LABELED) -> list[str]:
    """Labels given to too few of the visible points, and frames where the hand frame was lost.

    Parameters
    ----------
    points : int or ndarray of shape (T,)
        Visible (unlabeled) points, in total or per frame.
    labeled : int or ndarray of shape (T,)
        Points that received a label, in total or per frame.
    n_labels : int, optional
        Labels the layout has (M). A frame can have at most M labelled points, so with per-frame counts the
        fraction is ``sum labeled / sum min(points, M)``: ghosts beyond M do not count as missed labels.
    lost_frames : sequence of int
        Frames in which the labeler could not find the hand frame (e.g. ``LabelingResult.lost_frames``).
    min_fraction : float
        Default :data:`MIN_LABELED`.

    Returns
    -------
    list of str
    """
    if n_labels is not None:
        points = np.minimum(points, int(n_labels))
    n_points = float(np.sum(points))
    n_labeled = float(np.sum(labeled))
    n_frames = int(np.size(points)) if np.ndim(points) else 0
    out = []
    if n_points > 0 and n_labeled / n_points < min_fraction:
        out.append(f"labels for {100 * n_labeled / n_points:.1f} % of the visible points (plausible: >= "
                   f"{100 * min_fraction:g} %); the take may differ from the training take (marker placement, "
                   f"layout)")
    lost = np.asarray(list(lost_frames), dtype=int)
    if len(lost):
        of = f" of {n_frames}" if n_frames else ""
        out.append(f"hand frame lost in {len(lost)}{of} frames (first: {lost.min()}); the rigid markers did not "
                   f"match the training take there")
    return out


#: Markers a frame needs to fix the hand's place and turn (:func:`lost_frame_warnings`).
FRAME_MARKERS = 3


def lost_frame_warnings(seen: np.ndarray) -> list[str]:
    """A warning where the hand frame is lost: frames with fewer than :data:`FRAME_MARKERS` markers seen.

    There the solve holds the pose of the frames beside it (the first seen frame's, before any) and moves it only
    as far as the few markers pull: the hand's place and turn are not measured.

    Parameters
    ----------
    seen : ndarray (T,) int
        Markers seen in each frame.

    Returns
    -------
    list of str
        Empty where every frame shows enough.
    """
    lost = np.flatnonzero(np.asarray(seen) < FRAME_MARKERS)
    if not len(lost):
        return []
    none = int((np.asarray(seen)[lost] == 0).sum())
    return [f"the hand frame is lost in {len(lost)} of {len(seen)} frames (fewer than {FRAME_MARKERS} markers seen, "
            f"{none} of them with none; the first at frame {lost[0]}): their pose is held from the frames beside "
            f"them, not measured"]
