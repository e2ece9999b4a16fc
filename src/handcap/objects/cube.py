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
