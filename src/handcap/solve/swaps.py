"""Label swaps found by the hand solved from them, and mended (issue 14: never a silent wrong answer).

A labelled take can swap two labels for a stretch of frames: a capture system's labeller (or ``handcap label``)
confuses two fingertips that pass close to each other, or a finger's two markers. The solve then bends the hand
to reach the swapped markers, and its mean residual hardly shows it: in a synthetic ``glove-13`` grasp whose ring
and little fingertip labels are swapped for 19 frames, the solved ring fingertip lies 40 mm from the truth while the
take's MRE is 0.54 mm.

:func:`find_swaps` looks where a marker lies further than :data:`~handcap.quality.limits.MRE_LIMIT` from the fitted
hand for a stretch of frames, pairs it with each marker also off the hand there and with the markers seen nearest to
it (the solve can follow one of two swapped markers to within the limit), and solves each such stretch again with
the two labels exchanged. Where the hand then fits both within that limit, and :data:`CLOSER` times closer than as
labelled, and the other markers as well as before, the labels are swapped there. The verdict is the hand's fit, not
how far the markers strayed: the real Qualisys glove's markers stray up to 16 mm from the fitted hand (the glove
slides on the skin), 77 times for 5 mm or more, and no swap is found in it.

Three labels can also go round a cycle (three fingertips together in a fist: each takes its neighbour's label);
exchanging two of them leaves one wrong, so no pair passes the verdict. Each cycle of a marker off the hand and
two of its partners (off the hand too, or seen nearest to it: the solve can follow one of the three) whose
positions lie near where the hand puts the next is tried too, ranked with the pairs (those with more markers off
the hand first, then those that come closer exchanged), with the same verdict.
"""

from __future__ import annotations

from dataclasses import dataclass
from itertools import permutations

import numpy as np

from handcap.quality.limits import MM, MRE_LIMIT

#: Frames solved on each side of a stretch, so that its first frames start from a settled pose; two stretches of a
#: pair this close are one.
CONTEXT = 5
#: A frame with more markers off the fitted hand than this, or whose median marker lies further than half the limit
#: from it, has lost its fit (or the attachment does not fit the hand): its pairs are not tried.
MAX_FAR = 6
#: With the labels exchanged, the hand must fit the pair this many times closer than as labelled (and within the
#: limit): the swaps synth made in the takes of ``benchmarks/swaps.py`` come 39-176 times closer; two markers that
#: both fit the hand about as well either way (a finger of two markers can bend to reach either) are no evidence of
#: a swap (the real glove's middle and ring fingertips, 1.2-1.4 times closer exchanged in a few stretches where both
#: lie 4-6 mm off).
CLOSER = 3.0
#: ... and the other markers no further from it on average than as labelled plus this, metres (two back-of-hand
#: markers exchanged in one frame of the real glove fitted within 1.6 mm, the hand turned, its other markers 60 mm
#: off).
OTHERS_WORSE = 0.0005
#: The stretches tried are solved again for at most this many times the take's frames (the likeliest first): the
#: search costs at most one solve more (the real glove: 0.15).
BUDGET = 1.0
#: Markers seen nearest to a marker off the hand that are tried as its partner (besides those off it too).
PARTNERS = 2
#: A pair's stretch is tried when, in its middle frame, each marker lies within this many times the larger of the
#: two residuals of where the fit puts the other (swaps the solve followed: 2.8 at most in synthetic takes). It
#: spares solves only; the verdict is the solve with the labels exchanged.
CANDIDATE_RATIO = 4.0


@dataclass(frozen=True)
class Swap:
    """Two labels swapped in frames ``first`` to ``last`` (inclusive), or three labels moved round a cycle (``c``
    not -1: marker ``a`` carries ``b``'s label there, ``b`` carries ``c``'s and ``c`` carries ``a``'s); residuals in
    metres (means over the stretch of its markers): as given, and with the labels exchanged."""

    a: int
    b: int
    first: int
    last: int
    given: float
    exchanged: float
    c: int = -1

    @property
    def markers(self) -> list[int]:
        """The markers whose labels are exchanged."""
        return exchange_columns(self.a, self.b, self.c)[0]

    @property
    def sources(self) -> list[int]:
        """For each of :attr:`markers`, the column it is read from once exchanged."""
        return exchange_columns(self.a, self.b, self.c)[1]


def exchange_columns(a: int, b: int, c: int = -1) -> tuple[list[int], list[int]]:
    """The markers of a pair ``(a, b)`` or a cycle ``(a, b, c)`` (``a`` read from ``b``'s label, ``b`` from ``c``'s,
    ``c`` from ``a``'s), and for each the column it is read from once exchanged.

    Parameters
    ----------
    a, b : int
    c : int
        -1 for a pair.
    """
    return ([a, b], [b, a]) if c < 0 else ([a, b, c], [b, c, a])


def exchange_name(names, a: int, b: int, c: int = -1, *, detail: bool = False) -> str:
    """The labels of a pair, 'a and b', or of a cycle, 'a, b and c round a cycle' (with ``detail``, which label each
    is read from).

    Parameters
    ----------
    names : sequence of str
        The markers' names.
    a, b, c : int
        The markers (``c`` -1 for a pair; see :func:`exchange_columns`).
    detail : bool
        Say which label each marker of a cycle is read from.
    """
    if c < 0:
        return f"{names[a]} and {names[b]}"
    told = f"{names[a]}, {names[b]} and {names[c]} round a cycle"
    if detail:
        told += (f" ({names[a]} read from {names[b]}'s label, {names[b]} from {names[c]}'s, {names[c]} from "
                 f"{names[a]}'s)")
    return told


def _stretches(far, seen, target, fit, residuals, limit):
    """Candidate (rank, ratio, a, b, c, first, last): a run of frames in which marker a is ``far`` from the fitted
    hand (runs a few frames apart joined), with the exchanges :func:`exchange_candidates` finds for a in its middle
    frame."""
    out = set()
    for a in np.flatnonzero(far.any(axis=0)):
        ts = np.flatnonzero(far[:, a])
        breaks = np.flatnonzero(np.diff(ts) > 1 + CONTEXT)  # a few frames apart (the two crossing): one stretch
        for first, last in zip(ts[np.r_[0, breaks + 1]], ts[np.r_[breaks, len(ts) - 1]]):
            t = ts[np.searchsorted(ts, (first + last) // 2)]  # the middle frame, or the next where a is far
            if far[t].sum() > MAX_FAR or np.median(residuals[t, seen[t]]) > limit / 2:
                continue
            for candidate in exchange_candidates(target[t], fit[t], residuals[t], far[t], seen[t], a):
                out.add((*candidate, int(first), int(last)))
    return sorted(out)


def exchange_candidates(points, fit, residuals, far, usable, a: int) -> list[tuple]:
    """The exchanges of labels worth trying for marker ``a``, off the hand in one frame.

    Its partners are the other markers off the hand and the :data:`PARTNERS` usable markers nearest to it (the
    solve can follow one of two swapped markers to within the limit). A pair ``(a, b)`` is a candidate, and with
    two markers or more off the hand each cycle of ``a`` and two partners (``a`` read from ``b``'s
    label, ``b`` from ``c``'s, ``c`` from ``a``'s), where each marker's position lies within
    :data:`CANDIDATE_RATIO` times the largest residual of where the hand puts the one it is read as.

    Parameters
    ----------
    points, fit : ndarray (M, 3)
        The markers as labelled, and where the fitted hand puts them, metres.
    residuals : ndarray (M,)
        Their distances, metres.
    far : ndarray (M,) bool
        Markers off the hand.
    usable : ndarray (M,) bool
        Markers that may be partners (seen; measured, not predicted).
    a : int

    Returns
    -------
    list of (rank, ratio, a, b, c)
        Rank: how many of its markers are not off the hand; ratio: as above; a pair has ``a < b`` and ``c = -1``, a
        cycle starts at its smallest marker. Sorted, they are the likeliest first.
    """
    gap = np.where(usable, np.linalg.norm(points - points[a], axis=-1), np.inf)
    gap[a] = np.inf
    near = np.argsort(gap)[:PARTNERS]
    partners = sorted(int(m) for m in set(np.flatnonzero(far)) | set(near[np.isfinite(gap[near])]) if m != a)
    out = []
    for b in partners:
        ratio = max(np.linalg.norm(points[a] - fit[b]), np.linalg.norm(points[b] - fit[a])) / max(residuals[a],
                                                                                                    residuals[b])
        if ratio <= CANDIDATE_RATIO:
            out.append((int(not far[b]), float(ratio), int(min(a, b)), int(max(a, b)), -1))
    if far.sum() < 2:  # three labels round a cycle leave two off the hand at least
        return out
    for b, c in permutations(partners, 2):  # a read from b's label, b from c's, c from a's
        cross = max(np.linalg.norm(points[b] - fit[a]), np.linalg.norm(points[c] - fit[b]),
                    np.linalg.norm(points[a] - fit[c]))
        ratio = cross / max(residuals[a], residuals[b], residuals[c])
        if ratio <= CANDIDATE_RATIO:
            cycle = [int(a), b, c]
            start = int(np.argmin(cycle))  # one way of writing each cycle: its smallest marker first
            out.append((int(3 - far[cycle].sum()), float(ratio), *(cycle[(start + k) % 3] for k in range(3))))
    return out


def verdict(exchanged, exchanged_seen, given, given_seen, moved, limit: float = MRE_LIMIT) -> tuple[bool, float,
                                                                                                     float]:
    """Whether labels exchanged are the hand's: it fits the ``moved`` markers within ``limit``, :data:`CLOSER`
    times closer than as given, and the other markers no further on average than as given plus
    :data:`OTHERS_WORSE`.

    Parameters
    ----------
    exchanged, given : ndarray (F, M)
        Each marker's distance from the hand solved with the labels exchanged and as given, metres, over F frames.
    exchanged_seen, given_seen : ndarray (F, M) bool
        The markers seen either way.
    moved : ndarray (M,) bool
        The markers whose labels are exchanged.
    limit : float
        Metres.

    Returns
    -------
    bool, float, float
        The verdict, and the moved markers' mean distance as given and exchanged, metres.
    """
    fit, others = exchanged[exchanged_seen & moved].mean(), exchanged[exchanged_seen & ~moved]
    before, before_others = given[given_seen & moved].mean(), given[given_seen & ~moved]
    ok = fit <= min(limit, before / CLOSER) and (not len(others) or others.mean() <= before_others.mean()
                                                 + OTHERS_WORSE)
    return bool(ok), float(before), float(fit)


def find_swaps(target, observed, fit, solve, *, limit: float = MRE_LIMIT) -> tuple[list[Swap], int]:
    """Stretches of frames in which two labels are swapped, by the hand solved again with them exchanged.

    Parameters
    ----------
    target : ndarray (T, M, 3)
        Observed markers, metres (anything where not ``observed``).
    observed : ndarray (T, M) bool
    fit : ndarray (T, M, 3)
        Where the solved hand puts each marker, metres.
    solve : callable
        ``solve(target, observed) -> fit`` for a stretch of frames (the same solve, frames ``(N, M, 3)``).
    limit : float
        Metres: a marker further than this from the fitted hand is off it; with the labels exchanged both of a pair
        must come within it.

    Returns
    -------
    list of Swap
        In order of their first frame; no two share a marker in overlapping frames.
    int
        Stretches left untried: their solves would have exceeded :data:`BUDGET` times the take's frames.
    """
    residuals = np.where(observed, np.linalg.norm(fit - np.nan_to_num(target), axis=-1), 0.0)
    far = observed & (residuals > limit)
    found, tried, spent, untried = [], [], 0, 0
    for _, _, a, b, c, first, last in _stretches(far, observed, target, fit, residuals, limit):
        if any((a, b, c) == key and first <= end and start <= last for key, start, end in tried):
            continue  # the same pair (or cycle) from another marker's stretch
        if any(len({a, b, c} & set(f.markers)) >= 2 and first <= f.last and f.first <= last for f in found):
            continue  # two of its markers found swapped there already (a cycle leaves no pair fitting, nor a pair
            # a cycle)
        tried.append(((a, b, c), first, last))
        lo, hi = max(0, first - CONTEXT), min(len(target), last + 1 + CONTEXT)
        if spent + hi - lo > BUDGET * len(target):
            untried += 1
            continue
        spent += hi - lo
        swap = Swap(a, b, first - lo, last - lo, 0.0, 0.0, c)
        swapped, seen = exchanged(target[lo:hi], observed[lo:hi], [swap])
        stretch = slice(swap.first, swap.last + 1)
        distance = np.linalg.norm(solve(swapped, seen)[stretch] - np.nan_to_num(swapped[stretch]), axis=-1)
        moved = np.zeros(distance.shape[1], dtype=bool)
        moved[swap.markers] = True
        ok, given, fit_exchanged = verdict(distance, seen[stretch], residuals[first:last + 1],
                                           observed[first:last + 1], moved, limit)
        if ok:
            found.append(Swap(a, b, first, last, given, fit_exchanged, c))
    kept = []
    for swap in sorted(found, key=lambda s: s.exchanged):  # a marker swapped with two others at once: the closer fit
        if not any(set(swap.markers) & set(k.markers) and swap.first <= k.last and k.first <= swap.last
                   for k in kept):
            kept.append(swap)
    return sorted(kept, key=lambda s: s.first), untried


def exchanged(target, observed, swaps) -> tuple[np.ndarray, np.ndarray]:
    """Copies of ``target`` and ``observed`` with each swap's two labels exchanged in its frames.

    Parameters
    ----------
    target : ndarray (T, M, 3)
        Observed markers, metres.
    observed : ndarray (T, M) bool
    swaps : list of Swap

    Returns
    -------
    ndarray (T, M, 3), ndarray (T, M) bool
    """
    target, observed = np.array(target, copy=True), np.array(observed, copy=True)
    for s in swaps:
        for values in (target, observed):
            values[s.first:s.last + 1, s.markers] = values[s.first:s.last + 1, s.sources]
    return target, observed


def swap_warnings(swaps, names, rate: float, untried: int = 0) -> list[str]:
    """One line for the swaps mended (at most five named), and one for stretches left untried.

    Parameters
    ----------
    swaps : list of Swap
    names : sequence of str
        The markers' names.
    rate : float
        Frames per second.
    untried : int
        Stretches :func:`find_swaps` did not try.

    Returns
    -------
    list of str
    """
    out = [f"solve: {untried} stretch(es) of frames where markers lie off the fitted hand were not checked for label "
           f"swaps (more than the search's budget of {BUDGET:g} of the take's frames)"] if untried else []
    if not swaps:
        return out
    told = "; ".join(f"{exchange_name(names, s.a, s.b, s.c, detail=True)} in frames {s.first}-{s.last} "
                     f"({s.first / rate:.2f}-{s.last / rate:.2f} s: {MM * s.given:.1f} mm from the hand as labelled, "
                     f"{MM * s.exchanged:.1f} mm exchanged)" for s in swaps[:5])
    more = f"; and {len(swaps) - 5} more" if len(swaps) > 5 else ""
    return out + [f"solve: {len(swaps)} label swap(s) found by the hand and solved exchanged: {told}{more}; "
            "the input file is unchanged (relabel it with handcap label --offline, or solve with --keep-swaps "
            "to solve the labels as given)"]
