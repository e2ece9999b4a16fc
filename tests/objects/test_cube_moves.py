"""The 2x2x2 cube's move algebra, against facts of the cube group that do not depend on this code."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from handcap import HandcapError
from handcap.objects.cube import (FACES, HOME, apply_moves, format_moves, is_solved, layer, parse_moves, permutation,
                                  positions, quarter_turn, solved_state)


def test_quarter_turns_are_clockwise_seen_from_the_face():
    for face, normal in FACES.items():
        turn = quarter_turn(normal, 1)
        # scipy's rotation by -90 degrees about the outward normal (right hand rule: clockwise seen from outside)
        expected = Rotation.from_rotvec(-np.pi / 2 * np.array(normal, dtype=float)).as_matrix()
        assert np.allclose(turn, expected), face
        assert (quarter_turn(normal, 4) == np.eye(3)).all()
        assert (quarter_turn(normal, 2) == turn @ turn).all()
        assert (quarter_turn(normal, -1) == turn.T).all()


def test_sexy_move_six_times_is_the_identity():
    state = solved_state()
    for k in range(1, 7):  # the sequence has order 6: solved after the sixth time, not before
        state = apply_moves(state, "R U R' U'")
        assert is_solved(state) == (k == 6)
    assert is_solved(apply_moves(solved_state(), "R U R' U' " * 6))


@pytest.mark.parametrize("face", list(FACES))
def test_every_face_turn_moves_its_four_cubies_and_has_order_four(face):
    state = solved_state()
    for turns, order in ((1, 4), (-1, 4), (2, 2)):
        moved = apply_moves(state, [(face, turns)])
        changed = (moved != state).any(axis=(1, 2))
        assert changed.sum() == 4 and (changed == layer(state, face)).all()
        # the four stay in the layer and go round it
        assert (layer(moved, face) == layer(state, face)).all()
        again = state
        for _ in range(order):
            again = apply_moves(again, [(face, turns)])
        assert is_solved(again)
    assert (apply_moves(state, f"{face} {face}") == apply_moves(state, f"{face}2")).all()
    assert is_solved(apply_moves(state, f"{face} {face}'"))


def test_d_is_u_and_a_whole_cube_turn_but_a_different_state():
    d = apply_moves(solved_state(), "D")
    u = apply_moves(solved_state(), "U")
    # turning the whole cube back by D's turn (+90 degrees about -y, i.e. -90 about +y) after a D leaves the
    # bottom layer home and the top turned clockwise as seen from above: the state of U
    whole_back = quarter_turn(FACES["D"], -1)
    assert (np.einsum("ij,njk->nik", whole_back, d) == u).all()
    assert not (d == u).all()
    assert layer(solved_state(), "D").sum() == 4 and not (layer(solved_state(), "D") & layer(solved_state(), "U")).any()


def test_positions_stay_corners_and_notation_round_trips():
    rng = np.random.default_rng(0)
    faces = list(FACES)
    for _ in range(20):
        moves = [(faces[rng.integers(6)], int(rng.choice([1, -1, 2]))) for _ in range(10)]
        text = format_moves(moves)
        assert parse_moves(text) == moves
        state = apply_moves(solved_state(), text)
        assert sorted(map(tuple, positions(state))) == sorted(map(tuple, HOME))
        assert sorted(permutation(state)) == list(range(8))
        assert all(round(abs(np.linalg.det(r))) == 1 for r in state)
        # undoing the moves in reverse order with opposite turns solves it
        undo = [(f, -t) for f, t in reversed(moves)]
        assert is_solved(apply_moves(state, undo))


def test_bad_moves_are_one_clear_line():
    for bad in ("X", "R3", "r", "M", "U''", "Rw"):
        with pytest.raises(HandcapError, match="U D L R F B"):
            parse_moves(bad)
    assert parse_moves("R2' U’") == [("R", 2), ("U", -1)]
