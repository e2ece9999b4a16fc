"""Short excursions of a solved take into another pose, mended from the frames around them.

Each frame of :func:`handcap.solve.motion.solve_lm` is fitted on its own. Where the markers leave two poses about
equally good (a sparse marker set, markers a few millimetres off the calibrated hand: a real glove; or a label on
the wrong point), a frame can settle in the other one and the next come back: the hand jumps for a frame or a few
and jumps back. Solved so, the real glove recording (6,000 frames, 13 markers, ``../shared/data``) had 184 jerk
spikes and a motion signal-to-noise ratio of 0.2 dB (7.0 dB with the frames around the spikes interpolated).

The frames in and between jerk spikes of the posed hand (``handcap.quality.jerk_spikes`` of its 16 joints and its
markers, each spike's four frames; stretches less than :data:`MAX_SECONDS` apart joined) are solved again. The
aim is the take's cost plus ``lam`` times the squared second differences of the hand's points (how far each frame
lies from where the two before carry it at constant velocity), ``lam`` the take's own ratio of the two (medians
over its frames), so that in a typical frame they weigh alike. Frame by frame (coordinate descent, at most
:data:`SWEEPS` sweeps, frames next to a changed one looked at again, at most :data:`MAX_SECONDS` beyond the
stretch), three poses are tried: the solve from the frame before, and the solves from the frame before and from
the frame itself with the angles pulled towards the mean of the frames either side. The one that lowers the aim
most replaces the frame's pose; none that does not. Where the markers alone decide, every try lands on the same
pose and nothing changes; a pose they leave open takes the course of its neighbours. The glove: 184 -> 9 spikes,
0.2 -> 7.1 dB, the marker fit 1.316 -> 1.323 mm.

Before that search, each stretch is solved again as a whole, frame after frame from the two frames before it, each
frame's angles pulled towards where those two carry it (half their last change, :data:`DAMPING`, as the live
solver's, ``handcap.stream.solver``), and kept where it lowers the aim and fits the markers as closely (its cost no
higher). The frame-by-frame search cannot leave a block of frames that is all in the other pose: each frame's
neighbours are there too. A synthetic glove-13 grasp (2026-12-01) had such a block, its thumb 74-77 mm from the
truth over 13 frames (p99 of the joints 27.4 mm; 8.4 mm now); on the real glove no stretch passed both tests
(spikes, MSNR and marker fit as before), and its solve takes 5.0-5.2 s instead of 4.6-4.8.
"""

from __future__ import annotations

import numpy as np

from handcap.quality.motion_checks import jerk_spikes
from handcap.solve.lm import Poses

#: The longest stretch between two spikes taken for one excursion, seconds; and how far beyond it frames next to
#: a changed one are looked at again.
MAX_SECONDS = 0.15
#: Sweeps over an excursion's frames at most (each lowers its cost plus its lack of smoothness, or ends them).
SWEEPS = 3
#: A frame whose second differences (and the next two frames') are all within this many times the take's median
#: (squared distances) is on course and is not solved again.
CALM = 4.0
#: Joints among the points of the posed hand (the rest are its markers).
JOINTS = 16
#: The prediction of a frame from the two before it (:func:`predicted`): the last angles plus this fraction of their
#: last change. 1 (constant velocity) let the angles the markers barely constrain run on in the live solver; 0
#: holds them, which lags.
DAMPING = 0.5


def predicted(older, last) -> np.ndarray:
    """Where the angles of two frames in a row carry the next frame: the last plus :data:`DAMPING` times their
    change (the live solver's and the stretches' prediction).

    Parameters
    ----------
    older, last : ndarray (27,)
        The two frames' angles, radians, in time order.

    Returns
    -------
    ndarray (27,)
        Radians.
    """
    return last + DAMPING * (last - older)


def excursions(fitted, rate: float) -> list[np.ndarray]:
    """Stretches of frames (each an array of frame numbers) in and between jerk spikes of the posed hand.

    Parameters
    ----------
    fitted : ndarray (T, P, 3)
        Points of the posed hand in every frame (joints, markers), metres.
    rate : float
        Hz.

    Returns
    -------
    list of ndarray of int
        Each stretch's frames, in order; the first two frames of the take are never in one (they start the
        constant-velocity prediction).
    """
    spikes = jerk_spikes(fitted, rate)
    if not len(spikes):
        return []
    flagged = np.unique((spikes[:, None] + np.arange(4)).ravel())
    flagged = flagged[(flagged >= 2) & (flagged < len(fitted))]
    gap = max(1, int(round(MAX_SECONDS * rate)))
    runs = np.split(flagged, np.flatnonzero(np.diff(flagged) > gap) + 1)
    return [np.arange(r[0], r[-1] + 1) for r in runs if len(r)]


def mend_excursions(poses, fitted_of, cost_of, solve_pulled, rate: float) -> int:
    """Lower the take's cost plus its lack of smoothness in and around its excursions (in place; see the module
    docstring).

    Parameters
    ----------
    poses : Poses
        The take's solved poses (T frames); changed in place.
    fitted_of : callable
        ``fitted_of(poses) -> (T', 16 + M, 3)``: points of the posed hand, its 16 joints then its M markers,
        metres.
    cost_of : callable
        ``cost_of(frames, poses) -> (T',)``: the solver's cost of ``poses`` at ``frames``, square metres.
    solve_pulled : callable
        ``solve_pulled(t, init, phi, weight) -> Poses``: frame ``t`` solved from the one-frame pose ``init``
        with its angles pulled towards ``phi`` (27,) radians at ``weight`` metres per radian (``phi`` None: the
        solver's own priors).
    rate : float
        Hz.

    Returns
    -------
    int
        Frames that took a new pose.
    """
    fitted = fitted_of(poses)
    stretches = excursions(fitted, rate)
    if not stretches:
        return 0
    n = len(fitted)
    cost = cost_of(np.arange(n), poses)
    typical = max(float(np.median(_surprise(fitted, np.arange(2, n)))), 1e-12)
    lam = np.median(cost) / typical
    # the pull: an angle as far from its neighbours' mean as in a typical frame costs as much as a typical marker's
    # residual does
    bend = np.sqrt(np.mean((poses.phi[2:] - 2 * poses.phi[1:-1] + poses.phi[:-2]) ** 2, axis=1))
    markers = max(fitted.shape[1] - JOINTS, 1)
    weight = np.sqrt(np.median(cost) / markers) / max(float(np.median(bend)), 1e-6)
    reach = max(1, int(round(MAX_SECONDS * rate)))
    mended = set()

    def local(t, points, own_cost):
        """The frame's cost and the squared second differences it takes part in."""
        saved, fitted[t] = fitted[t].copy(), points
        frames = np.arange(max(t, 2), min(t + 3, n))
        value = own_cost + lam * np.sum(_surprise(fitted, frames))
        fitted[t] = saved
        return value

    def aim(lo, hi):
        """The take's cost plus its lack of smoothness, over the terms frames ``lo``..``hi`` take part in."""
        return np.sum(cost[lo:hi + 1]) + lam * np.sum(_surprise(fitted, np.arange(max(lo, 2), min(hi + 3, n))))

    for stretch in stretches:
        lo, hi = max(int(stretch[0]) - reach, 2), min(int(stretch[-1]) + reach, n - 1)
        # The whole stretch again, frame after frame from the frames before it, each pulled towards where the two
        # before carry it (as the live solver does): a block of frames in the other pose holds each of its frames
        # there in the frame-by-frame search below, whose neighbours are in that pose too.
        swept = poses.take(slice(lo - 2, hi + 1)).copy()
        for i in range(2, hi - lo + 3):
            prediction = predicted(swept.phi[i - 2], swept.phi[i - 1])
            swept.put(slice(i, i + 1), solve_pulled(lo - 2 + i, swept.take(slice(i - 1, i)).copy(), prediction,
                                                    weight))
        swept = swept.take(slice(2, None))
        points, own = fitted_of(swept), cost_of(np.arange(lo, hi + 1), swept)
        before = aim(lo, hi)
        saved = fitted[lo:hi + 1].copy(), cost[lo:hi + 1].copy()
        fitted[lo:hi + 1], cost[lo:hi + 1] = points, own
        if aim(lo, hi) < before * (1 - 1e-9) and np.sum(own) <= np.sum(saved[1]):  # smoother, markers as close
            poses.put(slice(lo, hi + 1), swept)
            mended.update(range(lo, hi + 1))
        else:
            fitted[lo:hi + 1], cost[lo:hi + 1] = saved
        work = set(stretch.tolist())
        for _ in range(SWEEPS):  # each frame of the work, then those next to a frame that moved
            moved = set()
            for t in sorted(work):
                near = np.arange(max(t, 2), min(t + 3, n))
                if _surprise(fitted, near).max() <= CALM * typical:  # on course already: nothing to mend
                    continue
                middle = (poses.phi[t - 1] + poses.phi[t + 1]) / 2 if t + 1 < n else 2 * poses.phi[t - 1] - poses.phi[
                    t - 2]
                previous = poses.take(slice(t - 1, t)).copy()
                tries = [solve_pulled(t, previous, None, 0.0), solve_pulled(t, previous, middle, weight),
                         solve_pulled(t, poses.take(slice(t, t + 1)).copy(), middle, weight)]
                tried = Poses(*(np.concatenate([getattr(r, k) for r in tries]) for k in ("transl", "rot", "phi")))
                points, own = fitted_of(tried), cost_of(np.full(len(tries), t), tried)
                values = [local(t, points[k], own[k]) for k in range(len(tries))]
                k = int(np.argmin(values))
                if values[k] < local(t, fitted[t], cost[t]) * (1 - 1e-9):
                    poses.put(slice(t, t + 1), tries[k])
                    fitted[t], cost[t] = points[k], own[k]
                    mended.add(t)
                    moved.add(t)
            work = {u for t in moved for u in range(t - 2, t + 3) if lo <= u <= hi}
            if not work:
                break
    return len(mended)


def _surprise(fitted, frames) -> np.ndarray:
    """Squared distance of the hand's points at ``frames`` (each >= 2) from the constant-velocity prediction of
    the two frames before, summed over the points, square metres."""
    return np.sum((fitted[frames] - 2 * fitted[frames - 1] + fitted[frames - 2]) ** 2, axis=(-1, -2))


__all__ = ["DAMPING", "MAX_SECONDS", "excursions", "mend_excursions", "predicted"]
