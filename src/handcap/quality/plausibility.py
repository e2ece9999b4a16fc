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
value; none is fitted to one file:

==================  =====================================================================================
``MRE_LIMIT``       5 mm: a marker fit worse than a marker's own radius means the model, the attachment
                    or the labels are wrong (issue 14; DexterCap and the real glove reach 1-3 mm).
``SHAPE_BOUND``     3: shape values are in standard deviations of adult hands (OpenHand); 3 is the bound
                    of the shape fit of ``calibrate_attachment`` and the edge of 99.7 % of adults.
``MIN_LABELED``     95 % of the visible points labelled (issue 14).
``SPIKE_Z``         10 robust standard deviations above the take's median jerk, and ``SPIKE_JUMP``
``SPIKE_JUMP``      5 mm: the one-frame jump a spike implies (a third difference of 3 x 5 mm).
``HAND_SPREAD``     0.03-0.35 m: the extent of the markers of one hand (a fist to a spread adult hand).
``MAX_SPEED``       10 m/s: faster than a hand moves (the fastest throws reach ~10 m/s at the wrist).
``HAND_LENGTH_RANGE`` average adult hand length +- 5 standard deviations (SD 5.2 %, Pheasant & Haslegrave
                    2006, as in :mod:`handcap.hand.anthropometry`): 135-230 mm.
``BONE_RATIO``      1.5: a bone longer or shorter than its anthropometric proportion by more than this
                    factor; OpenHand's shape space with every value at +-3 SD reaches 1.50.
``REPROJECTION_PX`` camera calibration RMS above 1 px (a well-detected board gives 0.1-0.5 px).
==================  =====================================================================================
"""

from handcap.quality.fit_checks import (labeling_warnings, limit_warnings, residual_warnings, shape_warnings)
from handcap.quality.limits import (BONE_RATIO, CAPTURE_SPREAD, HAND_LENGTH_RANGE, HAND_SPREAD, MAX_SPEED, MIN_LABELED,
                                    MRE_LIMIT, REPROJECTION_PX, SHAPE_BOUND, SPIKE_JUMP, SPIKE_Z)
from handcap.quality.motion_checks import (BONE_NAMES, anthropometric_bone_lengths, bone_lengths, bone_warnings,
                                           jerk_spikes, jerk_warnings, size_warnings, speed_warnings, speeds, spread)
from handcap.quality.stage_checks import (attach, camera_warnings, clean_warnings, marker_figures, marker_warnings,
                                          motion_figures, motion_warnings, object_warnings, summary,
                                          triangulation_warnings)

__all__ = ["anthropometric_bone_lengths", "attach", "bone_lengths", "BONE_NAMES", "BONE_RATIO", "bone_warnings",
           "camera_warnings", "CAPTURE_SPREAD", "clean_warnings", "HAND_LENGTH_RANGE", "HAND_SPREAD", "jerk_spikes",
           "jerk_warnings", "labeling_warnings", "limit_warnings", "marker_figures", "marker_warnings", "MAX_SPEED",
           "MIN_LABELED", "motion_figures", "motion_warnings", "MRE_LIMIT", "object_warnings", "REPROJECTION_PX",
           "residual_warnings", "SHAPE_BOUND", "shape_warnings", "size_warnings", "speed_warnings", "speeds",
           "SPIKE_JUMP", "SPIKE_Z", "spread", "summary", "triangulation_warnings"]
