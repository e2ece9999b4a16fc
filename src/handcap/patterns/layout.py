"""The marker layout of a template's hand patches: every corner, on the segment its patch is stuck on.

handcap's own hand patches have the shipped ``dense-patches`` layout, with every corner's spot on the template hand.
Patches printed otherwise (another generator's, imported with ``handcap pattern --import``; patches cut to other
sizes) have a template but no layout. :func:`pattern_layout` writes one from the template: each corner of a patch of
the hand is a marker named as the template names it (without the owner, as layouts name markers), on the segment the
user gives for that patch (or the one the template records), with no position. ``calibrate-markers`` then places
every corner from a calibration take, as it places any marker a layout gives no position. On a synthetic
calibration take and grasp (dense patches, 395 corners) that gave a solve MRE of 0.55 mm and joints 1.75 mm from
the truth, against 0.54 mm and 1.35 mm with ``dense-patches`` and its positions (README, "Patches printed by another
generator").
"""

from __future__ import annotations

import difflib
from fnmatch import fnmatchcase

from handcap.core.errors import HandcapError
from handcap.hand.anatomy import SEGMENT_NAMES
from handcap.layouts.file import LayoutMarker, MarkerLayout
from handcap.patterns.pattern import Pattern

#: Distance from the skin to a printed corner, metres: paper on tape (as the ``dense-patches`` layout).
PATCH_RADIUS = 0.0005


def segment_rule(spec: str) -> tuple[str, str]:
    """``PATCHES=SEGMENT`` as ``(glob, segment)``, the segment checked against the hand's.

    Parameters
    ----------
    spec : str
        A shell pattern of patch names and a hand segment, e.g. ``thumb_1=thumb_distal`` or ``palm*=palm``.

    Returns
    -------
    (str, str)
    """
    glob, sep, segment = str(spec).partition("=")
    glob, segment = glob.strip(), segment.strip()
    if not sep or not glob or not segment:
        raise HandcapError(f"--segment {spec!r}: give PATCHES=SEGMENT, e.g. 'thumb_1=thumb_distal' (a shell pattern "
                           "of patch names, then the hand segment they are stuck on)")
    if segment not in SEGMENT_NAMES:
        close = difflib.get_close_matches(segment, SEGMENT_NAMES, n=1)
        raise HandcapError(f"--segment {spec!r}: no hand segment {segment!r}"
                           + (f" (did you mean {close[0]!r}?)" if close else "")
                           + f"; the segments are {', '.join(SEGMENT_NAMES)}")
    return glob, segment


def pattern_layout(pattern: Pattern, side: str | None = None, segments=(), name: str = "patches") -> MarkerLayout:
    """A layout of every corner of the hand patches of ``pattern``, without positions.

    Parameters
    ----------
    pattern : Pattern
    side : {'right', 'left'}, optional
        The hand (owner) whose patches to take; by default the one hand the template holds.
    segments : sequence of str or (str, str)
        ``PATCHES=SEGMENT`` rules (:func:`segment_rule`); the first that matches a patch's name wins. A patch no
        rule matches keeps the segment the template records for it, where that is a hand segment (handcap's own
        patches); otherwise it is an error that names it.
    name : str
        The layout's name.

    Returns
    -------
    MarkerLayout
        Markers ``PATCH_rRcC`` in the template's order, ``marker_kind`` ``"patch"``, no rigid set.
    """
    hands = [o for o in pattern.owners if o in ("right", "left")]
    if side is None and len(hands) == 2:
        raise HandcapError("the template holds patches of both hands: give --side right or --side left")
    side = side or (hands[0] if hands else "right")
    if side not in hands:
        raise HandcapError(f"the template has no patch of the {side} hand (its owners: {', '.join(pattern.owners)}); "
                           "handcap pattern --import --owner 'PATCHES=right' gives patches to a hand")
    rules = [segment_rule(r) if isinstance(r, str) else tuple(r) for r in segments]
    markers, unplaced = [], []
    for patch in pattern.of_owner(side):
        segment = next((s for glob, s in rules if fnmatchcase(patch.name, glob)), patch.segment)
        if segment not in SEGMENT_NAMES:
            unplaced.append(patch.name)
            continue
        markers += [LayoutMarker(n, segment, None, patch.name) for n in patch.corner_names(owner=False)]
    if unplaced:
        raise HandcapError(f"{len(unplaced)} patches of the {side} hand have no segment: "
                           f"{', '.join(unplaced[:6])}{' ...' if len(unplaced) > 6 else ''}; give each with --segment "
                           f"'PATCHES=SEGMENT' (segments: {', '.join(SEGMENT_NAMES)})")
    unused = [glob for glob, _ in rules if not any(fnmatchcase(p.name, glob) for p in pattern.of_owner(side))]
    if unused:
        raise HandcapError(f"--segment {unused[0]!r} matches no patch of the {side} hand (patches: "
                           f"{', '.join(p.name for p in pattern.of_owner(side)[:6])} ...)")
    return MarkerLayout(name, side, tuple(markers), (), PATCH_RADIUS, "patch",
                        f"every corner of the {side} hand's patches of a template, placed by calibrate-markers")
