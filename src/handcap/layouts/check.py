"""Check a marker layout against the template hand and a take (``handcap layout check``).

A user's own layout can be wrong in ways that every command accepts and that
give silently wrong results later: a name that differs from the capture's
labels, a position on the wrong finger or in millimetres, a rigid set of two
markers, or in a line. :func:`check_layout` looks at each in turn:

* names: which layout markers the take has (a ``Subject:`` prefix in the
  take is ignored, as everywhere in handcap), which it lacks (with the take's
  closest name), which take trajectories no layout marker claims, and layout
  names that match several prefixed trajectories;
* segments: how many markers each segment carries (unknown segment names are
  refused when the layout is loaded);
* positions: each given position against the surface of its own segment on
  the template hand (OpenHand, ``betas = 0``, flat pose, the layout's side);
  positions are skin spots, so a plausible one lies within
  :data:`MAX_SEGMENT_DISTANCE` of its segment (hand sizes differ by about
  10 %, which moves a fingertip by up to 2 cm from the template's);
* the rigid set: 3 or more markers of one segment, not in a line, and in the
  take as far apart as the layout says, once scaled to the subject's hand
  (:data:`HAND_SCALE`, within :data:`RIGID_TOLERANCE`);
* what will be estimated: hand markers without a position, placed by
  ``calibrate-markers`` from the take.

Problems that make the layout unusable raise :class:`HandcapError` (one line);
the others are warnings (:func:`handcap.core.errors.warn`) kept on the result.
"""

from __future__ import annotations

import difflib
from dataclasses import dataclass, field

import numpy as np

from handcap.core.errors import HandcapError, warn
from handcap.core.geometry import closest_points_on_mesh
from handcap.core.markers import MarkerSequence
from handcap.hand import OpenHand
from handcap.hand.anatomy import SEGMENT_NAMES
from handcap.layouts.file import MARKER_GAP, MarkerLayout

#: Farthest a given position may lie from the skin of its own segment on the template, metres.
MAX_SEGMENT_DISTANCE = 0.02
#: Rigid markers closer than this to the line through them do not fix a rotation about it, metres.
MIN_RIGID_SPREAD = 0.005
#: Allowed difference between a rigid pair's distance in the take and on the template, once the
#: template is scaled to the subject (the median ratio of the pairs): relative and absolute parts
#: (marker placement), metres.
RIGID_TOLERANCE = (0.10, 0.005)
#: Plausible size of a subject's hand against the template (adult hand lengths span about +-20 %).
HAND_SCALE = (0.75, 1.33)
#: A rigid marker this near another marker of the back of the hand makes a look-alike of the rigid set, metres:
#: the triangle with the other marker in its place has nearly the set's own distances (another subject's, or
#: another day's placement, can fit it better), and the labeler may take it for the hand frame.
LOOK_ALIKE = 0.012
#: Positions farther than this from the template's wrist are not metres on a hand.
_NOT_A_HAND = 1.0


@dataclass(frozen=True)
class LayoutCheck:
    """What :func:`check_layout` found.

    Attributes
    ----------
    layout : MarkerLayout
    take : str or None
        The take's description (its file name), if one was given.
    matched : dict of str to str
        Layout name -> the take's trajectory name.
    missing : tuple of str
        Layout markers the take lacks.
    extra : tuple of str
        Take trajectories that no layout marker claims.
    ambiguous : dict of str to tuple of str
        Layout name -> the several prefixed trajectories it matches.
    never_seen : tuple of str
        Matched markers with no sample in the take.
    estimated : tuple of str
        Hand markers without a position (``calibrate-markers`` estimates them).
    distance : dict of str to float
        Given position -> distance to the skin of its segment on the template, metres.
    rigid_spread : float or None
        Largest distance of a rigid marker from the line through the others (template, or take), metres.
    warnings : tuple of str
    """

    layout: MarkerLayout
    take: str | None
    matched: dict
    missing: tuple
    extra: tuple
    ambiguous: dict
    never_seen: tuple
    estimated: tuple
    distance: dict
    rigid_spread: float | None
    rigid_distances: list = field(default_factory=list)
    warnings: tuple = ()

    def summary(self) -> str:
        """A one-screen report, one topic per line."""
        layout = self.layout
        lines = [f"layout    : {layout.name}, {len(layout)} markers, {layout.side} hand, {layout.marker_kind} "
                 f"markers {1000 * layout.marker_radius:.1f} mm off the skin"]
        if self.take is not None:
            text = f"names     : {len(self.matched)} of {len(layout)} found in {self.take}"
            prefixes = sorted({t.rsplit(':', 1)[0] + ':' for t in self.matched.values() if ':' in t})
            if prefixes:
                text += f" (prefix {', '.join(prefixes)} ignored)"
            if self.missing:
                text += f"; missing: {_listed(self.missing)}"
            if self.ambiguous:
                text += f"; ambiguous: {_listed(self.ambiguous)}"
            if self.extra:
                text += f"; in the take only: {_listed(self.extra)}"
            lines.append(text)
        counts = {}
        for m in layout.markers:
            counts[m.segment] = counts.get(m.segment, 0) + 1
        empty = [s for s in SEGMENT_NAMES if s not in counts]
        lines.append("segments  : " + ", ".join(f"{s} {n}" for s, n in counts.items())
                     + (f"; no marker on {_listed(empty)} (held by the pose priors)" if empty else ""))
        if self.distance:
            worst = max(self.distance, key=self.distance.get)
            median = 1000 * np.median(list(self.distance.values()))
            text = (f"positions : {len(self.distance)} given, median {median:.1f} mm from their segment's skin on the "
                    f"template hand, farthest {worst} {1000 * self.distance[worst]:.1f} mm")
        else:
            text = "positions : none given"
        if self.estimated:
            text += f"; estimated from the take by calibrate-markers: {_listed(self.estimated)}"
        lines.append(text)
        if layout.rigid:
            text = f"rigid set : {', '.join(layout.rigid)}"
            if self.rigid_spread is not None:
                text += f", {1000 * self.rigid_spread:.1f} mm off a line"
            if self.rigid_distances:
                text += "; apart in the take / layout: " + ", ".join(
                    f"{a}-{b} {1000 * t:.1f}/{1000 * p:.1f} mm" for a, b, t, p in self.rigid_distances)
            lines.append(text)
        else:
            lines.append("rigid set : none")
        lines.append(f"verdict   : usable, {len(self.warnings)} warning(s)" if self.warnings else "verdict   : usable")
        return "\n".join(lines)


def check_layout(layout: MarkerLayout, markers: MarkerSequence | None = None, *, take: str | None = None,
                 hand=None) -> LayoutCheck:
    """Check a layout's names, segments, positions and rigid set, against a take if given.

    Parameters
    ----------
    layout : MarkerLayout
    markers : MarkerSequence, optional
        A labeled take recorded with this marker set, metres.
    take : str, optional
        How to name the take in the report (its file name).
    hand : HandModel, optional
        The template the positions are written for: OpenHand of the layout's side by default.

    Returns
    -------
    LayoutCheck
        With one-line warnings (also issued as :class:`~handcap.core.errors.HandcapWarning`).

    Raises
    ------
    HandcapError
        When the layout is unusable: none of its names is in the take, or its
        positions are not metres on a hand.
    """
    if not isinstance(layout, MarkerLayout):
        raise HandcapError(f"need a MarkerLayout, got {type(layout).__name__}")
    if hand is None:
        hand = OpenHand(layout.side)
    layout_for_hand = layout.for_side(hand.side)
    messages = []

    matched, missing, extra, ambiguous, never_seen = {}, (), (), {}, ()
    if markers is not None:
        matched, missing, extra, ambiguous = match_names(layout.names, markers.names)
        where = take or "the take"
        if not matched and ambiguous:
            prefixes = sorted({t.rsplit(":", 1)[0] for hits in ambiguous.values() for t in hits})
            raise HandcapError(f"every layout name matches markers of several subjects in {where} "
                               f"({', '.join(prefixes)}); write the prefixed names in the layout "
                               f"(e.g. {prefixes[0]}:{next(iter(ambiguous))}), one layout per subject")
        if not matched:
            raise HandcapError(f"none of the layout's {len(layout)} names ({_listed(layout.names, 4)}) is in {where}, "
                               f"whose markers are {_listed(markers.names, 6)}; rename the layout's markers "
                               "after the take's labels")
        if missing:
            hints = []
            for name in missing:
                close = difflib.get_close_matches(name, [n.rsplit(":", 1)[-1] for n in extra], n=1, cutoff=0.5)
                hints.append(f"{name} (the take has {close[0]!r})" if close else name)
            messages.append(warn(f"{len(missing)} layout marker(s) not in {where}: {_listed(hints)}; "
                                 "calibrate-markers needs every hand marker of the layout: rename or remove them"))
        if ambiguous:
            messages.append(warn(f"layout names matching several prefixed markers of {where}: "
                                 + "; ".join(f"{k} -> {', '.join(v)}" for k, v in ambiguous.items())
                                 + "; give the prefixed name in the layout or keep one subject in the take"))
        seen = ~np.isnan(markers.positions[..., 0])
        never_seen = tuple(n for n, t in matched.items() if not seen[:, markers.names.index(t)].any())
        if never_seen:
            messages.append(warn(f"markers in {where} with no sample at all: {_listed(never_seen)}"))

    hand_markers = layout_for_hand.hand_markers
    estimated = tuple(m.name for m in hand_markers if m.position is None)
    distance, far = _segment_distances(layout_for_hand, hand)
    messages += far + _crowded(layout_for_hand)

    rigid_spread, rigid_distances = None, []
    messages += _check_rigid(layout_for_hand, markers, matched, take or "the take")
    spread_points = _rigid_points(layout_for_hand, markers, matched)
    if spread_points is not None:
        rigid_spread = _line_spread(spread_points)
        if rigid_spread < MIN_RIGID_SPREAD:
            messages.append(warn(f"rigid markers {', '.join(layout.rigid)} lie within {1000 * rigid_spread:.1f} mm "
                                 "of one line: they cannot fix the hand's rotation about it; add a marker off "
                                 "that line to rigid"))
    if markers is not None:
        rigid_distances, wrong = _rigid_distances(layout_for_hand, markers, matched)
        messages += wrong

    return LayoutCheck(layout, take, matched, tuple(missing), tuple(extra), ambiguous, never_seen, estimated,
                       distance, rigid_spread, rigid_distances, tuple(messages))


def match_names(layout_names, take_names) -> tuple[dict, tuple, tuple, dict]:
    """Match layout names to a take's names; a ``Subject:`` prefix in the take is ignored.

    Parameters
    ----------
    layout_names, take_names : sequence of str

    Returns
    -------
    matched : dict of str to str
        Layout name -> take name (an exact name first, else the one name whose
        unprefixed part equals it).
    missing : tuple of str
    extra : tuple of str
        Take names no layout name claims, in the take's order.
    ambiguous : dict of str to tuple of str
        Layout names whose unprefixed match is not unique.
    """
    take_names = [str(n) for n in take_names]
    short = [n.rsplit(":", 1)[-1] for n in take_names]
    matched, missing, ambiguous = {}, [], {}
    for name in layout_names:
        if name in take_names:
            matched[name] = name
            continue
        hits = [t for t, s in zip(take_names, short) if s == name]
        if len(hits) == 1:
            matched[name] = hits[0]
        elif hits:
            ambiguous[name] = tuple(hits)
        else:
            missing.append(name)
    claimed = set(matched.values()) | {t for hits in ambiguous.values() for t in hits}
    extra = tuple(t for t in take_names if t not in claimed)
    return matched, tuple(missing), extra, ambiguous


def _segment_distances(layout: MarkerLayout, hand) -> tuple[dict, list]:
    """Distance of each given position to its segment's skin on the template, and warnings."""
    given = [m for m in layout.hand_markers if m.position is not None]
    if not given:
        return {}, []
    points = np.array([m.position for m in given])
    template = hand.forward().vertices
    if np.median(np.linalg.norm(points, axis=1)) > _NOT_A_HAND:
        scale = np.median(np.linalg.norm(points, axis=1))
        hint = " (they look like millimetres: divide by 1000)" if 20 < scale < 1000 else ""
        raise HandcapError(f"layout {layout.name!r}: positions lie {scale:.3g} m from the wrist on average; "
                           f"positions are metres on the template hand{hint}")
    faces = hand.faces
    _, face_any, _ = closest_points_on_mesh(points, template, faces, candidates=64)
    face_segment = hand.segment_of_vertex[faces[:, 0]]
    distance, messages = {}, []
    for segment in sorted({m.segment for m in given}):
        idx = [i for i, m in enumerate(given) if m.segment == segment]
        own = hand.segment_faces(segment)
        closest, _, _ = closest_points_on_mesh(points[idx], template, faces[own], candidates=64)
        for i, point in zip(idx, closest):
            distance[given[i].name] = float(np.linalg.norm(points[i] - point))
    far = [(m, distance[m.name]) for m in given if distance[m.name] > MAX_SEGMENT_DISTANCE]
    if far:
        described = []
        for m, d in far:
            nearest = hand.segment_names[face_segment[face_any[given.index(m)]]]
            described.append(f"{m.name} {1000 * d:.0f} mm from {m.segment}"
                             + (f" (nearest segment: {nearest})" if nearest != m.segment else ""))
        messages.append(warn(f"positions farther than {1000 * MAX_SEGMENT_DISTANCE:.0f} mm from their segment on the "
                             f"template hand: {'; '.join(described)}; correct the segment or the position, or "
                             "remove the position to have it estimated from a calibration take"))
    return distance, messages


def _crowded(layout: MarkerLayout) -> list:
    """Warnings for sphere markers whose given positions touch (:data:`MARKER_GAP`), and for a marker rigid with
    the back of the hand so near a rigid marker that their triangles look alike (:data:`LOOK_ALIKE`)."""
    given = [m for m in layout.hand_markers if m.position is not None]
    if layout.marker_kind == "patch" or len(given) < 2:
        return []
    points = np.array([m.position for m in given])
    dist = np.linalg.norm(points[:, None] - points[None], axis=-1)
    touch = 2 * layout.marker_radius + MARKER_GAP
    pairs, alike = [], []
    for i, j in zip(*np.triu_indices(len(given), 1)):
        a, b = given[i], given[j]
        if dist[i, j] < touch:
            pairs.append(f"{a.name}-{b.name} {1000 * dist[i, j]:.1f} mm")
        elif (dist[i, j] < LOOK_ALIKE and (a.name in layout.rigid) != (b.name in layout.rigid)
              and a.segment == b.segment):
            alike.append(f"{a.name}-{b.name} {1000 * dist[i, j]:.1f} mm")
    messages = []
    if pairs:
        messages.append(warn(f"markers closer than their {1000 * touch:.0f} mm spheres allow (centre to centre): "
                             f"{_listed(pairs)}; they would touch and merge into one blob in the cameras: move "
                             "one of each pair"))
    if alike:
        messages.append(warn(f"rigid markers within {1000 * LOOK_ALIKE:.0f} mm of another marker of their segment: "
                             f"{_listed(alike)}; the triangle with the other marker looks like the rigid set's own, "
                             "and another subject's placement can make the labeler take it for the hand frame: "
                             "keep the rigid set clear of the knuckle markers"))
    return messages


def _check_rigid(layout: MarkerLayout, markers, matched, where) -> list:
    rigid = layout.rigid
    by_name = {m.name: m for m in layout.markers}
    if not rigid:
        if layout.marker_kind == "patch":
            return []  # coded patches carry their labels; no hand frame is searched for
        return [warn("no rigid set: handcap label cannot find the hand frame; list 3 or more markers of the back "
                     "of the hand (segment palm) in rigid")]
    messages = []
    segments = sorted({by_name[r].segment for r in rigid})
    if len(segments) > 1:
        messages.append(warn(f"rigid markers sit on several segments ({', '.join(segments)}): they move against each "
                             "other; keep markers of one segment (palm) in rigid"))
    if len(rigid) < 3:
        others = [m.name for m in layout.markers if m.segment == segments[0] and m.name not in rigid]
        wrist = [n for n in others if "wrist" in n.lower()]
        suggestion = (f"add {(wrist or others)[0]!r} (segment {segments[0]}) to rigid" if others else
                      "add a third marker on the back of the hand or at the wrist (segment palm) and list it in rigid")
        messages.append(warn(f"rigid set has {len(rigid)} marker(s) ({', '.join(rigid)}); the hand frame needs 3: "
                             + suggestion))
    if markers is not None:
        absent = [r for r in rigid if r not in matched]
        if absent:
            messages.append(warn(f"rigid markers not in {where}: {', '.join(absent)}; the hand frame cannot be found"))
    return messages


def _rigid_points(layout: MarkerLayout, markers, matched) -> np.ndarray | None:
    """Positions (R, 3) of the rigid set: the template's, else the take's median frame; None if unknown."""
    if len(layout.rigid) < 3:
        return None
    by_name = {m.name: m for m in layout.markers}
    if all(by_name[r].position is not None for r in layout.rigid):
        return np.array([by_name[r].position for r in layout.rigid])
    if markers is None or not all(r in matched for r in layout.rigid):
        return None
    points = markers.positions[:, [markers.names.index(matched[r]) for r in layout.rigid]]
    complete = ~np.isnan(points[..., 0]).any(axis=1)
    if not complete.any():
        return None
    spreads = np.array([_line_spread(p) for p in points[complete][:: max(1, complete.sum() // 200)]])
    return points[complete][:: max(1, complete.sum() // 200)][int(np.argsort(spreads)[len(spreads) // 2])]


def _line_spread(points: np.ndarray) -> float:
    """Largest distance of the points (R, 3) from their best-fitting line, metres."""
    centred = points - points.mean(axis=0)
    direction = np.linalg.svd(centred, full_matrices=False)[2][0]
    off = centred - np.outer(centred @ direction, direction)
    return float(np.linalg.norm(off, axis=1).max())


def _rigid_distances(layout: MarkerLayout, markers: MarkerSequence, matched) -> tuple[list, list]:
    """Median pairwise distances of the rigid markers in the take against the template's."""
    by_name = {m.name: m for m in layout.markers}
    usable = [r for r in layout.rigid if r in matched and by_name[r].position is not None]
    rows = []
    for i, a in enumerate(usable):
        for b in usable[i + 1:]:
            pa = markers.positions[:, markers.names.index(matched[a])]
            pb = markers.positions[:, markers.names.index(matched[b])]
            d = np.linalg.norm(pa - pb, axis=1)
            if np.isnan(d).all():
                continue
            rows.append((a, b, float(np.nanmedian(d)), float(np.linalg.norm(by_name[a].position
                                                                            - by_name[b].position))))
    if not rows:
        return rows, []
    # One scale for the subject's hand (the median over pairs, so one wrong pair cannot set it), then each pair.
    scale = float(np.median([measured / max(nominal, 1e-9) for _, _, measured, nominal in rows]))
    if not HAND_SCALE[0] <= scale <= HAND_SCALE[1]:
        return rows, [warn(f"rigid markers are {scale:.2f} times as far apart in the take as in the layout (a hand "
                           f"is {HAND_SCALE[0]}-{HAND_SCALE[1]} times the template): check the take's units and the "
                           "layout's positions")]
    relative, absolute = RIGID_TOLERANCE
    wrong = [f"{a}-{b} {1000 * measured:.1f} mm in the take, {1000 * nominal:.1f} mm in the layout"
             for a, b, measured, nominal in rows
             if abs(measured - scale * nominal) > relative * scale * nominal + absolute]
    if wrong:
        return rows, [warn(f"rigid markers apart by other distances than their layout positions (scaled by "
                           f"{scale:.2f} to the subject): {'; '.join(wrong)}; check the names (swapped?) and the "
                           "positions, or remove the positions")]
    return rows, []


def _listed(names, limit: int = 8) -> str:
    names = list(names)
    return ", ".join(map(str, names[:limit])) + (f" and {len(names) - limit} more" if len(names) > limit else "")


__all__ = ["HAND_SCALE", "MAX_SEGMENT_DISTANCE", "MIN_RIGID_SPREAD", "RIGID_TOLERANCE", "LayoutCheck", "check_layout",
           "match_names"]
