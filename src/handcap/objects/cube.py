"""The 2x2x2 puzzle cube's moves: notation, layers and the state of its eight cubies (issue 18).

Frame: the cube's own, metres, centred; ``x`` towards the R face, ``y`` towards U, ``z`` towards F (right
handed). A face turn in standard notation (``R``, ``U'``, ``F2`` ...) turns the layer of the four cubies on that
face's side: ``X`` a quarter turn clockwise as seen looking at the face from outside (-90 degrees about the
face's outward normal), ``X'`` counter-clockwise, ``X2`` a half turn. On a 2x2x2 cube a turn of D leaves the
same arrangement as a turn of U and a turn of the whole cube; here the cube's frame is fixed, so the two are
different states: which layer moved decides.

The state is one rotation per cubie (``(8, 3, 3)`` integer matrices): cubie ``i``, at home at
:data:`HOME` ``[i]``, is now at ``R_i @ HOME[i]`` and turned by ``R_i``. The solved cube has every ``R_i`` the
identity.
"""

from __future__ import annotations

import re
from itertools import permutations, product

import numpy as np

from handcap.core.errors import HandcapError

#: Outward normal of each face, cube frame.
FACES = {"R": (1, 0, 0), "L": (-1, 0, 0), "U": (0, 1, 0), "D": (0, -1, 0), "F": (0, 0, 1), "B": (0, 0, -1)}
#: The faces in the order of per-face arrays (layer angles).
FACE_ORDER = tuple(FACES)
#: Home positions of the eight cubies (signs of their centres), in a fixed order.
HOME = np.array([(x, y, z) for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], dtype=np.int64)
#: Quarter turns of each suffix: clockwise, counter-clockwise, half.
TURNS = {"": 1, "'": -1, "2": 2}
#: Edge of a cubie of the shipped cube (56 mm across, with a little play between the cubies), metres.
CUBIE_EDGE = 0.0275
#: Distance of a cubie's centre from the cube's along each axis, metres.
CUBIE_OFFSET = 0.014
_MOVE = re.compile(r"^([RLUDFB])(2'?|'2?|)$")


def quarter_turn(axis, quarters: int) -> np.ndarray:
    """The integer rotation (3, 3) by ``quarters`` times -90 degrees about a signed unit ``axis`` (clockwise seen
    from the axis' tip).

    Parameters
    ----------
    axis : array_like (3,) int
        A face's outward normal, e.g. ``(1, 0, 0)``.
    quarters : int
        Clockwise quarter turns (negative: counter-clockwise).
    """
    axis = np.asarray(axis, dtype=np.int64)
    k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    q = (-quarters) % 4  # counter-clockwise quarters (Rodrigues with sin, cos of multiples of 90 degrees)
    sin, cos = (0, 1, 0, -1)[q], (1, 0, -1, 0)[q]
    return np.eye(3, dtype=np.int64) + sin * k + (1 - cos) * (k @ k)


def parse_moves(text: str) -> list[tuple[str, int]]:
    """Moves in standard notation, ``"R U R' U' D2"``, as ``(face, quarter turns)`` with turns 1, -1 or 2.

    Raises
    ------
    HandcapError
        A token that is no face turn (only U D L R F B with ``'`` or ``2``; whole-cube rotations and slice
        moves do not apply to a 2x2x2 cube's layers).
    """
    moves = []
    for token in str(text).replace(",", " ").split():
        m = _MOVE.match(token.replace("’", "'"))
        if m is None:
            raise HandcapError(f"move {token!r}: a 2x2x2 cube's moves are the faces U D L R F B, each alone, "
                               f"with ' (counter-clockwise) or 2 (half turn), e.g. \"R U R' U'\"")
        moves.append((m.group(1), 2 if "2" in m.group(2) else (-1 if "'" in m.group(2) else 1)))
    return moves


def format_moves(moves) -> str:
    """``(face, quarter turns)`` pairs as standard notation (turns taken modulo 4; zero turns dropped)."""
    out = []
    for face, turns in moves:
        q = int(turns) % 4
        if q:
            out.append(face + {1: "", 2: "2", 3: "'"}[q])
    return " ".join(out)


def random_moves(count: int, rng) -> list[tuple[str, int]]:
    """A random scramble of ``count`` face turns, no face twice in a row (what a scrambler would write).

    Parameters
    ----------
    count : int
    rng : numpy.random.Generator
    """
    moves, last = [], None
    for _ in range(count):
        face = str(rng.choice([f for f in FACES if f != last]))
        moves.append((face, int(rng.choice([1, -1, 2]))))
        last = face
    return moves


def solved_state() -> np.ndarray:
    """The solved cube: eight identity rotations, (8, 3, 3) int."""
    return np.tile(np.eye(3, dtype=np.int64), (8, 1, 1))


def positions(state) -> np.ndarray:
    """Where each cubie sits now, (8, 3) signs."""
    return np.einsum("nij,nj->ni", np.asarray(state), HOME)


def layer(state, face: str) -> np.ndarray:
    """Which cubies (8,) bool sit in ``face``'s layer now.

    Parameters
    ----------
    state : ndarray (8, 3, 3) int
    face : str
        One of U D L R F B.
    """
    return positions(state) @ np.array(FACES[face]) > 0


def apply_moves(state, moves) -> np.ndarray:
    """The state after ``moves``, (8, 3, 3) int.

    Parameters
    ----------
    state : ndarray (8, 3, 3) int
    moves : str or sequence of (str, int)
        Notation (``"R U R' U'"``) or ``(face, quarter turns)`` pairs.
    """
    state = np.array(state, dtype=np.int64)
    for face, turns in (parse_moves(moves) if isinstance(moves, str) else moves):
        turn = quarter_turn(FACES[face], turns)
        moving = layer(state, face)
        state[moving] = turn @ state[moving]
    return state


def is_solved(state) -> bool:
    """Every cubie home and unturned."""
    return bool((np.asarray(state) == solved_state()).all())


def permutation(state) -> np.ndarray:
    """The cubie at each home place, (8,) int: ``permutation(state)[k]`` sits at ``HOME[k]``."""
    where = positions(state)
    index = {tuple(h): k for k, h in enumerate(HOME)}
    out = np.empty(8, dtype=np.int64)
    for cubie, place in enumerate(where):
        out[index[tuple(place)]] = cubie
    return out


def twists(state) -> np.ndarray:
    """Each cubie's twist (8,) int, 0 to 2: how many turns of +120 degrees about its place's outward diagonal
    bring the face of that place along y to the face that was its own y face at home. Every state that face
    turns reach from the solved cube, in any frame of the cube, has twists summing to a multiple of 3.

    Parameters
    ----------
    state : ndarray (8, 3, 3) int
    """
    state = np.asarray(state, dtype=np.int64)
    out = np.zeros(8, dtype=np.int64)
    cycle = np.array([[0, 0, 1], [1, 0, 0], [0, 1, 0]])  # +120 degrees about (1, 1, 1): x -> y -> z -> x
    for c, place in enumerate(positions(state)):
        flip = np.diag(place)  # a reflection where the place has an odd number of minus signs
        turn = flip @ (cycle if np.prod(place) > 0 else cycle.T) @ flip  # +120 degrees about the place's diagonal
        mine, face = state[c] @ np.array([0, HOME[c][1], 0]), np.array([0, place[1], 0])
        for k in range(3):
            if (face == mine).all():
                out[c] = k
            face = turn @ face
    return out


def _rotations() -> np.ndarray:
    """The 24 integer rotations (24, 3, 3): signed permutation matrices of determinant 1."""
    out = [np.diag(signs)[list(order)] for order in permutations(range(3)) for signs in product((1, -1), repeat=3)]
    return np.array([r for r in out if round(np.linalg.det(r)) == 1], dtype=np.int64)


def complete_state(state, known) -> np.ndarray:
    """The state with its one unknown cubie put where the seven others leave room and turned as the cube allows.

    The cubie takes the one place the others do not hold, and of the three turns that put it there (their
    twists are 0, 1 and 2) the one that makes the cube's total a multiple of 3 (:func:`twists`): a cubie hidden
    all the while is still placed exactly, if the others are right.

    Parameters
    ----------
    state : ndarray (8, 3, 3) int
        The known cubies' rotations (the unknown one's is ignored).
    known : ndarray (8,) bool
        Exactly one False.

    Returns
    -------
    ndarray (8, 3, 3) int

    Raises
    ------
    HandcapError
        Not exactly one cubie unknown, or two known cubies in one place.
    """
    state, known = np.array(state, dtype=np.int64), np.asarray(known, dtype=bool)
    if (~known).sum() != 1:
        raise HandcapError(f"complete_state places one unknown cubie, not {int((~known).sum())}")
    c = int(np.flatnonzero(~known)[0])
    taken = {tuple(p) for p in positions(state)[known]}
    free = [h for h in HOME if tuple(h) not in taken]
    if len(free) != 1:
        raise HandcapError("the cube's known cubies share a place: the last one cannot be placed")
    for turn in _rotations():
        state[c] = turn
        if (turn @ HOME[c] == free[0]).all() and twists(state).sum() % 3 == 0:
            break
    return state


def cube_signed_distance(points, cube_pose, cubie_rotation, *, chunk: int = 64) -> np.ndarray:
    """Signed distance (metres, negative inside) of world points to the union of the cube's eight cubies, each
    where its rotation puts it (mid-turn too).

    Parameters
    ----------
    points : ndarray (T, P, 3)
        World points, metres (e.g. a hand's vertices); NaN gives NaN.
    cube_pose : ndarray (T, 4, 4)
        The cube's frame to the world.
    cubie_rotation : ndarray (T, 8, 3, 3)
        Each cubie's rotation in the cube's frame.
    chunk : int
        Frames computed at once (memory).

    Returns
    -------
    ndarray (T, P)
    """
    points = np.asarray(points, dtype=np.float64)
    out = np.empty(points.shape[:2])
    centre = HOME * CUBIE_OFFSET
    for a in range(0, len(points), chunk):
        b = slice(a, a + chunk)
        local = np.einsum("tji,tpj->tpi", cube_pose[b, :3, :3], points[b] - cube_pose[b, None, :3, 3])
        inner = np.einsum("tnji,tpj->tnpi", cubie_rotation[b], local) - centre[None, :, None]  # cubie frames
        q = np.abs(inner) - CUBIE_EDGE / 2
        d = np.linalg.norm(np.maximum(q, 0), axis=-1) + np.minimum(q.max(axis=-1), 0)
        out[b] = d.min(axis=1)
    return out
