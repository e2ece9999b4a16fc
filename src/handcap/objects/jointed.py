"""Tracking an articulated object whose parts turn on revolute joints (a hinge, scissors, pliers) from its
labelled markers and its description alone (issue 18; the 2x2x2 cube's layers are
:mod:`handcap.objects.cube_track`).

The parts and joints form a tree (:mod:`handcap.objects.articulated`): one root part, and every other part the
child of exactly one revolute joint. In every frame:

1. The root's pose is Kabsch of its markers (a marker more than :data:`OUTLIER` off the first fit is dropped
   and the fit repeated); it is the object's pose (the description's frame to the world). A frame whose root
   shows fewer than 3 markers starts from the nearest frame that had them, and is kept if step 2's joint
   refinement fits its markers within :data:`POOR_FIT`.
2. Each joint's angle, parent before child, is the rotation about the joint's axis through its origin that
   brings the child's rest markers closest to where they were seen, in the parent's frame: a least-squares
   problem in one angle with a closed form (``atan2``), so one marker of the child off the axis is enough
   when the others are hidden. Then the root's pose and every angle are refined together over all the
   frame's markers (Gauss-Newton), so that the parts steady each other.
3. Angles are unwrapped over time; a joint outside its ``limits_deg`` by more than
   :data:`LIMIT_SLACK_DEG` is reported in the warnings, as are frames in which a part's markers sit far from
   the fitted object (a joint the description does not have, or mislabelled markers).

:func:`pose_parts` is the forward kinematics both ways use (and :mod:`handcap.synth` makes takes with).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from handcap.core.errors import HandcapError
from handcap.objects.articulated import ArticulatedObject
from handcap.objects.rigid import kabsch_refit

#: A marker farther than this from the first fit of its part (metres) is dropped and the fit repeated.
OUTLIER = 0.005
#: Degrees a joint may pass its limits before a warning.
LIMIT_SLACK_DEG = 5.0
#: RMS distance (metres) of markers from the fitted object above which a frame is called a poor fit.
POOR_FIT = 0.004


def joint_order(obj: ArticulatedObject) -> tuple[str, list]:
    """The root part and the revolute joints ordered parent before child.

    Parameters
    ----------
    obj : ArticulatedObject
        Revolute joints only.

    Returns
    -------
    root : str
    joints : list of Joint

    Raises
    ------
    HandcapError
        A layers joint, a part that is the child of two joints, a loop, or parts not joined to the root.
    """
    if any(j.kind != "revolute" for j in obj.joints):
        raise HandcapError(f"{obj.name}: a layers joint is tracked as a 2x2x2 cube, not with revolute joints")
    children = [j.child for j in obj.joints]
    twice = {c for c in children if children.count(c) > 1}
    if twice:
        raise HandcapError(f"{obj.name}: part {sorted(twice)[0]!r} is the child of two joints")
    roots = [p.name for p in obj.parts if p.name not in children]
    if len(roots) != 1:
        raise HandcapError(f"{obj.name}: the joints must join every part into one tree with one root part "
                           f"(parts no joint moves: {', '.join(roots) or 'none, a loop'})")
    order, placed = [], {roots[0]}
    while len(order) < len(obj.joints):
        ready = [j for j in obj.joints if j.parent in placed and j.child not in placed]
        if not ready:
            raise HandcapError(f"{obj.name}: the joints form a loop or leave parts unjoined")
        order += ready
        placed |= {j.child for j in ready}
    return roots[0], order


def _axis_turn(axis, angle) -> np.ndarray:
    return Rotation.from_rotvec(np.outer(np.atleast_1d(angle), axis)).as_matrix()


def pose_parts(obj: ArticulatedObject, pose, angles) -> dict:
    """Every part's pose from the object's pose and its joint angles (forward kinematics).

    Parameters
    ----------
    obj : ArticulatedObject
        Revolute joints only.
    pose : ndarray (T, 4, 4)
        The description's frame (the root part's) to the world, metres.
    angles : ndarray (T, J)
        Radians, in the order of ``obj.joints``.

    Returns
    -------
    dict of str to ndarray (T, 4, 4)
        Each part's rest frame (the description's) to the world.
    """
    _, order = joint_order(obj)
    root = next(p.name for p in obj.parts if p.name not in {j.child for j in obj.joints})
    poses = {root: np.asarray(pose, dtype=np.float64)}
    index = {id(j): k for k, j in enumerate(obj.joints)}
    for j in order:
        local = np.tile(np.eye(4), (len(pose), 1, 1))
        turn = _axis_turn(j.axis, np.asarray(angles)[:, index[id(j)]])
        local[:, :3, :3] = turn
        local[:, :3, 3] = j.origin - turn @ j.origin
        poses[j.child] = poses[j.parent] @ local
    return poses


def part_markers(obj: ArticulatedObject, poses: dict) -> np.ndarray:
    """World positions of every marker from the parts' poses.

    Parameters
    ----------
    obj : ArticulatedObject
    poses : dict of str to ndarray (T, 4, 4)
        Each part's rest frame to the world (:func:`pose_parts`).

    Returns
    -------
    ndarray (T, M, 3)
        Metres, in ``obj.marker_names`` order.
    """
    return np.concatenate([np.einsum("tij,mj->tmi", poses[p.name][:, :3, :3], p.markers)
                           + poses[p.name][:, None, :3, 3] for p in obj.parts], axis=1)


@dataclass(frozen=True)
class JointedTrack:
    """What :func:`track_jointed` found.

    Attributes
    ----------
    rotation, translation : ndarray (T, 3)
        The object's pose (the root part's; axis-angle, metres), NaN where its root was not seen.
    angles : ndarray (T, J)
        Joint angles, radians, in the order of the description's joints; NaN where not measured.
    joint_names : tuple of str
        Each joint named by its child part.
    rms : ndarray (T,)
        RMS distance of the seen markers from the fitted object, metres.
    warnings : tuple of str
    """

    rotation: np.ndarray
    translation: np.ndarray
    angles: np.ndarray
    joint_names: tuple
    rms: np.ndarray
    warnings: tuple


def _hinge_angle(joint, rest, in_parent, valid) -> np.ndarray:
    """The angle (T,) about ``joint``'s axis through its origin that best moves ``rest`` (M, 3) onto
    ``in_parent`` (T, M, 3), both in the parent's rest frame; NaN where no marker off the axis is seen."""
    a = joint.axis
    u = rest - joint.origin
    u_perp = u - np.outer(u @ a, a)
    v = np.where(valid[..., None], in_parent - joint.origin, 0.0)
    cos = np.einsum("tmi,mi->t", v, u_perp)
    sin = np.einsum("tmi,mi->t", v, np.cross(a, u))
    reach = (valid * (np.linalg.norm(u_perp, axis=1) > 0.005)).sum(axis=1)
    angle = np.arctan2(sin, cos)
    angle[reach == 0] = np.nan
    return angle


def _perturbed(pose, angles, k, eps):
    """The pose (F, 4, 4) and angles (F, J) with parameter ``k`` moved by ``eps``: 0-2 a turn in the root's
    frame, 3-5 a shift, then the angles."""
    pose, angles = pose.copy(), angles.copy()
    if k < 3:
        pose[:, :3, :3] = pose[:, :3, :3] @ Rotation.from_rotvec(eps * np.eye(3)[k]).as_matrix()
    elif k < 6:
        pose[:, k - 3, 3] += eps
    else:
        angles[:, k - 6] += eps
    return pose, angles


def _refine(obj, markers, valid, pose, angles, iterations: int = 3):
    """Gauss-Newton on every frame's root pose and angles together, over all its seen markers (so the parts
    steady each other); frames already fully known only."""
    ok = np.isfinite(pose).all(axis=(1, 2)) & np.isfinite(angles).all(axis=1)
    if not ok.any():
        return pose, angles
    p, a = pose[ok], angles[ok]
    y, w = np.nan_to_num(markers[ok]), valid[ok][..., None]
    n_params = 6 + a.shape[1]
    for _ in range(iterations):
        base = part_markers(obj, pose_parts(obj, p, a))
        residual = np.where(w, base - y, 0.0).reshape(len(p), -1)
        jac = np.stack([np.where(w, part_markers(obj, pose_parts(obj, *_perturbed(p, a, k, 1e-6))) - base, 0.0)
                        .reshape(len(p), -1) / 1e-6 for k in range(n_params)], axis=2)
        normal = np.einsum("fri,frj->fij", jac, jac) + 1e-9 * np.eye(n_params)
        step = np.linalg.solve(normal, -np.einsum("fri,fr->fi", jac, residual)[..., None])[..., 0]
        p[:, :3, :3] = p[:, :3, :3] @ Rotation.from_rotvec(step[:, :3]).as_matrix()
        p[:, :3, 3] += step[:, 3:6]
        a = a + step[:, 6:]
    pose, angles = pose.copy(), angles.copy()
    pose[ok], angles[ok] = p, a
    return pose, angles


def _unwrap(angle) -> np.ndarray:
    out = angle.copy()
    ok = np.isfinite(angle)
    if ok.any():
        out[ok] = np.unwrap(angle[ok])
    return out


def track_jointed(markers, obj: ArticulatedObject) -> JointedTrack:
    """Pose and joint angles of an object with revolute joints from its labelled markers (see the module
    docstring).

    Parameters
    ----------
    markers : ndarray (T, M, 3)
        The object's markers in its description's order (``obj.marker_names``), metres, NaN where not seen.
    obj : ArticulatedObject

    Returns
    -------
    JointedTrack

    Raises
    ------
    HandcapError
        Markers of the wrong shape, a description that is not a tree of revolute joints, or a take in which
        the root part never shows 3 markers.
    """
    root, order = joint_order(obj)
    markers = np.asarray(markers, dtype=np.float64)
    if markers.ndim != 3 or markers.shape[1:] != (len(obj.marker_names), 3):
        raise HandcapError(f"{obj.name} markers must be (T, {len(obj.marker_names)}, 3), got {markers.shape}")
    n = len(markers)
    valid = np.isfinite(markers).all(axis=2)
    start = np.cumsum([0] + [len(p.marker_names) for p in obj.parts])
    cols = {p.name: slice(start[k], start[k + 1]) for k, p in enumerate(obj.parts)}
    rot, trans = kabsch_refit(obj.part(root).markers, np.nan_to_num(markers[:, cols[root]]), valid[:, cols[root]],
                              OUTLIER)
    if not np.isfinite(trans).all(axis=1).any():
        raise HandcapError(f"{obj.name}: its root part {root!r} never shows 3 markers in one frame ({n} frames)")
    index = {id(j): k for k, j in enumerate(obj.joints)}
    angles = np.full((n, len(obj.joints)), np.nan)
    frames = {root: np.tile(np.eye(4), (n, 1, 1))}
    frames[root][:, :3, :3], frames[root][:, :3, 3] = rot, trans
    for j in order:
        parent = frames[j.parent]
        seen = markers[:, cols[j.child]]
        in_parent = np.einsum("tji,tmj->tmi", parent[:, :3, :3], seen - parent[:, None, :3, 3])
        ok = valid[:, cols[j.child]] & np.isfinite(parent[:, :1, 3])
        angle = _unwrap(_hinge_angle(j, obj.part(j.child).markers, np.nan_to_num(in_parent), ok))
        angles[:, index[id(j)]] = angle
        local = np.tile(np.eye(4), (n, 1, 1))
        turn = _axis_turn(j.axis, np.nan_to_num(angle))
        local[:, :3, :3], local[:, :3, 3] = turn, j.origin - turn @ j.origin
        frames[j.child] = parent @ local
        frames[j.child][~np.isfinite(angle)] = np.nan
    pose, angles = frames[root].copy(), angles
    known = np.isfinite(pose).all(axis=(1, 2)) & np.isfinite(angles).all(axis=1)
    # a frame whose root shows too few markers starts from the nearest known one, if it has enough in all
    gap = ~known & (valid.sum(axis=1) >= max(5, (len(obj.joints) + 11) // 3 + 1))  # a margin over 6 + J
    if known.any() and gap.any():
        near = np.flatnonzero(known)[np.clip(np.searchsorted(np.flatnonzero(known), np.flatnonzero(gap)), 0,
                                             known.sum() - 1)]
        pose[gap], angles[gap] = pose[near], angles[near]
    pose, angles = _refine(obj, markers, valid, pose, angles)
    frames = pose_parts(obj, np.nan_to_num(pose), np.nan_to_num(angles))
    fitted = part_markers(obj, frames)
    err = np.where(valid, np.linalg.norm(np.nan_to_num(fitted - markers), axis=-1), np.nan)
    with np.errstate(invalid="ignore"):
        rms = np.sqrt(np.nanmean(err ** 2, axis=1)) if valid.any() else np.full(n, np.nan)
    # a gap frame stays empty unless it fits about as well as the frames that had their root
    usual = np.nanmedian(rms[known]) if np.isfinite(rms[known]).any() else POOR_FIT
    lost = ~(known | gap) | (gap & ~(rms <= min(2.0 * usual, POOR_FIT)))
    pose[lost], angles[lost], rms[lost] = np.nan, np.nan, np.nan
    angles = np.stack([_unwrap(a) for a in angles.T], axis=1) if angles.size else angles
    rot, trans = pose[:, :3, :3], pose[:, :3, 3]
    found = ~lost
    warnings = []
    poor = np.nan_to_num(rms) > POOR_FIT
    if poor.any():
        warnings.append(f"{obj.name}: in {int(poor.sum())} of {n} frames the markers sit {np.nanmax(rms) * 1000:.1f} "
                        f"mm RMS (worst) from the fitted object: a joint the description lacks, or mislabelled "
                        f"markers")
    for j in obj.joints:
        if j.limits is None:
            continue
        a = np.rad2deg(angles[:, index[id(j)]])
        lo, hi = np.rad2deg(j.limits)
        out = np.isfinite(a) & ((a < lo - LIMIT_SLACK_DEG) | (a > hi + LIMIT_SLACK_DEG))
        if out.any():
            warnings.append(f"{obj.name}: joint {j.child!r} leaves its limits [{lo:g}, {hi:g}] deg in "
                            f"{int(out.sum())} frames (from {np.nanmin(a):.0f} to {np.nanmax(a):.0f} deg)")
    missing = int((~found).sum())
    if missing:
        warnings.append(f"{obj.name}: no pose in {missing} of {n} frames (too few of its markers seen)")
    rotvec = np.full((n, 3), np.nan)
    rotvec[found] = Rotation.from_matrix(rot[found]).as_rotvec()
    return JointedTrack(rotvec, trans, angles, tuple(j.child for j in obj.joints), rms, tuple(warnings))
