"""Hand (and object) motions for synthetic captures.

Motions: ``calibration`` (an open hand slowly turned every way, for marker
attachment calibration), ``open-close``, ``tapping``, ``pinch``, ``grasp``
(power grasp), ``precision``, ``rotate-cube`` (in-hand rotation), ``wrist``
and ``random``. Every motion is made of key poses placed in time and joined by clamped cubic
splines (zero velocity at the ends: smooth, no jumps), plus a small
physiological tremor (band-limited noise below 6 Hz). Finger flexion follows
the usual synergies: the DIP flexes two thirds as much as the PIP, and
neighbouring fingers move together.

Object motions (:mod:`handcap.synth.grasps`) go approach, close, carry, put down,
open, leave; the hand is still between these phases (minimum-jerk moves,
:func:`rest_path`; a spline through keys that repeat would swing the hand 14-21 mm
into the object it closes on). Each finger closes until its skin touches the
object (analytic signed distance, at most 1.5 mm of soft-tissue compression), so
contacts are real and fingers pass behind the object for the cameras; while it
holds the object it rests on it: it gives way to an object turning in the
fingers, and its tremor does not press it in. Nor does the wrist's tremor press
the hand into the object standing on the table.

World frame: metres, z up; the hand works around ``WORK_CENTRE``. In the
neutral wrist pose the palm faces down and the fingers point along +x.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.interpolate import CubicSpline
from scipy.signal import butter, sosfiltfilt
from scipy.spatial.transform import Rotation, RotationSpline

from handcap.core.errors import HandcapError
from handcap.core.transforms import homogeneous
from handcap.hand.anatomy import PHI_LIMITS, PHI_NAMES, finger_flexion, relaxed_pose
from handcap.hand.anatomy import pose_from_degrees as _pose
from handcap.synth.clearance import clear_keys
from handcap.synth.grasps import FINGERS, grasp_configuration, pinch_pose, rest_on_object, steady_wrist

MOTIONS = ("calibration", "open-close", "tapping", "pinch", "grasp", "precision", "rotate-cube", "wrist", "random")
WORK_CENTRE = np.array([0.0, 0.0, 1.0])
# Model axes (x distal, y dorsal, z = x cross y) to world: palm down, fingers along +x.
NEUTRAL = Rotation.from_matrix(np.array([[1.0, 0, 0], [0, 0, -1], [0, 1, 0]]))
_I = {n: i for i, n in enumerate(PHI_NAMES)}
MIN_OBJECT_SECONDS = 2.5  # shortest take in which a hand can reach, grasp, carry and release


@dataclass(frozen=True)
class Motion:
    """A generated motion.

    Attributes
    ----------
    phi : ndarray (T, 27)
        Anatomical angles, radians.
    global_orient : ndarray (T, 3)
        Axis-angle of the wrist in the world.
    transl : ndarray (T, 3)
        Wrist joint position in the world, metres (OpenHand's wrist is its origin).
    object_rotation, object_translation : ndarray (T, 3) or None
        Object pose (axis-angle, metres) when the motion has an object.
    holding : ndarray (T,) bool
        True while the hand carries the object.
    """

    phi: np.ndarray
    global_orient: np.ndarray
    transl: np.ndarray
    object_rotation: np.ndarray | None = None
    object_translation: np.ndarray | None = None
    holding: np.ndarray | None = None


def fist_pose() -> np.ndarray:
    """A closed fist (27,) radians: every finger fully flexed, the thumb across it."""
    phi = _pose(thumb_cmc_bend=45, thumb_cmc_spread=-15, thumb_cmc_twist=15, thumb_mcp_bend=35, thumb_ip_bend=45)
    for finger in FINGERS:
        phi = finger_flexion(phi, finger, 1.0)
    return phi


def natural_pose(rng) -> np.ndarray:
    """A random pose of the kind people make: correlated flexion, modest spread and twist."""
    base = rng.uniform(0.0, 0.9)
    amounts = np.clip(base + np.cumsum(rng.normal(0, 0.12, 4)), 0.0, 1.0)
    phi = np.zeros(27)
    for finger, amount in zip(FINGERS, amounts):
        phi = finger_flexion(phi, finger, amount, mcp=rng.uniform(60, 90), pip=rng.uniform(70, 105))
        phi[_I[f"{finger}_mcp_spread"]] = np.deg2rad(rng.normal(0, 7))
        phi[_I[f"{finger}_mcp_twist"]] = np.deg2rad(rng.normal(0, 4))
    thumb = rng.uniform(0, 1)
    phi[_I["thumb_cmc_bend"]] = np.deg2rad(-10 + 55 * thumb + rng.normal(0, 8))
    phi[_I["thumb_cmc_spread"]] = np.deg2rad(rng.uniform(-25, 10))
    phi[_I["thumb_cmc_twist"]] = np.deg2rad(20 * thumb + rng.normal(0, 6))
    phi[_I["thumb_mcp_bend"]] = np.deg2rad(rng.uniform(0, 45))
    phi[_I["thumb_ip_bend"]] = np.deg2rad(rng.uniform(-5, 60))
    return np.clip(phi, PHI_LIMITS[:, 0], PHI_LIMITS[:, 1])


# -- interpolation -------------------------------------------------------------

def spline(times, values, t):
    """Clamped cubic spline through key values, zero velocity at the ends.

    Parameters
    ----------
    times : ndarray (K,)
        Seconds, increasing.
    values : ndarray (K, ...)
    t : ndarray (T,)
        Seconds to evaluate at.
    """
    return CubicSpline(times, values, axis=0, bc_type="clamped")(t)


def rotation_path(times, rotations: Rotation, t) -> Rotation:
    """A C2 spline through key orientations.

    Parameters
    ----------
    times : ndarray (K,)
        Seconds, increasing.
    rotations : Rotation (K,)
    t : ndarray (T,)
        Seconds to evaluate at.
    """
    return RotationSpline(times, rotations)(t)


def rest_path(times, values, t):
    """Minimum-jerk moves from key to key, at rest at every key (zero velocity and acceleration there).

    The path a hand takes between two still poses (Flash and Hogan 1985): no overshoot, unlike a spline
    through keys that repeat (a hand that closes, holds, then carries would swing past its hold).

    Parameters
    ----------
    times : ndarray (K,)
        Seconds, increasing.
    values : ndarray (K, ...)
    t : ndarray (T,)
        Seconds to evaluate at; held at the first and last keys outside them.
    """
    times, values = np.asarray(times, dtype=np.float64), np.asarray(values, dtype=np.float64)
    k = np.clip(np.searchsorted(times, t, side="right") - 1, 0, len(times) - 2)
    u = np.clip((t - times[k]) / np.maximum(times[k + 1] - times[k], 1e-12), 0.0, 1.0)
    s = (u ** 3 * (10.0 - 15.0 * u + 6.0 * u ** 2)).reshape((-1,) + (1,) * (values.ndim - 1))
    return values[k] + s * (values[k + 1] - values[k])


def _tremor(rng, n, width, rate, amplitude, cutoff=6.0):
    """Band-limited noise (T, width) with standard deviation ``amplitude``."""
    noise = rng.normal(size=(n + 64, width))
    sos = butter(2, min(cutoff / (rate / 2), 0.99), output="sos")
    smooth = sosfiltfilt(sos, noise, axis=0)[32:32 + n]
    return smooth / max(smooth.std(), 1e-12) * amplitude


def wrist_keys(rng, n_keys, *, turn_deg=25.0, move=0.05, centre=WORK_CENTRE, base=NEUTRAL):
    """``n_keys`` wrist orientations about ``base`` (spread ``turn_deg`` degrees) and positions about ``centre``
    (spread ``move`` metres), drawn from ``rng``.

    Parameters
    ----------
    rng : numpy.random.Generator
    n_keys : int
    turn_deg, move : float
        Twice the standard deviation of the turn (degrees, per axis) and of the position (metres, per axis).
    centre, base : ndarray (3,) (metres) and Rotation

    Returns
    -------
    rotations : Rotation (n_keys,)
    positions : ndarray (n_keys, 3)
    """
    rots = [base * Rotation.from_rotvec(np.deg2rad(rng.normal(0, turn_deg / 2, 3))) for _ in range(n_keys)]
    pos = [centre + rng.normal(0, move / 2, 3) for _ in range(n_keys)]
    return Rotation.concatenate(rots), np.array(pos)


# -- motions -----------------------------------------------------------------

def make_motion(name: str, hand, n_frames: int, rate: float, rng, obj=None, *, betas=None) -> Motion:
    """Generate one of :data:`MOTIONS`.

    Parameters
    ----------
    name : str
    hand : HandModel
    n_frames : int
    rate : float
        Frames per second.
    rng : numpy.random.Generator
    obj : SynthObject, optional
        Needed by ``grasp``, ``precision`` and ``rotate-cube``.
    betas : ndarray (10,), optional
        The hand's shape, for which grasps are planned (the average hand when omitted).
    """
    if name not in MOTIONS:
        raise HandcapError(f"unknown motion {name!r}; choose one of {', '.join(MOTIONS)}")
    if n_frames < 2:
        raise HandcapError(f"a motion needs at least 2 frames, got {n_frames}")
    t = np.arange(n_frames) / rate
    duration = max(t[-1], 1e-6)
    object_motion = name in ("grasp", "precision", "rotate-cube")
    if object_motion and obj is None:
        raise HandcapError(f"motion {name!r} needs an object")
    if name in ("grasp", "precision", "rotate-cube"):
        if duration < MIN_OBJECT_SECONDS:
            raise HandcapError(f"motion {name!r} needs at least {MIN_OBJECT_SECONDS:g} s to reach, grasp, carry and "
                               f"release; {n_frames} frames at {rate:g} Hz span {duration:.2f} s (first to last): give "
                               f"{int(np.ceil(MIN_OBJECT_SECONDS * rate - 1e-9)) + 1} frames or more")
        return _object_motion(name, hand, t, duration, rate, rng, obj, betas)

    n_keys = max(3, int(round(duration / {"calibration": 1.0, "open-close": 0.7, "tapping": 0.2, "pinch": 0.8,
                                          "wrist": 0.7, "random": 0.6}[name])) + 1)
    key_t = np.linspace(0.0, duration, n_keys)
    relaxed = relaxed_pose()
    if name == "calibration":
        # An open hand, fingers a little apart, slowly turned every way (DexterCap section 3.4.2).
        open_hand = _pose(index_mcp_spread=-6, ring_mcp_spread=5, pinky_mcp_spread=9, thumb_cmc_spread=-8)
        keys = [open_hand + np.deg2rad(rng.normal(0, 2, 27)) for _ in range(n_keys)]
        turn, move = 80.0, 0.06
    elif name == "open-close":
        keys = [relaxed if k % 2 == 0 else fist_pose() for k in range(n_keys)]
        turn, move = 15.0, 0.03
    elif name == "tapping":
        keys = []
        for k in range(n_keys):
            phi = relaxed.copy()
            if k % 2 == 1:
                finger = FINGERS[(k // 2) % 4]
                phi = finger_flexion(phi, finger, 0.55, mcp=70, pip=60)
            keys.append(phi)
        turn, move = 5.0, 0.01
    elif name == "pinch":
        keys = []
        for k in range(n_keys):
            keys.append(relaxed if k % 2 == 0 else pinch_pose(hand, FINGERS[(k // 2) % 4], relaxed))
        turn, move = 15.0, 0.03
    else:  # keys drawn at random: drawn again where they would put two fingers in one place
        def draw():
            return relaxed + np.deg2rad(rng.normal(0, 3, 27)) if name == "wrist" else natural_pose(rng)
        keys = [draw() for _ in range(n_keys)]
        turn, move = (70.0, 0.15) if name == "wrist" else (35.0, 0.08)
    phi = clear_keys(hand, keys, key_t, t, draw, spline) if name in ("wrist", "random") else spline(
        key_t, np.array(keys), t)
    rots, pos = wrist_keys(rng, n_keys, turn_deg=turn, move=move)
    orient = rotation_path(key_t, rots, t)
    transl = spline(key_t, pos, t)
    return finish_motion(phi, orient, transl, rng, rate)


def finish_motion(phi, orient: Rotation, transl, rng, rate):
    """A :class:`Motion` from smooth angles (T, 27), wrist orientations (T rotations) and positions (T, 3), with a
    physiological tremor added (angles 0.4 degrees, wrist 0.3 degrees and 0.4 mm, below 6 Hz).

    Parameters
    ----------
    phi : ndarray (T, 27)
        Radians; clipped to :data:`PHI_LIMITS` after the tremor.
    orient, transl : Rotation (T,) and ndarray (T, 3)
    rng : numpy.random.Generator
    rate : float
        Frames per second.
    """
    n = len(phi)
    phi = phi + _tremor(rng, n, 27, rate, np.deg2rad(0.4))
    phi = np.clip(phi, PHI_LIMITS[:, 0], PHI_LIMITS[:, 1])
    orient = orient * Rotation.from_rotvec(_tremor(rng, n, 3, rate, np.deg2rad(0.3)))
    transl = transl + _tremor(rng, n, 3, rate, 0.0004)
    return Motion(phi, orient.as_rotvec(), transl)


def _object_motion(name, hand, t, duration, rate, rng, obj, betas) -> Motion:
    kind = "power" if name == "grasp" else "precision"
    # Each take's grasp is one person's of many; the cube turned in the fingers keeps the planned pinch (drawn like
    # the others, its turning corners swept up to 6.5 mm into the fingers over 64 takes of 4 s, against 2.8 mm).
    object2hand, open_phi, grasp_phi = grasp_configuration(hand, obj, kind, betas=betas,
                                                           rng=None if name == "rotate-cube" else rng)
    # Timeline (fractions of the take): approach, close, carry, put down, open, leave. The hand is still at each
    # phase's start and end: it moves to the object, stops, closes, carries it (a smooth course through the
    # carry's keys), stops, opens, leaves.
    f = np.array([0.0, 0.15, 0.28, 0.82, 0.92, 1.0]) * duration
    n_carry = max(2, int(round((f[3] - f[2]) / 0.7)))
    tilt = Rotation.from_rotvec(np.deg2rad(rng.normal(0, 10, 3)))
    table_pose = homogeneous((NEUTRAL * tilt).as_matrix() @ object2hand[:3, :3],
                             WORK_CENTRE + np.array([0.0, 0.0, -0.08]) + rng.normal(0, 0.02, 3) * [1, 1, 0])
    wrist_at_grasp = table_pose @ np.linalg.inv(object2hand)
    grasp_rot = Rotation.from_matrix(wrist_at_grasp[:3, :3])
    grasp_pos = wrist_at_grasp[:3, 3]
    up = np.array([0.0, 0.0, 1.0])
    carry_rot, carry_pos = wrist_keys(rng, n_carry, turn_deg=50.0, move=0.1, centre=grasp_pos + 0.12 * up,
                                       base=grasp_rot)
    put_down = carry_pos[-1].copy()
    put_down[2] = grasp_pos[2]
    # The hand comes onto the object and leaves it straight, along the line from the object to the wrist, turning
    # only once its fingers are clear of it, the object's size away (turned near the object, or moved straight up
    # with the hand turned, a relaxed finger swept 8 mm into it).
    above = (0.5 * (f[0] + f[1]), 0.5 * (f[4] + f[5]))
    clear = 2.0 * float(np.max(obj.size)) + 0.01
    away = -object2hand[:3, 3] / np.linalg.norm(object2hand[:3, 3])  # in the hand's frame
    key_t = np.concatenate([[f[0], above[0], f[1], f[2]], np.linspace(f[2], f[3], n_carry + 2)[1:-1],
                            [f[3], f[4], above[1], f[5]]])
    lift = Rotation.from_rotvec([0.3, 0.0, 0.0])
    rots = Rotation.concatenate([grasp_rot * lift, grasp_rot, grasp_rot, grasp_rot, carry_rot, carry_rot[-1],
                                 carry_rot[-1], carry_rot[-1], carry_rot[-1] * lift])
    approach = grasp_pos + clear * grasp_rot.apply(away) + 0.06 * up + grasp_rot.apply([-0.06, 0.0, 0.0])
    off = put_down + clear * carry_rot[-1].apply(away)
    pos = np.vstack([approach, grasp_pos + clear * grasp_rot.apply(away), grasp_pos, grasp_pos, carry_pos, put_down,
                     put_down, off, off + 0.06 * up])
    phi = rest_path(key_t, np.vstack([open_phi] * 3 + [grasp_phi] * (n_carry + 2) + [open_phi] * 3), t)
    carry = (t >= f[2]) & (t <= f[3])
    ends = slice(3, 5 + n_carry)  # the carry's keys, from the grasp to the put-down

    def course(values):
        out = rest_path(key_t, values, t)
        out[carry] = spline(key_t[ends], values[ends], t[carry])
        return out

    # Orientations as turns from the grasp's (under 180 degrees: the carry's spread is 50).
    orient = grasp_rot * Rotation.from_rotvec(course((grasp_rot.inv() * rots).as_rotvec()))
    transl = course(pos)
    motion = finish_motion(phi, orient, transl, rng, rate)
    # The object: on the table, then carried rigidly (turning half a turn in the fingers for
    # rotate-cube), then put down.
    wrist = np.zeros((len(t), 4, 4))
    wrist[:, :3, :3] = Rotation.from_rotvec(motion.global_orient).as_matrix()
    wrist[:, :3, 3] = motion.transl
    wrist[:, 3, 3] = 1.0
    in_hand = np.repeat(object2hand[None], len(t), axis=0)
    if name == "rotate-cube":  # about the axis through the centres of the faces pinched (the thumb's and fingers')
        joints = hand.forward(betas, phi=grasp_phi, vertices=False).joints
        pinch = joints[16] - 0.5 * (joints[17] + joints[18])
        normals = object2hand[:3, :3].T @ pinch  # the pinch in the object's frame: its faces' normals are its axes
        axis = object2hand[:3, :3][:, np.argmax(np.abs(normals))]
        pivot = object2hand[:3, 3]
        progress = np.clip((t - f[2]) / max(f[3] - f[2], 1e-9), 0, 1)
        angle = np.deg2rad(180.0) * (0.5 - 0.5 * np.cos(np.pi * progress))
        turn = Rotation.from_rotvec(angle[:, None] * axis).as_matrix()
        spin = homogeneous(turn, pivot - np.einsum("tij,j->ti", turn, pivot))
        in_hand = spin @ in_hand
    carried = wrist @ in_hand
    first, last = np.flatnonzero(carry)[[0, -1]]
    obj_pose = carried.copy()
    obj_pose[:first] = carried[first]
    obj_pose[last + 1:] = carried[last]
    # Off the hand, on the table, the object cannot give way: the wrist's tremor does not press the hand into it
    # (a left hand's first phalanx went 2.6 mm into a cylinder as it closed).
    still = np.flatnonzero(~carry)
    wrist[still] = steady_wrist(hand, obj, obj_pose[still], homogeneous(orient[still].as_matrix(), transl[still]),
                                wrist[still], phi[still], betas=betas)
    motion = Motion(motion.phi, Rotation.from_matrix(wrist[:, :3, :3]).as_rotvec(), wrist[:, :3, 3].copy())
    # Fingers rest on the object: they give way to it, and their tremor does not press them in.
    fingers = rest_on_object(hand, obj, np.linalg.inv(wrist) @ obj_pose, phi, motion.phi, open_phi, rate, betas=betas)
    return Motion(fingers, motion.global_orient, motion.transl,
                  Rotation.from_matrix(obj_pose[:, :3, :3]).as_rotvec(), obj_pose[:, :3, 3], carry)
