"""A commented layout file to start from (``handcap layout new --like NAME``).

A user with a marker set of their own copies the closest shipped layout and
edits it. :func:`layout_template` writes that copy as TOML with every field
explained in comments, so the file itself is the documentation: what the
names must match, the segment names, what the rigid set is for, and when a
position matters and when it is estimated from a take.
"""

from __future__ import annotations

from handcap.hand.anatomy import SEGMENT_NAMES
from handcap.layouts.file import LayoutMarker, MarkerLayout, toml_key, toml_value

#: One line on each segment, in the order of :data:`handcap.hand.anatomy.SEGMENT_NAMES`.
SEGMENT_HELP = {
    "palm": "back and palm of the hand from the wrist crease to the knuckles (metacarpals 2-5, MCP knuckles, "
            "wrist markers)",
    "thumb_proximal": "thumb metacarpal (between the wrist and the thumb's MCP joint)",
    "thumb_middle": "thumb proximal phalanx (between MCP and IP joints)",
    "thumb_distal": "thumb distal phalanx and nail",
}
for _finger in ("index", "middle", "ring", "pinky"):
    SEGMENT_HELP[f"{_finger}_proximal"] = f"{_finger} proximal phalanx (MCP to PIP joint)"
    SEGMENT_HELP[f"{_finger}_middle"] = f"{_finger} middle phalanx (PIP to DIP joint)"
    SEGMENT_HELP[f"{_finger}_distal"] = f"{_finger} distal phalanx and nail (DIP joint to the tip)"

_HEADER = """\
# handcap marker layout: which marker sits on which segment of the hand.
# Made by `handcap layout new {made}`; edit it for your marker set, then run
#   handcap layout check THIS.toml YOUR_TAKE.c3d
# which lists the names it finds in the take, the segments, the positions and the rigid set.
#
# name         : any label for this layout (reports print it).
# side         : "right" or "left": the hand the positions below are written for; the
#                commands mirror the layout onto the other hand when asked (--side).
# marker_radius: metres from the skin to the marker centre (a 10 mm sphere on a 2 mm base: 0.007).
# marker_kind  : "sphere" (seen from every side) or "patch" (a printed corner, seen from the front).
# rigid        : markers fixed to one rigid part of the hand (the back of the hand), used to find the
#                hand frame when labeling unlabeled points (handcap label). List 3 or more markers of
#                the palm segment that are not in a line; a hand with only 2 markers on its back
#                takes a wrist marker (segment "palm") as the third.
#
# [markers.NAME] : one table per marker. NAME is the label in your capture files; a prefix
#                  such as "Subject:" or "RHand:" in the files is ignored when matching.
#                  Quote names with other characters: [markers."R.Wrist"].
#   segment  = the segment the marker is stuck on (it moves with that bone):
{segments}
#              or "object:NAME" for a marker on a held object.
#   position = [x, y, z] optional, metres: the marker's skin spot on handcap's template hand
#              (OpenHand, average shape, flat open hand, {side} hand). Its frame: origin at the
#              wrist joint, x from the wrist towards the middle fingertip, y out of the back of the
#              hand, z across the hand ({z_side}).
#              Leave it out when you do not know it: handcap calibrate-markers then estimates
#              where the marker sits from a calibration take (open hand, slowly turned), and
#              solve and fill use that estimate. A position is needed by handcap synth (to make
#              synthetic takes with your layout, e.g. for train-occlusion), by clean (its cluster
#              radius) and as the starting point of calibrate-markers (given positions may move
#              by at most 2 cm there, so a wrong one does harm: better none than a guess).
#   patch    = optional name of the printed patch a corner belongs to (patch layouts).
"""


def layout_template(layout: MarkerLayout, *, like: str | None = None, positions: bool = True,
                    made: str | None = None) -> str:
    """The TOML text of ``layout`` with every field explained in comments.

    Parameters
    ----------
    layout : MarkerLayout
        The layout to copy (usually a shipped one).
    like : str, optional
        How the user named it (for the header); ``layout.name`` by default.
    positions : bool
        Keep the positions of the hand markers; without them every hand marker is
        estimated by ``calibrate-markers`` (for a marker set placed otherwise).
    made : str, optional
        The ``handcap layout new`` arguments that made it, for the header (default ``--like LIKE``).

    Returns
    -------
    str
        A layout file: :func:`handcap.layouts.load_layout` of it gives ``layout``
        back (without hand positions if ``positions`` is false).
    """
    if not positions:
        layout = MarkerLayout(layout.name, layout.side,
                              tuple(m if m.on_object else LayoutMarker(m.name, m.segment, None, m.patch)
                                    for m in layout.markers),
                              layout.rigid, layout.marker_radius, layout.marker_kind, layout.description)
    width = max(len(s) for s in SEGMENT_NAMES)
    segments = "\n".join(f"#                {s:{width}s}  {SEGMENT_HELP[s]}" for s in SEGMENT_NAMES)
    z_side = "towards the little finger; the thumb is at negative z" if layout.side == "right" else \
        "towards the little finger; the thumb is at positive z"
    lines = [_HEADER.format(made=made or f"--like {like or layout.name}", segments=segments, side=layout.side,
                            z_side=z_side)]
    table = layout.to_toml()
    markers = table.pop("markers")
    for key, value in table.items():
        lines.append(f"{key} = {toml_value(value)}")
    lines.append("")
    counts: dict[str, int] = {}
    for marker in layout.markers:
        counts[marker.segment] = counts.get(marker.segment, 0) + 1
    lines.append(f"# {len(layout)} markers: " + ", ".join(f"{n} on {s}" for s, n in counts.items()))
    for name, entry in markers.items():
        lines += ["", f"[markers.{toml_key(name)}]"]
        lines += [f"{key} = {toml_value(value)}" for key, value in entry.items()]
        if "position" not in entry:
            lines.append("# position: none, estimated by calibrate-markers")
    return "\n".join(lines) + "\n"


__all__ = ["SEGMENT_HELP", "layout_template"]
