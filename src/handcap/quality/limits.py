"""The limits of the plausibility checks (:mod:`handcap.quality.plausibility`), each with its reason.

Every limit is a module constant with the reason for its value; none is fitted to one file:

==================  =====================================================================================
``MRE_LIMIT``       5 mm: a marker fit worse than a marker's own radius means the model, the attachment
                    or the labels are wrong (issue 14; DexterCap and the real glove reach 1-3 mm).
``SHAPE_BOUND``     3: shape values are in standard deviations of adult hands (OpenHand); 3 is the bound
                    of the shape fit of ``calibrate_attachment`` and the edge of 99.7 % of adults.
``MIN_LABELED``     95 % of the visible points labelled (issue 14).
``SPIKE_Z``         10 robust standard deviations above the take's median jerk, and ``SPIKE_JUMP``
``SPIKE_JUMP``      5 mm: the one-frame jump a spike implies (a third difference of 3 x 5 mm).
``SPIKE_STRAY``     3: a spike is a change of course (an impact), not a jump, when the velocities in it stray
                    no further than 3 times the change from the old and new velocities; real hands bouncing
                    off a wheelchair's rim stray up to 1.1 times, jumps of a point 30-90 times (a margin
                    between the two, not a fit to either).
``HAND_SPREAD``     0.03-0.35 m: the extent of the markers of one hand (a fist to a spread adult hand).
``MAX_SPEED``       10 m/s: faster than a hand moves (the fastest throws reach ~10 m/s at the wrist).
``HAND_LENGTH_RANGE`` average adult hand length +- 5 standard deviations (SD 5.2 %, Pheasant & Haslegrave
                    2006, as in :mod:`handcap.hand.anthropometry`): 135-230 mm.
``BONE_RATIO``      1.5: a bone longer or shorter than its anthropometric proportion by more than this
                    factor; OpenHand's shape space with every value at +-3 SD reaches 1.50.
``REPROJECTION_PX`` camera calibration RMS above 1 px (a well-detected board gives 0.1-0.5 px).
``PITCH_TOLERANCE`` 15 %: the coded patches' measured square side (median) against their printed pitch. Skin
                    and tape bend and stretch (synth's patches on its hands of every size and pose: 108.7 % on
                    a grasp take; a 5 mm square round a finger 8 mm in radius: 98.4 %); past 15 % the rig's
                    scale is off (a calibration board's square size given wrong, the units of its
                    translations). A page printed "to fit" (94-97 %) shows only in the printed figure.
==================  =====================================================================================
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np



#: Largest plausible mean marker error (solve, calibration), metres.
MRE_LIMIT = 0.005
#: Shape values (standard deviations of adult hands) at or beyond this are reported.
SHAPE_BOUND = 3.0
#: Smallest plausible fraction of visible points that get a label.
MIN_LABELED = 0.95
#: A jerk spike: this many robust standard deviations above the take's median jerk ...
SPIKE_Z = 10.0
#: ... and a one-frame jump of at least this many metres (its third difference is 3 x the jump).
SPIKE_JUMP = 0.005
#: A jerk spike changes course, not jumps, when its velocities stray from the old and new ones by at most this
#: many times the change (:func:`handcap.quality.motion_checks.spike_events`).
SPIKE_STRAY = 3.0
#: Plausible extent (bounding-box diagonal) of the markers of one hand, metres.
HAND_SPREAD = (0.03, 0.35)
#: Plausible extent of all markers of a capture, metres (no capture volume is larger; a hand is not smaller).
CAPTURE_SPREAD = (0.01, 30.0)
#: Fastest plausible marker speed, metres per second.
MAX_SPEED = 10.0
#: Plausible adult hand length, metres: 182.5 mm +- 5 SD of 5.2 % (Pheasant & Haslegrave 2006).
HAND_LENGTH_RANGE = (0.1825 * (1 - 5 * 0.052), 0.1825 * (1 + 5 * 0.052))
#: Largest plausible factor between a bone's length and its anthropometric proportion of the hand.
BONE_RATIO = 1.5
#: Largest plausible reprojection RMS of a camera calibration, pixels.
REPROJECTION_PX = 1.0
#: Largest plausible departure of the coded patches' measured square side from their printed pitch (a share).
PITCH_TOLERANCE = 0.15

MM = 1000.0  # millimetres per metre, for messages


def listed(names: Sequence[str], values, unit: str = "mm", scale: float = MM, most: int = 4) -> str:
    """``a (6.1 mm), b (5.5 mm) and 3 more``: the worst ``most`` entries first.

    Parameters
    ----------
    names : sequence of str (N,)
        One per value.
    values : sequence of float (N,)
        In the caller's unit (metres by default); the largest are the worst.
    unit : str
        Unit printed after each value.
    scale : float
        Factor from the values' unit to ``unit`` (default millimetres per metre).
    most : int
        Entries shown.

    Returns
    -------
    str
        One line, values with one decimal.
    """
    order = np.argsort(-np.asarray(values, dtype=np.float64), kind="stable")
    shown = [f"{names[i]} ({scale * values[i]:.1f} {unit})" for i in order[:most]]
    rest = len(order) - len(shown)
    return ", ".join(shown) + (f" and {rest} more" if rest > 0 else "")


def default_names(names, count: int, prefix: str = "marker") -> list[str]:
    """``names`` as a list when there are ``count`` of them, else ``"<prefix> 0"``, ``"<prefix> 1"``, ...

    Parameters
    ----------
    names : sequence of str or None
    count : int
        Number of names needed.
    prefix : str
        Stem of the made-up names.

    Returns
    -------
    list of str
        ``count`` names.
    """
    names = list(names) if names is not None else []
    return names if len(names) == count else [f"{prefix} {i}" for i in range(count)]
