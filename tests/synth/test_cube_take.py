"""Synthetic cube takes: the cubies end as the move algebra says, move as rigid bodies, and turn one layer at a time."""

import numpy as np
import pytest

from handcap import HandcapError
from handcap.objects.cube import FACES, HOME, apply_moves, is_solved, solved_state
from handcap.synth.cube import FACE_ORDER, cube_take


def test_the_take_ends_in_the_state_of_its_moves():
    moves = "R U R' U' D L' B2 F"
    take = cube_take(moves, np.random.default_rng(1), rate=60.0)
    assert (take.state == apply_moves(solved_state(), moves)).all()
    assert np.allclose(take.cubie_rotation[-1], take.state)
    assert np.allclose(take.cubie_rotation[0], solved_state())
    assert len(take.move_frames) == 8 and (np.diff(take.move_frames.ravel()) > 0).all()
    assert take.markers.shape == (len(take.global_pose), 24, 3) and np.isfinite(take.markers).all()
    assert is_solved(cube_take("R U R' U' " * 6, rate=30.0).state)


def test_each_cubie_moves_rigidly_and_one_layer_turns_at_a_time():
    take = cube_take("R U' F2", np.random.default_rng(2), rate=60.0)
    # distances between the three markers of each cubie never change
    cubies = take.markers.reshape(len(take.markers), 8, 3, 3)
    d = np.linalg.norm(cubies[:, :, :, None] - cubies[:, :, None], axis=-1)
    assert np.abs(d - d[0]).max() < 1e-9
    for (face, turns), (a, b) in zip(take.moves, take.move_frames):
        mid = (a + b) // 2
        # in the cube's frame only the four cubies of the layer differ from the frame before the move
        before = take.cubie_rotation[a - 1]
        changed = np.abs(take.cubie_rotation[mid] - before).max(axis=(1, 2)) > 1e-6
        assert changed.sum() == 4
        # the layer angle is the move's, reached at its last frame, and other faces stay at zero
        f = FACE_ORDER.index(face)
        assert take.layer_angle[b, f] == pytest.approx(np.pi / 2 * turns)
        assert np.abs(np.delete(take.layer_angle[a:b + 1], f, axis=1)).max() == 0.0
        # the moving cubies turn about the face's axis: they stay in the face's layer, on its side
        axis = np.array(FACES[face])
        centres = np.einsum("nij,nj->ni", take.cubie_rotation[mid], HOME)
        assert (centres[changed] @ axis == pytest.approx(1.0)) and (centres[~changed] @ axis == pytest.approx(-1.0))


def test_bad_moves():
    with pytest.raises(HandcapError, match="U D L R F B"):
        cube_take("R X")
