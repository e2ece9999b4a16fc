"""Leave-one-marker-out error of a take: an accuracy figure for real data, which has no ground truth.

It re-solves the take once per marker, so it sits in ``solve`` (above
:mod:`handcap.quality.metrics`, whose :class:`~handcap.quality.metrics.Stat`
it returns).
"""

from __future__ import annotations

import numpy as np

from handcap.quality.metrics import Stat
from handcap.solve.motion import observed_markers, solve_hand


def leave_one_marker_out(markers, attachment, hand=None, *, names=None, frames=None, **solve_options) -> dict:
    """Leave-one-marker-out error: a real-data accuracy figure that needs no ground truth.

    For every marker i (of ``names``, default all attached markers): solve the
    take without marker i, then compare where the fitted hand puts marker i
    with where it was observed. Reported per marker as the mean distance over
    the frames where it was observed (metres). This measures how well the
    model and the other markers predict a marker they did not see.

    Parameters
    ----------
    markers : MarkerSequence
    attachment : MarkerAttachment
    hand : HandModel, optional
    names : sequence of str, optional
    frames : slice, optional
        Frames of ``markers`` to use (e.g. ``slice(0, None, 4)``).
    solve_options
        Passed to :func:`handcap.solve.solve_hand`.

    Returns
    -------
    dict name -> Stat
    """
    if frames is not None:
        markers = markers[frames] if isinstance(frames, slice) else markers.frames(*frames)
    names = list(attachment.marker_names if names is None else names)
    observed, _ = observed_markers(markers, list(attachment.marker_names))
    out = {}
    for name in names:
        i = attachment.marker_names.index(name)
        keep = [n for n in markers.names if markers.short_names[markers.names.index(n)] != name and n != name]
        motion = solve_hand(markers.select(keep), attachment, hand, **solve_options)
        out[name] = Stat.of(np.linalg.norm(motion.marker_fit[:, i] - observed[:, i], axis=-1))
    return out
