"""A 2x2x2 cube turned through a move sequence, with exact truth (issue 18: the cube's own motion, no hand yet).

The cube drifts and turns smoothly in the world (as in a hand), and its layers turn one move at a time:
each quarter turn takes ``turn_seconds`` with a smooth (minimum-jerk) angle profile, a half turn twice as long,
with ``pause_seconds`` of rest between moves. Every cubie's markers are those of the cube's description
(:func:`handcap.objects.articulated.load_articulated`), moved with their cubie.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from handcap.core.transforms import homogeneous
from handcap.objects.articulated import ArticulatedObject, load_articulated
from handcap.objects.cube import FACE_ORDER, FACES, apply_moves, layer, parse_moves, solved_state


@dataclass(frozen=True)
class CubeTake:
    """What :func:`cube_take` made.

    Attributes
    ----------
    markers : ndarray (T, M, 3)
        World positions of the cube's markers (description order), metres; no noise.
    marker_names : tuple of str
    rate : float
    global_pose : ndarray (T, 4, 4)
        Cube frame to world.
    cubie_rotation : ndarray (T, 8, 3, 3)
        Each cubie's rotation in the cube's frame (integer quarter turns at rest, in between during a move).
    layer_angle : ndarray (T, 6)
        Angle of each face's layer (:data:`FACE_ORDER`) in the current move, radians clockwise seen from the
        face; 0 outside its moves.
    moves : list of (str, int)
        The sequence.
    move_frames : ndarray (K, 2) int
        First and last frame of each move.
    state : ndarray (8, 3, 3) int
        The cubies' state after the sequence (:func:`handcap.objects.cube.apply_moves`).
    """

    markers: np.ndarray
    marker_names: tuple
    rate: float
    global_pose: np.ndarray
    cubie_rotation: np.ndarray
    layer_angle: np.ndarray
    moves: list
    move_frames: np.ndarray
    state: np.ndarray


def _smoothstep(u):
    return u ** 3 * (10 - 15 * u + 6 * u ** 2)  # minimum jerk from 0 to 1


def cube_take(moves: str, rng=None, *, rate: float = 120.0, turn_seconds: float = 0.35,
              pause_seconds: float = 0.25, cube: ArticulatedObject | None = None,
              turn_deg: float = 30.0, drift: float = 0.03) -> CubeTake:
    """The cube's markers while it is turned through ``moves``, and the truth.

    Parameters
    ----------
    moves : str
        Standard notation, e.g. ``"R U R' U'"``.
    rng : numpy.random.Generator, optional
    rate : float
        Frames per second.
    turn_seconds, pause_seconds : float
        Duration of a quarter turn, and of the rest before, between and after the moves.
    cube : ArticulatedObject, optional
        Default: the shipped ``cube2x2``.
    turn_deg, drift : float
        Amplitude of the cube's smooth global rotation (degrees) and translation (metres).

    Returns
    -------
    CubeTake
    """
    rng = np.random.default_rng(0) if rng is None else rng
    cube = load_articulated("cube2x2") if cube is None else cube
    sequence = parse_moves(moves)
    quarter, pause = int(round(turn_seconds * rate)), int(round(pause_seconds * rate))
    lengths = [quarter * (2 if abs(t) == 2 else 1) for _, t in sequence]
    n = pause + sum(length + pause for length in lengths)
    rot = np.tile(np.eye(3), (n, 8, 1, 1))
    angle = np.zeros((n, 6))
    state = solved_state()
    frames = []
    start = pause
    for (face, turns), length in zip(sequence, lengths):
        moving = layer(state, face)
        axis = np.array(FACES[face], dtype=np.float64)
        total = -np.pi / 2 * turns  # clockwise seen from the face: negative about its outward normal
        u = _smoothstep(np.clip((np.arange(n) - start + 1) / length, 0.0, 1.0))  # 0 before, 1 after
        during = Rotation.from_rotvec(np.outer(u[start:] * total, axis)).as_matrix()  # from this move on
        rot[start:] = state.astype(float)  # later moves overwrite their own frames
        rot[start:, moving] = np.einsum("tij,njk->tnik", during, state[moving].astype(float))
        inside = np.arange(start, start + length)
        angle[inside, FACE_ORDER.index(face)] = -u[inside] * total
        state = apply_moves(state, [(face, turns)])
        frames.append((start, start + length - 1))
        start += length + pause
    t = np.arange(n) / rate
    phases = rng.uniform(0, 2 * np.pi, 6)
    freq = rng.uniform(0.2, 0.5, 6)
    turn = np.deg2rad(turn_deg) * np.sin(2 * np.pi * freq[:3] * t[:, None] + phases[:3])
    start_pose = Rotation.random(random_state=int(rng.integers(1 << 31)))
    glob = homogeneous((Rotation.from_rotvec(turn) * start_pose).as_matrix(),
                       np.array([0.0, 0.0, 0.3]) + drift * np.sin(2 * np.pi * freq[3:] * t[:, None] + phases[3:]))
    cubie = np.repeat(np.arange(8), [len(p.marker_names) for p in cube.parts])
    local = np.einsum("tmij,mj->tmi", rot[:, cubie], cube.markers)  # cube frame
    world = np.einsum("tij,tmj->tmi", glob[:, :3, :3], local) + glob[:, None, :3, 3]
    return CubeTake(world, cube.marker_names, float(rate), glob, rot, angle, sequence, np.array(frames, dtype=int),
                    state)
