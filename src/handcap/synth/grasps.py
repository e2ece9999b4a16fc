"""Grasps for synthetic captures: where an object sits in the hand, and fingers that rest on it, not in it.

A grasp is planned like a grasp planner's auto-grasp (:func:`close_until_contact`): the object is placed against
the open hand (:func:`grasp_configuration`), then each finger closes, all its joints together, until its skin touches
the object's analytic surface. Skin gives: a vertex may press at most :data:`SQUEEZE` (1.5 mm) into the object,
within DexterCap's 3.8 +- 3.1 mm of hand-object penetration measured on real captures (where tracking error adds
to it). A hand that holds an object keeps resting on it while its tremor goes on: :func:`rest_on_object`
holds back the part of each finger's tremor that would press it deeper, and :func:`steady_wrist` the part of the
wrist's that would press the hand into an object it does not hold (on the table, it cannot give way).

Frames: the hand model's (metres; x distal, y dorsal); ``object2hand`` maps the object's frame into it.
"""

from __future__ import annotations

import numpy as np
from scipy.ndimage import convolve1d, maximum_filter1d
from scipy.optimize import least_squares
from scipy.spatial.transform import Rotation

from handcap.core.transforms import homogeneous
from handcap.hand.anatomy import PHI_LIMITS, PHI_NAMES, finger_flexion, relaxed_pose
from handcap.hand.anatomy import pose_from_degrees as _pose

FINGERS = ("index", "middle", "ring", "pinky")
#: Deepest a vertex of the skin may press into a held object, metres (soft tissue gives).
SQUEEZE = 0.0015
#: How one person's grasp of an object differs from another's (:func:`grasp_configuration` with ``rng``): where the
#: object sits (metres, standard deviation, along the palm; the way it is pushed against the palm is planned), how
#: far a power grasp's object turns about the palm's normal (degrees, standard deviation), and each joint's pace of
#: closing (uniform range, times the planned one). Chosen as a few millimetres, a few degrees and a sixth of the
#: pace, not fitted to any take.
GRASP_VARIETY = {"shift": 0.004, "slant_deg": 10.0, "pace": (0.85, 1.15)}
_I = {n: i for i, n in enumerate(PHI_NAMES)}


def _finger_links(hand, finger: str) -> list:
    """The vertices of a digit's proximal, middle and distal phalanx (for the thumb: metacarpal, proximal, distal)."""
    return [np.flatnonzero(hand.segment_of_vertex == hand.segment_id(f"{finger}_{s}"))
            for s in ("proximal", "middle", "distal")]


def _finger_vertices(hand, finger: str) -> np.ndarray:
    return np.concatenate(_finger_links(hand, finger))


_JOINT_GROUPS = {f: ((f"{f}_mcp_twist", f"{f}_mcp_spread", f"{f}_mcp_bend"), (f"{f}_pip_bend",), (f"{f}_dip_bend",))
                 for f in FINGERS}
_JOINT_GROUPS["thumb"] = (("thumb_cmc_twist", "thumb_cmc_spread", "thumb_cmc_bend"),
                          ("thumb_mcp_twist", "thumb_mcp_spread", "thumb_mcp_bend"), ("thumb_ip_bend",))


def _pressed(hand, obj, hand2object, path, links, moving, reference, squeeze, betas):
    """Which phalanges (len(path), 3) of the poses ``path`` (P, 27) press into the object.

    A vertex may press at most ``squeeze`` in, or no deeper than ``reference`` (its depth where the path began,
    the first pose's when None): one already resting on the object may slide along it, not into it. Also returns
    the depths of the first pose.
    """
    verts = hand.forward(betas, phi=path).vertices
    depth = obj.signed_distance(verts @ hand2object[:3, :3].T + hand2object[:3, 3])
    deep = depth < np.minimum(-squeeze, depth[0] if reference is None else reference) - 1e-7
    out = np.stack([deep[:, link].any(axis=1) for link in links], axis=1)
    out[:, :moving] = False  # phalanges whose joints have stopped do not move
    return out, depth[0]


def close_until_contact(hand, obj, object2hand, open_phi, closed_phi, fingers, *, squeeze=SQUEEZE, steps=40,
                        betas=None):
    """Close each finger, all its joints together, until its skin touches the object.

    Like a grasp planner's auto-grasp (GraspIt's): every joint of a finger turns
    from its open towards its closed value at once, each at its own pace, so that
    all arrive together. When a phalanx would press deeper than ``squeeze`` into the
    object (or, if it already did, deeper than it was), the joints before it stop,
    and its own joint too when that was the first still turning; the joints after
    it go on. A finger whose first phalanx lands on the object wraps round it with
    its PIP and DIP bending together, as a human's does, not with its PIP left
    straight while the DIP alone closes; a fingertip that reached past an edge
    curls round the edge.

    Parameters
    ----------
    hand : HandModel
    obj : SynthObject
    object2hand : ndarray (4, 4)
        Object frame to hand-model frame.
    open_phi, closed_phi : ndarray (27,)
    fingers : sequence of str
        Fingers that close (others stay at ``open_phi``); ``"thumb"`` included.
    squeeze : float
        Deepest allowed skin compression, metres.
    steps : int
        Poses tried along the way from open to closed.
    betas : ndarray (10,), optional
        The hand's shape (the average hand when omitted).

    Returns
    -------
    phi : ndarray (27,)
    contact : dict finger -> bool
    """
    hand2object = np.linalg.inv(object2hand)
    phi = open_phi.copy()
    contact = {}
    for finger in fingers:
        links = _finger_links(hand, finger)  # the vertices of its proximal, middle and distal phalanx
        groups = [[_I[n] for n in group] for group in _JOINT_GROUPS[finger]]
        moving, done, touched = 0, 0.0, False  # groups before ``moving`` have stopped; the others are ``done`` closed
        while moving < len(groups) and done < 1.0:
            idx = [i for g in groups[moving:] for i in g]

            def path(at, idx=idx):  # the poses with the joints still turning at fractions ``at`` closed
                out = np.repeat(phi[None], len(at), axis=0)
                out[:, idx] = open_phi[idx] + np.asarray(at)[:, None] * (closed_phi[idx] - open_phi[idx])
                return out

            at = np.linspace(done, 1.0, max(2, int(np.ceil(steps * (1.0 - done)))))
            hits, reference = _pressed(hand, obj, hand2object, path(at), links, moving, None, squeeze, betas)
            first = np.flatnonzero(hits.any(axis=1))
            if len(first) == 0:
                phi[idx] = closed_phi[idx]
                break
            # Where between the last free pose and the first that presses in (bisection, 1/64 of a step).
            low, high = at[first[0] - 1], at[first[0]]
            hit = hits[first[0]]
            for _ in range(6):
                middle = 0.5 * (low + high)
                pressed = _pressed(hand, obj, hand2object, path([middle]), links, moving, reference, squeeze,
                                   betas)[0][0]
                low, high, hit = (low, middle, pressed) if pressed.any() else (middle, high, hit)
            phi[idx] = path([low])[0, idx]
            done, touched = low, True
            # The joints before the phalanx that touched stop; its own joint too when it was the first still
            # moving (the phalanx lies on the object): a fingertip that reached past an edge curls round it.
            link = int(np.flatnonzero(hit)[-1])
            moving = link if link > moving else link + 1
        contact[finger] = touched
    return phi, contact


def rest_on_object(hand, obj, object2hand, smooth_phi, phi, open_phi, rate, *, squeeze=SQUEEZE, betas=None):
    """Fingers that rest on the object they hold: they give way to it, and their tremor does not press them in.

    Two steps, each digit (the four fingers and the thumb) on its own:

    1. *Giving way.* Where a digit's skin in the planned pose ``smooth_phi`` lies deeper in the object than
       ``squeeze`` (an object turning in the fingers pushes them aside), the digit opens towards ``open_phi`` by
       the least fraction that keeps it out (bisection, 1/64). The fractions are then made smooth in time
       without falling below what each frame needs: the most over +-0.1 s, averaged over +-0.1 s (a Hann window).
    2. *Settling.* Where the digit with its variation (``phi - smooth_phi``: tremor) lies deeper than ``squeeze``
       (or than without it, when that is deeper), the variation is scaled down (half, a quarter, none) until it no
       longer does.

    Parameters
    ----------
    hand : HandModel
    obj : SynthObject
    object2hand : ndarray (T, 4, 4)
        Object frame to hand-model frame in each frame, metres.
    smooth_phi, phi : ndarray (T, 27)
        Radians: the planned poses, and the same with their variation (tremor).
    open_phi : ndarray (27,)
        Radians: the open hand the fingers give way towards.
    rate : float
        Frames per second.
    squeeze : float
        Deepest allowed skin compression, metres.
    betas : ndarray (10,), optional
        The hand's shape (the average hand when omitted).

    Returns
    -------
    ndarray (T, 27)
        Radians.
    """
    digits = FINGERS + ("thumb",)
    angles = [[_I[n] for group in _JOINT_GROUPS[f] for n in group] for f in digits]
    verts = [_finger_vertices(hand, f) for f in digits]
    hand2object = np.linalg.inv(object2hand)
    every = np.arange(len(phi))

    def depth(pose, rows):  # (len(rows), 5): each digit's deepest signed distance, metres
        v = hand.forward(betas, phi=pose[rows]).vertices
        local = np.einsum("tij,tvj->tvi", hand2object[rows, :3, :3], v) + hand2object[rows, None, :3, 3]
        sd = obj.signed_distance(local.reshape(-1, 3)).reshape(len(rows), -1)
        return np.stack([sd[:, i].min(axis=1) for i in verts], axis=1)

    def blend(base, towards, weight, rows):  # base with each digit's angles moved towards ``towards`` by weight
        out = base.copy()
        for d, idx in enumerate(angles):
            out[np.ix_(rows, idx)] += weight[rows, d, None] * (towards[np.ix_(rows, idx)] - base[np.ix_(rows, idx)])
        return out

    # 1. Giving way.
    planned = depth(smooth_phi, every)
    opened = np.broadcast_to(open_phi, phi.shape)
    limit = np.full_like(planned, -squeeze)
    rows = np.flatnonzero((planned < -squeeze).any(axis=1))
    if len(rows):
        limit[rows] = np.minimum(-squeeze, depth(opened, rows))
    limit -= 1e-7
    needed = (planned < limit).astype(np.float64)
    rows = np.flatnonzero(needed.any(axis=1))
    if len(rows):
        low, high = np.zeros_like(needed), needed.copy()
        for _ in range(6):
            middle = 0.5 * (low + high)
            deep = depth(blend(smooth_phi, opened, middle, rows), rows) < limit[rows]
            low[rows] = np.where(deep, middle[rows], low[rows])
            high[rows] = np.where(deep, high[rows], middle[rows])
        width = max(1, int(round(0.1 * rate)))
        window = np.hanning(2 * width + 3)[1:-1]
        needed = convolve1d(maximum_filter1d(high, 2 * width + 1, axis=0, mode="nearest"), window / window.sum(),
                            axis=0, mode="nearest")
        smooth_phi = blend(smooth_phi, opened, needed, every)
        phi = blend(phi, opened, needed, every)
        moved = np.flatnonzero(needed.any(axis=1))
        planned[moved] = depth(smooth_phi, moved)

    # 2. Settling.
    allowed = np.minimum(-squeeze, planned) - 1e-7
    keep = np.ones((len(phi), len(digits)))
    out, rows = phi.copy(), every
    for level in (0.5, 0.25, 0.0):
        pressed = depth(out, rows) < allowed[rows]
        if not pressed.any():
            break
        keep[rows] = np.where(pressed, level, keep[rows])
        rows = rows[pressed.any(axis=1)]
        out[rows] = blend(phi, smooth_phi, 1.0 - keep, rows)[rows]
    return out


def steady_wrist(hand, obj, object_pose, smooth_wrist, wrist, phi, *, squeeze=SQUEEZE, betas=None):
    """Wrist poses whose tremor does not press the hand into an object it does not hold.

    An object standing on the table cannot give way to a hand closing on it or opening off it, and a hand does
    not push into what it is about to grasp. Where the hand in its planned angles ``phi``, moved by ``wrist``,
    lies deeper in the object than ``squeeze`` (or than with ``smooth_wrist``, when that is deeper), the wrist's
    variation from ``smooth_wrist`` (its tremor: turn and shift) is scaled down, to a half, a quarter, none,
    until it no longer does. The fingers' own tremor is :func:`rest_on_object`'s.

    Parameters
    ----------
    hand : HandModel
    obj : SynthObject
    object_pose, smooth_wrist, wrist : ndarray (T, 4, 4)
        The object's pose and the hand model's frame without and with the wrist's tremor, in the world, metres.
    phi : ndarray (T, 27)
        Radians: the planned angles.
    squeeze : float
        Deepest allowed skin compression, metres.
    betas : ndarray (10,), optional
        The hand's shape (the average hand when omitted).

    Returns
    -------
    ndarray (T, 4, 4)
        ``wrist`` with its tremor held back where it pressed the hand in.
    """
    verts = hand.forward(betas, phi=phi).vertices  # (T, V, 3) in the hand model's frame
    world2object = np.linalg.inv(object_pose)
    smooth_rot = Rotation.from_matrix(smooth_wrist[:, :3, :3])
    turn = (smooth_rot.inv() * Rotation.from_matrix(wrist[:, :3, :3])).as_rotvec()
    shift = wrist[:, :3, 3] - smooth_wrist[:, :3, 3]

    def posed(scale, rows):  # the wrists with their tremor scaled by ``scale`` (len(rows),)
        rot = (smooth_rot[rows] * Rotation.from_rotvec(scale[:, None] * turn[rows])).as_matrix()
        return homogeneous(rot, smooth_wrist[rows, :3, 3] + scale[:, None] * shift[rows])

    def depth(pose, rows):  # (len(rows),): the hand's deepest signed distance, metres
        to_object = world2object[rows] @ pose
        local = np.einsum("tij,tvj->tvi", to_object[:, :3, :3], verts[rows]) + to_object[:, None, :3, 3]
        return obj.signed_distance(local.reshape(-1, 3)).reshape(len(rows), -1).min(axis=1)

    every = np.arange(len(phi))
    allowed = np.minimum(-squeeze, depth(smooth_wrist, every)) - 1e-7
    out = np.array(wrist, dtype=np.float64)
    rows = every
    for level in (0.5, 0.25, 0.0):
        pressed = depth(out[rows], rows) < allowed[rows]
        if not pressed.any():
            break
        rows = rows[pressed]
        out[rows] = posed(np.full(len(rows), level), rows)
    return out


def _place_against_palm(hand, obj, rotation, start, direction, open_phi, *, clearance=0.001, betas=None):
    """Slide the object along ``direction`` from ``start`` until the open hand's palm and fingers are clear of it."""
    thumb = np.isin(hand.segment_of_vertex, [hand.segment_id(f"thumb_{k}") for k in ("proximal", "middle", "distal")])
    skin = hand.forward(betas, phi=open_phi).vertices[~thumb]  # the thumb closes round it later
    for step in np.arange(0.0, 0.08, 0.0005):
        centre = start + step * direction
        local = (skin - centre) @ rotation
        if obj.signed_distance(local).min() >= clearance:
            break
    return homogeneous(rotation, centre)


def grasp_configuration(hand, obj, kind: str, *, betas=None, rng=None):
    """Object pose in the hand frame and the grasping pose for a power or precision grasp.

    Power: the object's long axis lies across the palm under the proximal
    phalanges, against the palm; all five digits wrap round it. Precision: the
    object sits between the thumb and the index and middle fingertips, where a
    pinch of the object's width would put it; those three close on it.

    With ``rng``, the grasp is one person's of many (:data:`GRASP_VARIETY`): the object sits a few millimetres
    elsewhere (and, in a power grasp, turned about the palm's normal, across the palm at a slant), and each joint
    closes at its own pace, so the fingers meet the object in another shape. Without it, every call gives the
    same grasp (for the same hand and object).

    Parameters
    ----------
    hand : HandModel
    obj : SynthObject
        Its ``size`` in metres sets where it is put.
    kind : str
        ``"power"``; anything else gives a precision grasp.
    betas : ndarray (10,), optional
        The hand's shape (the average hand when omitted): the grasp is planned for the hand that makes it.
    rng : numpy.random.Generator, optional
        Draws the grasp's variety.

    Returns
    -------
    object2hand : ndarray (4, 4)
        Object frame to hand-model frame, translation in metres.
    open_phi, grasp_phi : ndarray (27,)
        Radians: the hand before closing, and closed until its fingers touch the object.
    """
    palmar = np.array([0.0, -1.0, 0.0])
    ulnar = np.array([0.0, 0.0, 1.0 if hand.is_right else -1.0])
    vary = rng is not None
    shift = rng.normal(0.0, GRASP_VARIETY["shift"], 3) if vary else np.zeros(3)
    if kind == "power":
        # Object x towards the back of the hand, z along the hand's ulnar axis (turned about the palm's normal).
        slant = Rotation.from_rotvec(np.deg2rad(rng.normal(0.0, GRASP_VARIETY["slant_deg"])) * palmar) if vary \
            else Rotation.identity()
        rotation = slant.as_matrix() @ np.column_stack([-palmar, np.cross(ulnar, -palmar), ulnar])
        mcp_x = hand.rest_joints(betas)[4, 0]
        start = np.array([mcp_x + 0.012, 0.0, 0.006 * ulnar[2]]) + palmar * obj.size[0] + shift * [1, 0, 1]
        open_phi = _pose(thumb_cmc_bend=-20, thumb_cmc_spread=10, thumb_mcp_bend=5)
        for finger in FINGERS:
            open_phi = finger_flexion(open_phi, finger, 0.05)
        object2hand = _place_against_palm(hand, obj, rotation, start, palmar, open_phi, betas=betas)
        closed = _pose(thumb_cmc_bend=70, thumb_cmc_spread=-30, thumb_cmc_twist=30, thumb_mcp_bend=55,
                       thumb_ip_bend=80)
        for finger in FINGERS:
            closed = finger_flexion(closed, finger, 1.1, pip=100)
        fingers = ("index", "middle", "ring", "pinky", "thumb")
    else:
        relaxed = relaxed_pose()
        width = 2.0 * float(np.min(obj.size))
        pinch = pinch_pose(hand, "index", relaxed, gap=width + 0.012, betas=betas)
        # Thumb, index and middle open straight; the others stay relaxed.
        open_phi = relaxed.copy()
        open_phi[[i for i, n in enumerate(PHI_NAMES) if n.startswith(("thumb_", "index_", "middle_"))]] = 0.0
        joints = hand.forward(betas, phi=pinch, vertices=False).joints
        centre = 0.5 * (joints[16] + joints[17]) + 0.25 * (joints[18] - joints[17]) + shift
        object2hand = _place_against_palm(hand, obj, np.eye(3), centre, np.array([1.0, 0.0, 0.0]), open_phi,
                                          betas=betas)
        closed = pinch_pose(hand, "index", relaxed, gap=0.0, betas=betas)
        closed = finger_flexion(closed, "middle", 0.9)
        fingers = ("index", "middle", "thumb")
    if vary:  # each joint at its own pace
        low, high = GRASP_VARIETY["pace"]
        closed = np.clip(open_phi + (closed - open_phi) * rng.uniform(low, high, len(closed)), PHI_LIMITS[:, 0],
                         PHI_LIMITS[:, 1])
    grasp_phi, _ = close_until_contact(hand, obj, object2hand, open_phi, closed, fingers, betas=betas)
    return object2hand, open_phi, grasp_phi


def pinch_pose(hand, finger: str, start_phi, *, gap: float = 0.012, betas=None) -> np.ndarray:
    """Thumb and ``finger`` tips brought ``gap`` apart by least squares.

    Only the thumb's and the finger's angles move, within :data:`PHI_LIMITS`, weakly pulled towards
    ``start_phi``; the others keep their start values.

    Parameters
    ----------
    hand : HandModel
    finger : {"index", "middle", "ring", "pinky"}
    start_phi : ndarray (27,)
        Radians.
    gap : float
        Distance between the thumb's tip point and the finger's (joints 16 and 17-20), metres.
    betas : ndarray (10,), optional
        The hand's shape (the average hand when omitted).

    Returns
    -------
    ndarray (27,)
        Radians.
    """
    tips = {"index": 17, "middle": 18, "ring": 19, "pinky": 20}
    idx = [i for i, n in enumerate(PHI_NAMES) if n.startswith(("thumb_", finger + "_"))]
    lo, hi = PHI_LIMITS[idx, 0], PHI_LIMITS[idx, 1]

    def residual(x):
        phi = start_phi.copy()
        phi[idx] = x
        joints = hand.forward(betas, phi=phi, vertices=False).joints
        return np.r_[np.linalg.norm(joints[16] - joints[tips[finger]]) - gap, 0.05 * (x - start_phi[idx])]

    x0 = np.clip(start_phi[idx], lo + 1e-6, hi - 1e-6)
    fit = least_squares(residual, x0, bounds=(lo, hi), x_scale=0.3, max_nfev=200)
    phi = start_phi.copy()
    phi[idx] = fit.x
    return phi


