"""The markers of each long finger in a layout, in order from the palm outward (:func:`finger_chains`).

A labeler that judges each marker by where it usually sits around the back of
the hand can hand a whole finger's markers to the neighbouring finger when
another subject's proportions differ from training
(:func:`handcap.labeling.fingers.untangle` sets them right). What it uses is
anatomy: the markers of one long finger (index to little) lie in the finger's
flexion plane, which stands across the back of the hand, and consecutive ones
keep their distance. The thumb (:func:`thumb_chain`) is not in a line seen
from the back: its flexion plane lies oblique to the palm.
"""

from __future__ import annotations

import numpy as np

from handcap.hand import OpenHand
from handcap.hand.anatomy import SEGMENT_NAMES
from handcap.layouts.file import MarkerLayout

#: Long fingers, from the thumb side.
FINGERS = ("index", "middle", "ring", "pinky")
#: A palm marker this near a finger's MCP joint on the template (metres; the joint lies 10-15 mm under the
#: skin of the knuckle), and nearer it than any other finger's, starts that finger's chain.
MCP_REACH = 0.025


def finger_chains(layout: MarkerLayout, hand=None) -> tuple[tuple[str, ...], ...]:
    """The markers of each long finger, from the palm outward; fingers with fewer than 3 are left out.

    A finger's markers are those on its proximal, middle and distal segments
    (in that order; on one segment, by their distance from the MCP joint on
    the template hand when positions are given), after the palm marker over
    its knuckle: the non-rigid palm marker whose given position lies within
    :data:`MCP_REACH` of the finger's MCP joint on the template.

    Parameters
    ----------
    layout : MarkerLayout
    hand : HandModel, optional
        The template (OpenHand of the layout's side by default).

    Returns
    -------
    tuple of tuple of str
        One chain of 3 or more marker names per finger that has them; none for a layout of coded patches
        (their corners carry their labels).
    """
    if layout.marker_kind == "patch":
        return ()
    hand = OpenHand(layout.side) if hand is None else hand
    layout = layout.for_side(hand.side)
    joints = np.asarray(hand.forward().joints)
    knuckles = joints[[SEGMENT_NAMES.index(f"{finger}_proximal") for finger in FINGERS]]
    palm = [m for m in layout.hand_markers if m.segment == "palm" and m.name not in layout.rigid
            and m.position is not None]
    reach = (np.linalg.norm(np.array([m.position for m in palm])[:, None] - knuckles[None], axis=-1) if palm
             else np.zeros((0, len(FINGERS))))
    chains = []
    for f, finger in enumerate(FINGERS):
        mcp = knuckles[f]
        chain = []
        if len(palm):
            k = int(np.argmin(reach[:, f]))
            if reach[k, f] < MCP_REACH and np.argmin(reach[k]) == f:
                chain.append(palm[k].name)
        for part in ("proximal", "middle", "distal"):
            on = [m for m in layout.hand_markers if m.segment == f"{finger}_{part}"]
            on.sort(key=lambda m: 0.0 if m.position is None else float(np.linalg.norm(m.position - mcp)))
            chain += [m.name for m in on]
        if len(chain) >= 3:
            chains.append(tuple(chain))
    return tuple(chains)


def thumb_chain(layout: MarkerLayout) -> tuple[str, ...]:
    """The thumb's markers from its base outward (on ``thumb_proximal``, ``thumb_middle``, ``thumb_distal``).

    Parameters
    ----------
    layout : MarkerLayout

    Returns
    -------
    tuple of str
        Empty for a layout of coded patches or with fewer than 2 thumb markers.
    """
    if layout.marker_kind == "patch":
        return ()
    chain = tuple(m.name for part in ("proximal", "middle", "distal") for m in layout.hand_markers
                  if m.segment == f"thumb_{part}")
    return chain if len(chain) >= 2 else ()
