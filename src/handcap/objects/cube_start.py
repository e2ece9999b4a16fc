"""Where a tracked 2x2x2 cube's cubies are: at the start, and for those first seen later, since the start.

The tracker (:func:`handcap.objects.cube_track.track_cube`) reads the moves from the first frame in which most
cubies are seen. Cubies join as they are seen: before the first turn in the frame the others give; after it, at
rest, where the pose of the known ones puts them now, and where they started from the moves read since (undone
one by one: a turn moves the cubies in its layer, wherever they came from). With 4 cameras most cubies of a quick
take were never seen before its first turn: the take stopped with an error.
"""

from __future__ import annotations

import numpy as np

from handcap.core.errors import HandcapError
from handcap.objects.cube import FACES, HOME, apply_moves, complete_state, quarter_turn
from handcap.objects.rigid import kabsch

#: The cubies' names in the order of :data:`handcap.objects.cube.HOME`.
CUBIE_NAMES = np.array(["DBL", "DFL", "UBL", "UFL", "DBR", "DFR", "UBR", "UFR"])
#: A layer has begun to turn when the known cubies fit one rigid body worse than this, metres RMS.
TURNING = 0.0025


def place_cubie(rest, world, rotation, translation):
    """A cubie's rotation in the cube's frame from two or more of its markers and the cube's pose.

    The cube's centre is a point of every cubie (it turns about it): with it, two markers place one.

    Parameters
    ----------
    rest : ndarray (k, 3)
        The markers at home on the cubie, cube frame, metres.
    world : ndarray (k, 3)
        Where they are seen, metres.
    rotation : ndarray (3, 3)
    translation : ndarray (3,)
        The cube's pose (cube frame to world).

    Returns
    -------
    ndarray (3, 3) int or None
        None where the fit is not within 0.2 of a quarter-turn rotation (about 11 deg).
    """
    turn, _ = kabsch(np.vstack([rest, np.zeros(3)]), np.vstack([world, translation]))
    guess = rotation.T @ turn
    return np.rint(guess).astype(np.int64) if np.abs(guess - np.rint(guess)).max() < 0.2 else None


def free_place(state, known, c: int, now) -> bool:
    """Whether cubie ``c`` turned to ``now`` lands on a place no known cubie holds.

    Parameters
    ----------
    state : ndarray (8, 3, 3) int
    known : ndarray (8,) bool
    c : int
    now : ndarray (3, 3) int
    """
    taken = np.einsum("nij,nj->ni", np.asarray(state)[known], HOME[known])
    return not (taken == np.asarray(now) @ HOME[c]).all(axis=1).any()


def start_state(w, seen, world, valid, cubie, rest) -> tuple[int, np.ndarray, np.ndarray]:
    """The first frame to track from, the cubies' state there, and which of them are known.

    From the first frame in which most cubies are seen (at least four, or as many as are ever seen), the
    first cubie seen sets the cube's frame; the others join as they are first seen (:func:`place_cubie`), while
    the known ones still move as one body (no layer is turning yet). One cubie never seen by then is placed from
    the seven others (:func:`~handcap.objects.cube.complete_state`); more are left to join later.

    Parameters
    ----------
    w : ndarray (T, 8, 3, 3)
    seen : ndarray (T, 8) bool
        Every cubie's rotation from its own markers, where seen.
    world : ndarray (T, M, 3)
        The markers, metres (any value where not ``valid``).
    valid : ndarray (T, M) bool
    cubie : ndarray (M,) int
        Each marker's cubie.
    rest : ndarray (M, 3)
        The markers at home, cube frame, metres.

    Returns
    -------
    first : int
    state : ndarray (8, 3, 3) int
        Zero for cubies not known.
    known : ndarray (8,) bool

    Raises
    ------
    HandcapError
        No two cubies are ever seen in one frame.
    """
    counts = seen.sum(axis=1)
    if counts.max() < 2:
        raise HandcapError(f"the cube is never seen: in {len(w)} frames no two of its cubies show 3 markers "
                           f"each")
    first = int(np.argmax(counts >= min(4, counts.max())))
    known = seen[first].copy()
    state = np.zeros((8, 3, 3), dtype=np.int64)
    state[known] = np.rint(np.einsum("ji,njk->nik", w[first, int(np.argmax(known))], w[first, known]))
    for f in range(first + 1, len(w)):
        if known.all():
            break
        use = valid[f] & known[cubie]
        if use.sum() < 3:
            continue
        x = np.einsum("mij,mj->mi", state[cubie], rest)
        rot, trans = kabsch(x, world[f], use.astype(float))
        if np.sqrt(np.mean(np.sum((x[use] @ rot.T + trans - world[f, use]) ** 2, axis=1))) > TURNING:
            break
        for c in np.flatnonzero(~known):
            mine = (cubie == c) & valid[f]
            placed = place_cubie(rest[mine], world[f, mine], rot, trans) if mine.sum() >= 2 else None
            if placed is not None and free_place(state, known, c, placed):
                state[c], known[c] = placed, True
    if (~known).sum() == 1:  # the seven others leave one place, and the cube's twists one turn there
        return first, complete_state(state, known), np.ones(8, bool)
    return first, state, known


def undo_moves(state, c: int, moves) -> np.ndarray:
    """Where cubie ``c`` was before ``moves``, (3, 3) int.

    Parameters
    ----------
    state : ndarray (8, 3, 3) int
        Now (only ``state[c]`` matters: a turn moves the cubies in its layer, wherever they came from).
    c : int
    moves : sequence of (str, int)
        Face and quarter turns, in the order made.
    """
    return apply_moves(state, [(face, -quarters) for face, quarters in reversed(moves)])[c]


def cubie_history(start, c: int, turns, n: int) -> np.ndarray:
    """Cubie ``c``'s rotation in the cube's frame in every frame, from where it started and the turns read.

    Parameters
    ----------
    start : ndarray (3, 3) int
    c : int
    turns : sequence of (frames, face, turn, quarters)
        Each turn read: its frames (F,), face, the layer's rotation in each of them (F, 3, 3) and the quarter
        turns it ended at (0 for a layer turned back).
    n : int
        Frames in all.

    Returns
    -------
    ndarray (n, 3, 3)
    """
    out = np.empty((n, 3, 3))
    now, t = np.asarray(start, dtype=float), 0
    for frames, face, turn, quarters in turns:
        out[t:frames[0]] = now
        inside = (now @ HOME[c]) @ np.array(FACES[face]) > 0
        out[frames] = turn @ now if inside else now
        if inside:
            now = quarter_turn(FACES[face], quarters) @ now
        t = int(frames[-1]) + 1
    out[t:] = now
    return out


def unvouched(joins, cubie_rotation, seen, rate: float, since: float) -> tuple[str, ...]:
    """Warnings for cubies placed late whose layers no earlier cubie vouches for.

    A cubie placed after the moves began to be read takes where it started from the moves read since. A turn of
    one of its layers that the tracker missed (none of the layer's cubies seen as it turned) is absorbed into
    that start, and the cubie agrees with the track. A cubie placed earlier in the same layer would not: seen
    afterwards beside a cubie outside the layer, the two disagree (:func:`handcap.objects.cube_check.check_track`).
    Where no such pair is seen after the late cubie is placed, the turn would go unread and unsaid.

    Parameters
    ----------
    joins : sequence of (int, int, ndarray (8,) bool)
        Each late cubie, the frame it was placed in, and the cubies placed before it.
    cubie_rotation : ndarray (T, 8, 3, 3)
        The track's arrangement.
    seen : ndarray (T, 8) bool
    rate : float
        Frames per second.
    since : float
        The first frame by which a turn could have been made and missed (the frame the moves are read from and
        the frames of the quickest turn): cubies placed earlier need no one to vouch.

    Returns
    -------
    tuple of str
    """
    out = []
    place = np.einsum("tnij,nj->tni", np.rint(cubie_rotation), HOME)  # (T, 8, 3)
    for c, frame, before in joins:
        if frame <= since:
            continue
        lonely = []
        for a in range(3):
            layer = place[frame:, :, a] == place[frame:, c:c + 1, a]  # (F, 8): the cubies in c's layer on axis a
            mates = (seen[frame:] & layer & before).any(axis=1)
            outside = (seen[frame:] & ~layer).any(axis=1)
            if not (mates & outside).any():
                lonely.append(("RUF" if place[frame, c, a] > 0 else "LDB")[a])
        if lonely:
            out.append(f"cube: cubie {CUBIE_NAMES[c]} is first placed at {frame / rate:.2f} s, and no cubie placed "
                       f"before it in its {'/'.join(lonely)} layer is seen beside the others after then: a turn of "
                       f"that layer before {frame / rate:.2f} s would not be read")
    return tuple(out)


def unplaced(known) -> HandcapError:
    """The error for cubies never placed in a take."""
    return HandcapError(f"the cube's cubies {', '.join(CUBIE_NAMES[~known])} are never seen (2 markers each) with "
                        f"the cube at rest: cannot tell where they are")
