"""A 2x2x2 cube turned through a move sequence, with exact truth (issue 18).

The layers turn one move at a time (:func:`move_schedule`): each quarter turn takes ``turn_seconds`` with a
smooth (minimum-jerk) angle profile, a half turn twice as long, with ``pause_seconds`` of rest between moves.
Every cubie's markers are those of the cube's description (:func:`handcap.objects.articulated.
load_articulated`), moved with their cubie.

- :func:`cube_take`: the cube alone, drifting and turning smoothly in the world as if held.
- :func:`turning_motion`: the hand holds the cube in a precision grasp (thumb against index and middle,
  the cube in one of its 24 orientations) and moves it about; for each move, the fingertip that lies on the
  turning layer rides it (its finger's angles solved so that the tip follows the layer), then returns to its
  grip during the pause. A layer that no fingertip touches turns on its own. ``handcap synth --motion
  turn-cube --moves ...`` films this with the hand (motion ``turn-cube``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from itertools import permutations

import trimesh
from scipy.optimize import least_squares

from handcap.core.transforms import homogeneous
from handcap.hand.anatomy import PHI_LIMITS, PHI_NAMES
from handcap.objects.articulated import ArticulatedObject, load_articulated
from handcap.objects.cube import CUBIE_EDGE, CUBIE_OFFSET, FACE_ORDER, FACES, HOME, apply_moves, layer, parse_moves
from handcap.objects.cube import cube_signed_distance, solved_state
from handcap.synth.grasps import grasp_configuration
from handcap.synth.motions import NEUTRAL, WORK_CENTRE, Motion, finish_motion, rotation_path
from handcap.synth.motions import spline, wrist_keys
from handcap.synth.objects import make_object

#: The motion of ``handcap synth`` in which the hand turns the cube's layers.
CUBE_MOTION = "turn-cube"
#: Where in a move (fraction of its time) the fingers are placed: every 10 % of the turn's angle (the
#: minimum-jerk profile's times), so that a tip riding the layer stays on its arc between them.
_KEYS = np.array([0.2, 0.29, 0.36, 0.42, 0.47, 0.53, 0.58, 0.64, 0.71, 0.8, 1.0])
#: Joint index of each fingertip that may ride a turning layer.
_TIPS = {"thumb": 16, "index": 17, "middle": 18}


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


def move_schedule(sequence, rate: float, turn_seconds: float = 0.35, pause_seconds: float = 0.25):
    """When each move happens and how every cubie is turned in every frame.

    Parameters
    ----------
    sequence : list of (str, int)
        Moves (:func:`handcap.objects.cube.parse_moves`).
    rate : float
        Frames per second.
    turn_seconds, pause_seconds : float
        A quarter turn's duration (a half turn twice as long), and the rest before, between and after moves.

    Returns
    -------
    cubie_rotation : ndarray (T, 8, 3, 3)
        Each cubie's rotation in the cube's frame.
    layer_angle : ndarray (T, 6)
        Radians, clockwise seen from the face (:data:`FACE_ORDER`), during its move; 0 elsewhere.
    move_frames : ndarray (K, 2) int
        First and last frame of each move.
    state : ndarray (8, 3, 3) int
        After the sequence.
    """
    quarter, pause = max(int(round(turn_seconds * rate)), 2), max(int(round(pause_seconds * rate)), 1)
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
    return rot, angle, np.array(frames, dtype=int).reshape(-1, 2), state


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
    rot, angle, frames, state = move_schedule(sequence, rate, turn_seconds, pause_seconds)
    n = len(rot)
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
    return CubeTake(world, cube.marker_names, float(rate), glob, rot, angle, sequence, frames, state)


def cube_rotations() -> np.ndarray:
    """The 24 rotations that map a cube onto itself, (24, 3, 3) int (signed permutation matrices, det +1)."""
    out = []
    for perm in permutations(range(3)):
        for signs in np.array(np.meshgrid(*[[-1, 1]] * 3)).reshape(3, -1).T:
            m = np.zeros((3, 3), dtype=np.int64)
            m[np.arange(3), perm] = signs
            if round(np.linalg.det(m)) == 1:
                out.append(m)
    return np.array(out)


@dataclass(frozen=True)
class TurningTake:
    """A hand turning the cube (:func:`turning_motion`).

    Attributes
    ----------
    motion : Motion
        The hand; ``object_rotation`` and ``object_translation`` are the cube's pose (its frame to the world,
        axis-angle and metres), ``holding`` is True throughout.
    cube_pose : ndarray (T, 4, 4)
        The cube's frame (its body: the cubies not turning) to the world, metres.
    cubie_rotation : ndarray (T, 8, 3, 3)
    layer_angle : ndarray (T, 6)
    moves : list of (str, int)
    move_frames : ndarray (K, 2) int
    state : ndarray (8, 3, 3) int
    riding : tuple of str
        The finger riding each move's layer ("" where none touches it).
    """

    motion: Motion
    cube_pose: np.ndarray
    cubie_rotation: np.ndarray
    layer_angle: np.ndarray
    moves: list
    move_frames: np.ndarray
    state: np.ndarray
    riding: tuple

    def markers(self, cube: ArticulatedObject) -> tuple[np.ndarray, np.ndarray]:
        """World positions and outward normals (T, M, 3) of ``cube``'s markers (description order), metres."""
        cubie = np.repeat(np.arange(8), [len(p.marker_names) for p in cube.parts])
        rest = cube.markers
        normal = np.zeros_like(rest)
        axis = np.argmax(np.abs(rest), axis=1)
        normal[np.arange(len(rest)), axis] = np.sign(rest[np.arange(len(rest)), axis])
        turn = np.einsum("tij,tmjk->tmik", self.cube_pose[:, :3, :3], self.cubie_rotation[:, cubie])
        world = np.einsum("tmij,mj->tmi", turn, rest) + self.cube_pose[:, None, :3, 3]
        return world, np.einsum("tmij,mj->tmi", turn, normal)

    def surface(self, t: int) -> tuple[np.ndarray, np.ndarray]:
        """The eight cubies' boxes in frame ``t``: vertices (V, 3) in the world (metres) and faces (F, 3)."""
        return cubie_boxes(self.cubie_rotation[t], self.cube_pose[t])


def cubie_boxes(cubie_rotation, cube_pose) -> tuple[np.ndarray, np.ndarray]:
    """The eight cubies' boxes of a turned cube in the world.

    Parameters
    ----------
    cubie_rotation : ndarray (8, 3, 3)
        Each cubie's rotation in the cube's frame (:data:`handcap.objects.cube.HOME` order).
    cube_pose : ndarray (4, 4)
        The cube's frame to the world, metres.

    Returns
    -------
    vertices : ndarray (64, 3)
        Metres.
    faces : ndarray (96, 3)
    """
    box = trimesh.creation.box(extents=np.full(3, CUBIE_EDGE))
    local = HOME[:, None, :] * CUBIE_OFFSET + np.asarray(box.vertices)[None]  # (8, 8, 3)
    turned = np.einsum("nij,nkj->nki", np.asarray(cubie_rotation, dtype=np.float64), local).reshape(-1, 3)
    world = turned @ cube_pose[:3, :3].T + cube_pose[:3, 3]
    faces = (np.asarray(box.faces)[None] + 8 * np.arange(8)[:, None, None]).reshape(-1, 3)
    return world, faces


def _reach(hand, phi, finger: str, target, surface) -> np.ndarray:
    """``phi`` (27,) with ``finger``'s angles moved (within :data:`PHI_LIMITS`) to bring its tip to ``target``
    (hand frame, metres) while its skin stays out of the cube (``surface``: points (P, 3) -> signed distance
    (P,), hand frame, metres) but for 1.5 mm of soft tissue, weakly held near where they were."""
    idx = [i for i, n in enumerate(PHI_NAMES) if n.startswith(finger + "_")]
    lo, hi = PHI_LIMITS[idx, 0], PHI_LIMITS[idx, 1]
    segments = [hand.segment_id(f"{finger}_{s}") for s in ("proximal", "middle", "distal")]
    skin = np.flatnonzero(np.isin(hand.segment_of_vertex, segments))[::3]

    def residuals(trials):
        """The residuals (N, R) of N sets of the finger's angles (N, n), in one pass of the hand model."""
        full = np.repeat(phi[None], len(trials), axis=0)
        full[:, idx] = trials
        out = hand.forward(phi=full)
        inside = np.minimum(surface(out.vertices[:, skin].reshape(-1, 3)).reshape(len(trials), -1) + 0.0015, 0.0)
        return np.concatenate([out.joints[:, _TIPS[finger]] - target, 0.01 * (trials - phi[idx]), 10.0 * inside],
                              axis=1)

    def jacobian(x):
        # Forward differences with least_squares' own steps (sqrt of the machine epsilon, relative, turned back
        # at the upper bound), every column in the same pass of the hand model instead of one pass each.
        step = np.sqrt(np.finfo(float).eps) * np.where(x >= 0, 1.0, -1.0) * np.maximum(1.0, np.abs(x))
        step = np.where(x + step > hi, -step, step)
        rows = residuals(np.vstack([x, x + np.diag(step)]))
        return ((rows[1:] - rows[0]) / ((x + step) - x)[:, None]).T

    fit = least_squares(lambda x: residuals(x[None])[0], np.clip(phi[idx], lo + 1e-6, hi - 1e-6), jac=jacobian,
                        bounds=(lo, hi), x_scale=0.3, max_nfev=80)
    out = phi.copy()
    out[idx] = fit.x
    return out


def turning_motion(hand, moves, rate: float, rng, *, turn_seconds: float = 0.35,
                   pause_seconds: float = 0.3) -> TurningTake:
    """The hand holding the 2x2x2 cube and turning its layers through ``moves`` (see the module docstring).

    Parameters
    ----------
    hand : HandModel
        At its average shape (``betas = 0``), which places the grasp.
    moves : str or list of (str, int)
        Standard notation or parsed moves.
    rate : float
        Frames per second; the take lasts as long as the moves need (a rest before, between and after).
    rng : numpy.random.Generator
    turn_seconds, pause_seconds : float
        See :func:`move_schedule`.

    Returns
    -------
    TurningTake
    """
    sequence = parse_moves(moves) if isinstance(moves, str) else list(moves)
    rot, angle, frames, state = move_schedule(sequence, rate, turn_seconds, pause_seconds)
    n = len(rot)
    t = np.arange(n) / rate
    object2hand, _, grasp_phi = grasp_configuration(hand, make_object("cube2x2"), "precision")
    spin = cube_rotations()[rng.integers(24)].astype(float)
    object2hand = object2hand @ homogeneous(spin, np.zeros(3))
    to_cube = np.linalg.inv(object2hand)
    tips = hand.forward(phi=grasp_phi, vertices=False).joints
    tip_in_cube = {f: to_cube[:3, :3] @ tips[j] + to_cube[:3, 3] for f, j in _TIPS.items()}
    grip = hand.forward(phi=grasp_phi).vertices
    # Finger angles: the grip, and for each move the riding finger's path along its layer; a gripping finger
    # that a turning cubie's corner would run into gives way, its tip kept where it was.
    skins, grip_depth = {}, {}
    for f in _TIPS:
        skins[f] = np.isin(hand.segment_of_vertex, [hand.segment_id(f"{f}_{s}") for s in ("proximal", "middle",
                                                                                          "distal")])
        depth = cube_signed_distance(grip[skins[f]][None], object2hand[None], solved_state()[None])[0].min()
        grip_depth[f] = min(depth, -0.0015)
    key_t, keys, riding = [0.0], [grasp_phi], []
    state = solved_state()
    for (face, turns), (first, last) in zip(sequence, frames):
        before, state = state, apply_moves(state, [(face, turns)])
        normal = np.array(FACES[face], dtype=np.float64)
        depth = {f: p @ normal for f, p in tip_in_cube.items()}
        rider = max(depth, key=depth.get)
        rider = rider if depth[rider] >= 0.004 else ""  # no fingertip on this layer: it turns on its own
        riding.append(rider)
        phi, let_go = grasp_phi, None
        key_t.append(first / rate)
        keys.append(grasp_phi)
        for u in _KEYS:
            amount = -np.pi / 2 * turns * _smoothstep(u)
            cubies = before.astype(float)
            cubies[layer(before, face)] = Rotation.from_rotvec(amount * normal).as_matrix() @ cubies[
                layer(before, face)]

            def surface(points, cubies=cubies):
                return cube_signed_distance(points[None], object2hand[None], cubies[None])[0]

            skin = hand.forward(phi=phi).vertices
            for finger in _TIPS:
                target = tip_in_cube[finger]
                if finger == rider and let_go is None:  # it follows the layer a quarter turn at most
                    target = Rotation.from_rotvec(np.clip(amount, -np.pi / 2, np.pi / 2) * normal).apply(target)
                    if abs(amount) > np.pi / 2:
                        let_go = target
                elif finger == rider:  # lifted off where it let go
                    target = let_go * (1 + 0.008 / np.linalg.norm(let_go))
                elif surface(skin[skins[finger]]).min() > grip_depth[finger] - 0.001:
                    continue
                phi = _reach(hand, phi, finger, object2hand[:3, :3] @ target + object2hand[:3, 3], surface)
                if finger == rider and let_go is None:
                    reached = to_cube[:3, :3] @ hand.forward(phi=phi, vertices=False).joints[_TIPS[finger]]
                    reached += to_cube[:3, 3]
                    if np.linalg.norm(reached - target) > 0.006:  # out of the finger's reach: it lets go
                        let_go = reached
            key_t.append((first + u * (last - first)) / rate)
            keys.append(phi)
        if rider:  # back to the grip over the layer, lifted a little off it
            if let_go is None:
                let_go = Rotation.from_rotvec(np.clip(-np.pi / 2 * turns, -np.pi / 2, np.pi / 2) * normal).apply(
                    tip_in_cube[rider])
            middle = 0.5 * (let_go + tip_in_cube[rider])
            middle *= (np.linalg.norm(middle) + 0.006) / np.linalg.norm(middle)
            cubies = state.astype(float)

            def surface(points, cubies=cubies):
                return cube_signed_distance(points[None], object2hand[None], cubies[None])[0]

            key_t.append(min(last + 0.4 * pause_seconds * rate, n - 1) / rate)
            keys.append(_reach(hand, phi, rider, object2hand[:3, :3] @ middle + object2hand[:3, 3], surface))
        key_t.append(min(last + 0.8 * pause_seconds * rate, n - 1) / rate)
        keys.append(grasp_phi)
    key_t.append(t[-1])
    keys.append(grasp_phi)
    key_t, order = np.unique(np.array(key_t), return_index=True)
    phi = spline(key_t, np.array(keys)[order], t)
    # The wrist wanders slowly with the cube in the grip; the palm faces sideways.
    n_keys = max(3, int(round(t[-1] / 0.8)) + 1)
    wrist_t = np.linspace(0.0, t[-1], n_keys)
    base = NEUTRAL * Rotation.from_rotvec([rng.choice([-1.0, 1.0]) * np.deg2rad(rng.uniform(60, 100)), 0.0, 0.0])
    rots, pos = wrist_keys(rng, n_keys, turn_deg=40.0, move=0.06, centre=WORK_CENTRE, base=base)
    motion = finish_motion(phi, rotation_path(wrist_t, rots, t), spline(wrist_t, pos, t), rng, rate)
    wrist = homogeneous(Rotation.from_rotvec(motion.global_orient).as_matrix(), motion.transl)
    cube_pose = wrist @ object2hand
    motion = Motion(motion.phi, motion.global_orient, motion.transl,
                    Rotation.from_matrix(cube_pose[:, :3, :3]).as_rotvec(), cube_pose[:, :3, 3].copy(),
                    np.ones(n, bool))
    return TurningTake(motion, cube_pose, rot, angle, sequence, frames, state, tuple(riding))
