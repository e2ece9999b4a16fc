"""From labeled markers to hand motion: attachment calibration, shape, motion solve.

    attachment = calibrate_attachment(calibration_take, layout).attachment
    motion = solve_hand(markers, attachment)          # HandMotion, metres and radians
"""

from handcap.solve.calibration import Calibration, calibrate_attachment, offsets_measurable, shape_is_constrained
from handcap.solve.leave_one_out import leave_one_marker_out
from handcap.solve.lm import Priors
from handcap.solve.misfit import calibrate_without_misfits
from handcap.solve.motion import METHODS, MRE_WARNING, solve_hand
from handcap.solve.shape import MEASUREMENTS, betas_from_measurements, betas_from_scan, hand_measurements

__all__ = ["Calibration", "MEASUREMENTS", "METHODS", "MRE_WARNING", "Priors", "betas_from_measurements",
           "betas_from_scan", "calibrate_attachment", "calibrate_without_misfits", "hand_measurements",
           "leave_one_marker_out", "offsets_measurable", "shape_is_constrained", "solve_hand"]
