"""Anatomical 27-DoF hand pose ``phi`` and its map to MANO's 45 axis-angle values.

Each finger joint i has a rest-pose joint frame ``C_i`` (columns: x along the
bone distal of the joint, y the direction the joint flexes towards, z the
flexion axis). A pose is ``R_i = C_i E(phi_i) C_i^T`` with
``E = Rz(bend) Ry(spread) Rx(twist)`` (intrinsic z-y'-x'', the ISB joint
coordinate system), so every angle is a true anatomical angle about a known
axis: a PIP ``bend`` of 90 degrees turns the middle phalanx 90 degrees about
the PIP flexion axis. ``R_i`` is the MANO joint rotation relative to the flat
hand; its axis-angle vector is MANO's ``hand_pose[3 i : 3 i + 3]``.

Layout of ``phi`` (27 values, radians), fingers in MANO order::

    index  MCP twist, MCP spread, MCP bend, PIP bend, DIP bend     0-4
    middle (same)                                                  5-9
    pinky  (same)                                                  10-14
    ring   (same)                                                  15-19
    thumb  CMC twist, CMC spread, CMC bend, MCP twist, MCP spread,
           MCP bend, IP bend                                       20-26

Signs, identical for both hands (the left hand's frames are mirror images):

* ``bend`` > 0 is flexion: the bone turns towards the frame's y axis (the
  palm for the fingers; across the palm, towards the little finger, for the
  thumb's CMC);
* ``spread`` > 0 turns the bone away from the frame's z axis: towards the
  little-finger side (ulnar) for the fingers; for the thumb's CMC, dorsally
  (radial abduction), so palmar abduction is negative;
* ``twist`` > 0 turns the bone about its own axis, the finger pad towards the
  thumb side.

Thumb frames: the thumb's flexion direction is the palmar direction turned
about the bone towards the little finger, by 90 degrees at the CMC (so CMC
flexion sweeps the metacarpal across the palm, the classical definition) and
45 degrees at the MCP and IP joints, whose flexion axes are oblique to the
palm (Hollister et al. 1995, doi:10.1097/00003086-199507000-00014).
"""

from __future__ import annotations

import numpy as np
from array_api_compat import array_namespace

from handcap.core.rotations import axis_angle_from_matrix, euler_zyx_from_matrix, matrix_from_axis_angle

FINGER_NAMES = ("index", "middle", "pinky", "ring", "thumb")  # MANO order
PARENTS = np.array([-1, 0, 1, 2, 0, 4, 5, 0, 7, 8, 0, 10, 11, 0, 13, 14])
JOINT_NAMES = ("wrist",) + tuple(f"{f}{k}" for f in FINGER_NAMES for k in (1, 2, 3))
TIP_NAMES = ("thumb_tip", "index_tip", "middle_tip", "ring_tip", "pinky_tip")
#: Joint whose segment each tip ends, in TIP_NAMES order.
TIP_PARENTS = np.array([15, 3, 6, 12, 9])
#: Segment i is the body moved by joint i (File contracts of DESIGN.md).
SEGMENT_NAMES = ("palm",) + tuple(f"{f}_{s}" for f in FINGER_NAMES for s in ("proximal", "middle", "distal"))

# (joint, axis) of every phi value; axis 0 twist (x), 1 spread (y), 2 bend (z).
_DOF = []
for _f in range(4):
    _j = 1 + 3 * _f
    _DOF += [(_j, 0), (_j, 1), (_j, 2), (_j + 1, 2), (_j + 2, 2)]
_DOF += [(13, 0), (13, 1), (13, 2), (14, 0), (14, 1), (14, 2), (15, 2)]
PHI_JOINT = np.array([d[0] for d in _DOF])
PHI_AXIS = np.array([d[1] for d in _DOF])
_AXIS_NAMES = ("twist", "spread", "bend")
_ANAT = {1: "mcp", 2: "pip", 3: "dip"}
_THUMB = {13: "cmc", 14: "mcp", 15: "ip"}
PHI_NAMES = tuple(
    f"thumb_{_THUMB[j]}_{_AXIS_NAMES[a]}" if j >= 13
    else f"{FINGER_NAMES[(j - 1) // 3]}_{_ANAT[(j - 1) % 3 + 1]}_{_AXIS_NAMES[a]}"
    for j, a in _DOF)
#: Joints with a single DoF (flexion only): PIP and DIP of the fingers, thumb IP.
HINGE_JOINTS = np.array([2, 3, 5, 6, 8, 9, 11, 12, 15])

THUMB_PRONATION_DEG = {13: 90.0, 14: 45.0, 15: 45.0}

_DEG = np.pi / 180
#: Default joint limits (radians), shape (27, 2). See :data:`LIMIT_SOURCES`.
PHI_LIMITS = np.zeros((27, 2))
for _i, (_j, _a) in enumerate(_DOF):
    if _j < 13:
        _kind = _ANAT[(_j - 1) % 3 + 1]
        _lim = {("mcp", 0): (-30, 30), ("mcp", 1): (-30, 30), ("mcp", 2): (-30, 90),
                ("pip", 2): (0, 110), ("dip", 2): (0, 90)}[(_kind, _a)]
    else:
        _lim = {(13, 0): (-45, 45), (13, 1): (-30, 30), (13, 2): (-30, 90),
                (14, 0): (-30, 30), (14, 1): (-30, 30), (14, 2): (0, 60), (15, 2): (-15, 90)}[(_j, _a)]
    PHI_LIMITS[_i] = np.array(_lim) * _DEG
PHI_LIMITS.setflags(write=False)

LIMIT_SOURCES = """\
Finger MCP flexion -30..90 deg (hyperextension to 30), PIP 0..110, DIP 0..90:
  American Academy of Orthopaedic Surgeons, Joint Motion: Method of Measuring
  and Recording (1965); Hume M.C. et al. (1990) J Hand Surg 15A:240-243,
  doi:10.1016/0363-5023(90)90102-W (active ranges of daily activities).
Finger MCP abduction/adduction +-30 deg and axial twist +-30 deg: passive ranges,
  Lee J., Kunii T.L. (1995) Model-based analysis of hand posture, IEEE CG&A
  15(5):77-86, doi:10.1109/38.403831; generous so fitted poses are not clamped.
Thumb CMC flexion -30..90, abduction +-30, axial rotation +-45; MCP flexion
  0..60, abduction and rotation +-30; IP -15..90: Cooney W.P. et al. (1981)
  J Bone Joint Surg 63A:1371-1381 (thumb kinematics), widened to cover the
  handcap frames' reference pose.
These are the defaults of the joint-limit penalty; pass your own (27, 2) array
to override them.
"""

DIP_PIP_RATIO = 2.0 / 3.0  # DIP flexion per unit PIP flexion (tendon coupling of the finger flexors)
_PHI_INDEX = {n: i for i, n in enumerate(PHI_NAMES)}


def pose_from_degrees(**degrees) -> np.ndarray:
    """Angles (27,) in radians from named angles in degrees (``index_pip_bend=30``); the rest zero."""
    phi = np.zeros(27)
    for name, value in degrees.items():
        phi[_PHI_INDEX[name]] = np.deg2rad(value)
    return phi


def finger_flexion(phi, finger: str, amount: float, *, mcp: float = 80.0, pip: float = 95.0) -> np.ndarray:
    """``phi`` (27,) with one finger flexed to ``amount``, its DIP coupled to the PIP by :data:`DIP_PIP_RATIO`.

    Parameters
    ----------
    phi : ndarray of shape (27,)
        Anatomical angles, radians; not changed (a copy is returned).
    finger : {"index", "middle", "ring", "pinky"}
        The finger to flex (the thumb has no PIP or DIP).
    amount : float
        0 straight .. 1 fist; scales ``mcp`` and ``pip`` linearly.
    mcp : float
        MCP flexion at ``amount`` 1, degrees.
    pip : float
        PIP flexion at ``amount`` 1, degrees.

    Returns
    -------
    phi : ndarray of shape (27,)
        Radians; the finger's MCP, PIP and DIP bend set (its other angles kept).
    """
    phi = phi.copy()
    phi[_PHI_INDEX[f"{finger}_mcp_bend"]] = np.deg2rad(mcp * amount)
    phi[_PHI_INDEX[f"{finger}_pip_bend"]] = np.deg2rad(pip * amount)
    phi[_PHI_INDEX[f"{finger}_dip_bend"]] = np.deg2rad(pip * amount) * DIP_PIP_RATIO
    return phi


def relaxed_pose() -> np.ndarray:
    """A relaxed, slightly curled hand (27,) radians: fingers 12-20 % of a fist, the thumb a little in."""
    phi = pose_from_degrees(thumb_cmc_bend=5, thumb_cmc_spread=-10, thumb_mcp_bend=10, thumb_ip_bend=10)
    for finger, amount in zip(("index", "middle", "ring", "pinky"), (0.12, 0.15, 0.18, 0.2)):
        phi = finger_flexion(phi, finger, amount)
    return phi


def hand_axes(rest_joints, is_right: bool):
    """Distal, palmar and ulnar unit vectors of a hand in its rest pose.

    Parameters
    ----------
    rest_joints : ndarray (16, 3)
        MANO joints of the flat hand, metres.
    is_right : bool

    Returns
    -------
    distal, palmar, ulnar : ndarrays (3,)
    """
    j = np.asarray(rest_joints, dtype=np.float64)
    distal = j[4] - j[0]
    distal /= np.linalg.norm(distal)
    radial = j[1] - j[7]
    radial -= distal * (radial @ distal)
    radial /= np.linalg.norm(radial)
    # Right hand: (x distal, y palmar, z radial) is right-handed, so palmar = radial x distal.
    palmar = np.cross(radial, distal) * (1.0 if is_right else -1.0)
    return distal, palmar, -radial


def joint_frames(rest_joints, rest_tips, is_right: bool) -> np.ndarray:
    """Rest-pose anatomical frames ``C_i`` of the 15 finger joints.

    Parameters
    ----------
    rest_joints : ndarray (16, 3)
    rest_tips : ndarray (5, 3)
        Thumb, index, middle, ring, pinky tips.
    is_right : bool

    Returns
    -------
    frames : ndarray (15, 3, 3)
        Columns x (bone axis, distal), y (flexion direction), z (flexion axis).
        Right-handed for the right hand; the mirror image for the left, so
        the same ``phi`` gives mirror-image poses.
    """
    joints = np.asarray(rest_joints, dtype=np.float64)
    tips = np.asarray(rest_tips, dtype=np.float64)
    _, palmar, ulnar = hand_axes(joints, is_right)
    child = {int(p): i for i, p in enumerate(PARENTS) if i > 0 and p > 0}
    tip_of = {int(j): t for t, j in enumerate(TIP_PARENTS)}
    frames = np.zeros((15, 3, 3))
    for i in range(1, 16):
        end = joints[child[i]] if i in child else tips[tip_of[i]]
        x = end - joints[i]
        x /= np.linalg.norm(x)
        if i >= 13:
            rho = np.deg2rad(THUMB_PRONATION_DEG[i])
            toward = np.cos(rho) * palmar + np.sin(rho) * ulnar
        else:
            toward = palmar
        y = toward - x * (toward @ x)
        y /= np.linalg.norm(y)
        z = np.cross(x, y) * (1.0 if is_right else -1.0)
        frames[i - 1] = np.stack([x, y, z], axis=1)
    return frames


def _euler_quaternion(twist, spread, bend):
    """Quaternion (w, x, y, z) of Rz(bend) Ry(spread) Rx(twist), shape (..., 4)."""
    xp = array_namespace(twist, spread, bend)
    cb, sb = xp.cos(bend / 2), xp.sin(bend / 2)
    cs, ss = xp.cos(spread / 2), xp.sin(spread / 2)
    ct, st = xp.cos(twist / 2), xp.sin(twist / 2)
    w = cb * cs * ct + sb * ss * st
    x = cb * cs * st - sb * ss * ct
    y = cb * ss * ct + sb * cs * st
    z = sb * cs * ct - cb * ss * st
    return xp.stack([w, x, y, z], axis=-1)


def _axis_angle_from_quaternion(q):
    xp = array_namespace(q)
    w, v = q[..., 0], q[..., 1:]
    sin_half_sq = xp.sum(v * v, axis=-1)
    small = sin_half_sq < 1e-20
    sin_half = xp.sqrt(xp.where(small, xp.ones_like(sin_half_sq), sin_half_sq))
    angle = 2.0 * xp.atan2(sin_half, w)
    # angle / sin(angle / 2) -> 2 / w as the angle goes to zero.
    scale = xp.where(small, 2.0 / w, angle / sin_half)
    return v * scale[..., None]


def hand_pose_from_phi(phi, frames):
    """MANO ``hand_pose`` (45 axis-angle values) from anatomical angles.

    Differentiable (works on numpy arrays and torch tensors).

    Parameters
    ----------
    phi : array (..., 27)
        Radians, layout in the module docstring.
    frames : array (15, 3, 3)
        Joint frames from :func:`joint_frames`.

    Returns
    -------
    hand_pose : array (..., 45)
    """
    xp = array_namespace(phi)
    frames = xp.asarray(frames, dtype=phi.dtype, device=getattr(phi, "device", None))
    zeros = xp.zeros(phi.shape[:-1], dtype=phi.dtype, device=getattr(phi, "device", None))
    angles = [[zeros, zeros, zeros] for _ in range(15)]
    for k in range(27):
        angles[int(PHI_JOINT[k]) - 1][int(PHI_AXIS[k])] = phi[..., k]
    twist = xp.stack([a[0] for a in angles], axis=-1)
    spread = xp.stack([a[1] for a in angles], axis=-1)
    bend = xp.stack([a[2] for a in angles], axis=-1)
    local = _axis_angle_from_quaternion(_euler_quaternion(twist, spread, bend))  # (..., 15, 3)
    # R = C E C^T has axis C @ axis(E) (times det C for a mirrored frame).
    det = xp.asarray(np.sign(np.linalg.det(np.asarray(frames_to_numpy(frames)))),
                     dtype=phi.dtype, device=getattr(phi, "device", None))
    world = xp.sum(frames * local[..., None, :], axis=-1) * det[:, None]
    return xp.reshape(world, phi.shape[:-1] + (45,))


def frames_to_numpy(frames) -> np.ndarray:
    """Frames as a numpy array (accepts torch tensors)."""
    return frames.detach().cpu().numpy() if hasattr(frames, "detach") else np.asarray(frames)


def phi_from_hand_pose(hand_pose, frames) -> np.ndarray:
    """Anatomical angles from MANO ``hand_pose`` (numpy; inverse of :func:`hand_pose_from_phi`).

    Exact for poses made by :func:`hand_pose_from_phi` (|spread| < 90 degrees).
    For other poses, rotations outside a hinge joint's flexion axis are
    dropped: the result is the flexion angle of the projected rotation.

    Parameters
    ----------
    hand_pose : ndarray (..., 45)
    frames : ndarray (15, 3, 3)

    Returns
    -------
    phi : ndarray (..., 27)
    """

    hand_pose = np.asarray(hand_pose, dtype=np.float64)
    frames = frames_to_numpy(frames)
    rot = matrix_from_axis_angle(hand_pose.reshape(hand_pose.shape[:-1] + (15, 3)))
    local = np.swapaxes(frames, -1, -2) @ rot @ frames
    bend, spread, twist = euler_zyx_from_matrix(local)
    by_axis = np.stack([twist, spread, bend], axis=-1)  # (..., 15, 3)
    return by_axis[..., PHI_JOINT - 1, PHI_AXIS]


def phi_from_rotations(rotations, frames) -> np.ndarray:
    """Anatomical angles from joint rotation matrices (..., 15, 3, 3) (numpy).

    Parameters
    ----------
    rotations : array_like of shape (..., 15, 3, 3)
        MANO joint rotations relative to the flat hand, joints 1 to 15.
    frames : array of shape (15, 3, 3)
        Joint frames from :func:`joint_frames` (a torch tensor is accepted).

    Returns
    -------
    phi : ndarray of shape (..., 27)
        Radians; see :func:`phi_from_hand_pose` for poses outside the hinge joints' axes.
    """
    rotations = np.asarray(rotations, dtype=np.float64)
    return phi_from_hand_pose(axis_angle_from_matrix(rotations).reshape(rotations.shape[:-3] + (45,)), frames)


def limit_violation(phi, limits=PHI_LIMITS):
    """Eq. (3) of DexterCap per value: ``clip(phi, low, high) - phi`` (differentiable).

    Works on numpy arrays and torch tensors.

    Parameters
    ----------
    phi : array of shape (..., 27)
        Anatomical angles, radians.
    limits : array_like of shape (27, 2)
        Lowest and highest angle of each value, radians.

    Returns
    -------
    array of shape (..., 27)
        Radians, of ``phi``'s type: 0 inside the limits, positive below ``low``, negative above ``high``.
    """
    xp = array_namespace(phi)
    limits = xp.asarray(np.array(limits), dtype=phi.dtype, device=getattr(phi, "device", None))
    return xp.clip(phi, limits[:, 0], limits[:, 1]) - phi
