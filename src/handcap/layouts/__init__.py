"""Marker layouts: which marker sits on which hand segment (TOML files).

Shipped layouts (``handcap.layouts.SHIPPED``):

``dense-patches``
    19 printed checkerboard patches on the rigid regions of the hand (one on
    the back of every phalanx, two on the dorsum, two on the palm), their inner
    corners as markers at 5 mm pitch: several hundred markers (DexterCap).
``glove-13``
    The Qualisys glove of ``../shared/data/markers/hand_embodiment_glove``:
    a rigid back-of-hand triad ``hand_top``, ``hand_left``, ``hand_right`` and a
    ``*_middle`` (proximal phalanx) and ``*_tip`` (nail) marker on each finger,
    named as in that recording (``little`` is the pinky).
``joints-19``
    A marker over every finger joint (MCP, PIP, DIP; thumb MCP, IP) and on
    every nail, 19 in all, plus a back-of-hand triad: the glove's two wrist-side
    markers and a third 2 cm short of the index and middle knuckles, clear of
    their markers (the glove's own third marker, on the knuckles between the
    middle and ring fingers, would touch ``ring_mcp``).
``tips-5``
    The five nail markers plus the back-of-hand triad.
``active-9``
    The PhaseSpace-style active glove of the real-time occlusion paper: three
    alignment markers (wrist, index base, pinky base), a marker on the back of
    the hand and the five fingertips.

A layout file follows the File contract of DESIGN.md::

    name = "glove-13"
    side = "right"
    marker_radius = 0.007       # metres from the skin to the marker centre
    marker_kind = "sphere"      # or "patch" (a printed corner, seen only from the front)
    rigid = ["hand_top", "hand_left", "hand_right"]
    [markers.hand_top]
    segment = "palm"
    position = [0.065, 0.02, 0.016]   # optional, on the flat template, metres

Positions are on the right hand of :class:`handcap.hand.OpenHand` at
``betas = 0`` in its flat pose; a left-hand layout mirrors them (z negated).
"""

from handcap.layouts.file import (MARKER_GAP, MARKER_KINDS, SHIPPED, LayoutMarker, MarkerLayout, load_layout,
                                  sides_named)
from handcap.layouts.template import SEGMENT_HELP, layout_template
from handcap.layouts.check import LayoutCheck, check_layout

__all__ = ["MARKER_GAP", "MARKER_KINDS", "SEGMENT_HELP", "SHIPPED", "LayoutCheck", "LayoutMarker", "MarkerLayout",
           "check_layout", "layout_template", "load_layout", "sides_named"]
