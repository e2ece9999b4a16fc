"""Plausibility checks: the figures of a result turned into one-line warnings (issue 14).

handcap never gives a silent wrong answer. Every stage that writes a result runs the checks below on it;
each check is a pure function that returns a list of one-line warnings (empty when the result looks
plausible). A warning names the figure, its value and the plausible range, so a user can judge it without
reading the code, e.g. ``"solve: MRE 13.1 mm is above 5 mm (plausible: <= 5 mm); ..."``.

The caller decides what to do with them: library code issues them with :func:`handcap.core.errors.warn`
and stores them on its result (:func:`attach` does both for the containers); the command line prints them
and, with ``handcap --strict``, exits with code 2.

The checks live in :mod:`~handcap.quality.fit_checks` (fits, labels), :mod:`~handcap.quality.motion_checks`
(jerk, bones, size, speed) and :mod:`~handcap.quality.stage_checks` (each stage's result, summaries); this
module names them all. Every limit is a constant of :mod:`~handcap.quality.limits` with the reason for its
value; none is fitted to one file (the table of them is there).
"""

from handcap.quality.fit_checks import (FRAME_MARKERS, labeling_warnings, limit_warnings, lost_frame_warnings,
                                        residual_warnings, shape_warnings)
from handcap.quality.limits import (BONE_RATIO, CAPTURE_SPREAD, HAND_LENGTH_RANGE, HAND_SPREAD, MAX_SPEED, MIN_LABELED,
                                    MRE_LIMIT, PITCH_TOLERANCE, REPROJECTION_PX, SHAPE_BOUND, SPIKE_JUMP, SPIKE_STRAY,
                                    SPIKE_Z)
from handcap.quality.motion_checks import (BONE_NAMES, anthropometric_bone_lengths, bone_lengths, bone_warnings,
                                           jerk_spikes, jerk_warnings, size_warnings, speed_warnings, speeds,
                                           spike_events, spread)
from handcap.quality.stage_checks import (attach, camera_warnings, clean_warnings, marker_figures, marker_warnings,
                                          motion_figures, motion_warnings, object_warnings, pitch_check,
                                          summary, triangulation_warnings)

__all__ = ["anthropometric_bone_lengths", "attach", "bone_lengths", "BONE_NAMES", "BONE_RATIO", "bone_warnings",
           "camera_warnings", "CAPTURE_SPREAD", "clean_warnings", "HAND_LENGTH_RANGE", "HAND_SPREAD", "jerk_spikes",
           "jerk_warnings", "labeling_warnings", "limit_warnings", "marker_figures", "marker_warnings", "MAX_SPEED",
           "MIN_LABELED", "FRAME_MARKERS", "lost_frame_warnings", "motion_figures", "motion_warnings", "MRE_LIMIT",
           "object_warnings", "PITCH_TOLERANCE", "pitch_check", "REPROJECTION_PX", "residual_warnings", "SHAPE_BOUND",
           "shape_warnings", "size_warnings", "speed_warnings", "speeds", "spike_events", "SPIKE_JUMP", "SPIKE_STRAY",
           "SPIKE_Z", "spread", "summary", "triangulation_warnings"]
