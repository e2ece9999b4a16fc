"""Marker attachment calibration: where each marker sits on its segment (Eq. 1-2 of DexterCap).

From a calibration take (the subject holds an open hand and slowly turns it
so every marker is seen) and a layout, find for every marker the triangle and
barycentric coordinates on its own segment's submesh (and, optionally, its
height off the skin), together with the pose of every calibration frame:

1. Start from the layout's nominal spots; markers without one start at the
   middle of the back of their segment, only to get the first poses.
2. Solve the pose of every calibration frame with the current attachment
   (the motion solver; fingers drawn towards an open hand, as the subject was
   asked to hold one).
3. Move each observed marker into its segment's rest frame (undo that
   segment's skinning transform) and take the median over frames: a robust
   version of recomputing the closest triangle frame by frame.
4. Move each marker towards that estimate and put it at the closest point of
   its segment's submesh (segment-restricted closest point), with the normal
   distance as its offset when offsets are estimated. A marker the layout
   placed moves by :func:`relaxation` and ends at most ``MAX_SHIFT`` from its
   nominal spot; a marker without a layout position goes all the way, in the
   first round too: it starts where it was measured (issue 14: starting every
   such marker of a segment at one spot and capping its move kept a
   19-marker set at 13 mm MRE).
5. Repeat 2-4 until no marker moves by more than 0.1 mm; with ``fit_shape``,
   also refit the 10 shape values to all frames between rounds.

Shape values that end at their bounds, and a calibration MRE above
:data:`handcap.solve.motion.MRE_WARNING`, are reported as warnings stored on
the attachment (the checks of :mod:`handcap.quality.plausibility`).
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from scipy.optimize import lsq_linear

from handcap.core.errors import HandcapError
from handcap.core.geometry import closest_points_on_mesh
from handcap.core.markers import MarkerSequence
from handcap.hand import OpenHand
from handcap.hand.attachment import MarkerAttachment
from handcap.layouts import LayoutMarker, MarkerLayout
# Shape values stay within SHAPE_BOUND standard deviations of the average hand: the fit's bound and the
# plausibility check's are one number.
from handcap.quality.plausibility import SHAPE_BOUND, attach, residual_warnings, shape_warnings
from handcap.solve.lm import Poses, Priors
from handcap.solve.markers import MarkerModel
from handcap.solve.motion import MRE_WARNING, solve_lm, observed_markers

#: How strongly calibration frames are drawn to the open hand, metres per radian.
OPEN_HAND_WEIGHT = 0.02
#: Furthest a marker may end from the nominal spot its layout gives, metres (markers without one move freely).
MAX_SHIFT = 0.02


@dataclass(frozen=True)
class Calibration:
    """Result of :func:`calibrate_attachment`.

    Attributes
    ----------
    attachment : MarkerAttachment
        Carries the warnings too.
    poses : Poses
        Poses of the calibration frames used.
    frames : ndarray (F,) int
        Which frames of the input those are.
    residuals : ndarray (F, M)
        Marker errors of the final fit, metres (NaN where unobserved).
    rounds : int
    fit_shape : bool
        Whether the shape values were estimated (see :func:`shape_is_constrained`).
    warnings : tuple of str
        One-line warnings about the result (also on ``attachment``).
    """

    attachment: MarkerAttachment
    poses: Poses
    frames: np.ndarray
    residuals: np.ndarray
    rounds: int
    fit_shape: bool = False
    warnings: tuple[str, ...] = ()

    @property
    def mre(self) -> float:
        """Mean marker error of the calibration fit, metres."""
        return float(np.nanmean(self.residuals))

    def summary(self) -> str:
        """One line: markers, frames, rounds, calibration MRE and the shape values (when fitted)."""
        shape = ("shape fitted: " + " ".join(f"{b:+.2f}" for b in self.attachment.betas)) if self.fit_shape \
            else "shape not fitted (use --fit-shape)"
        return (f"{len(self.attachment)} markers from {len(self.frames)} frames, {self.rounds} rounds, "
                f"calibration MRE {1000 * self.mre:.2f} mm; {shape}")


def shape_is_constrained(layout) -> bool:
    """Whether a layout's markers say enough about the hand's proportions to fit its shape by default.

    The rule: at least three markers on the palm (its pose, hence where the
    fingers leave it, is seen from its own markers) and, on at least three of
    the five digits, markers on two or more of the digit's segments (the
    distances between them, through the joints, carry the bone lengths and,
    with the palm markers, the breadth of the palm). ``glove-13``,
    ``joints-19`` and ``dense-patches`` qualify; ``tips-5`` and ``active-9``
    (one marker per digit: a finger's length and its flexion trade off) do
    not. Whether the layout gives positions does not matter.

    Parameters
    ----------
    layout : MarkerLayout

    Returns
    -------
    bool
    """
    segments = [m.segment for m in layout.hand_markers]
    on_palm = sum(s == "palm" for s in segments)
    digits = {}
    for s in set(segments) - {"palm"}:
        digits.setdefault(s.split("_")[0], set()).add(s)
    return on_palm >= 3 and sum(len(v) >= 2 for v in digits.values()) >= 3


def offsets_measurable(layout) -> np.ndarray:
    """Whose heights off the skin a calibration measures by default (M,) bool, in ``layout.hand_markers`` order.

    Sphere markers (patches are printed on the skin: their height is the
    layout's radius) that the layout places (``position``) on a segment
    carrying three or more markers: the segment's pose is then fixed by its own
    markers and the marker's spot along the skin by the layout, so its height
    (a ball on a base or a plate, 7-20 mm on the real glove) shows in every
    frame. A lone marker's height trades off with its joint's angle, and a
    marker without a position with its spot; measured on synthetic takes,
    estimating those made the joint error worse (by 1-2 mm), so they keep the
    layout's radius.
    """
    markers = layout.hand_markers
    segments = [m.segment for m in markers]
    return np.array([layout.marker_kind == "sphere" and m.position is not None and segments.count(m.segment) >= 3
                     for m in markers], dtype=bool)


def initial_attachment(layout, hand, betas) -> MarkerAttachment:
    """The layout's nominal spots; markers without one go to the middle of the back of their segment.

    The latter are only a start for the first poses: :func:`calibrate_attachment`
    then puts each where it was measured.

    Parameters
    ----------
    layout : MarkerLayout
        Mirrored to the hand's side if needed; positions in metres on the average hand.
    hand : HandModel
    betas : ndarray (10,)
        Shape recorded on the attachment.

    Returns
    -------
    MarkerAttachment
        Offsets the layout's ``marker_radius``, metres.
    """
    layout = layout.for_side(hand.side)
    template = hand.forward().vertices
    seg = hand.segment_of_vertex
    dorsal = np.array([0.0, 1.0, 0.0])
    markers = []
    for m in layout.hand_markers:
        if m.position is None:
            verts = template[seg == hand.segment_id(m.segment)]
            centre = verts.mean(axis=0)
            # The skin point of the segment furthest towards the back, near its middle.
            score = (verts - centre) @ dorsal - 0.5 * np.linalg.norm((verts - centre) * [1, 0, 1], axis=1)
            m = LayoutMarker(m.name, m.segment, verts[np.argmax(score)], m.patch)
        markers.append(m)
    placed = MarkerLayout(layout.name, layout.side, tuple(markers), layout.rigid, layout.marker_radius,
                          layout.marker_kind, layout.description)
    return MarkerAttachment.from_layout(placed, hand, betas)


def calibrate_attachment(markers: MarkerSequence, layout, hand=None, *, betas=None, frames=None,
                         max_frames: int = 120, fit_shape: bool | None = None, estimate_offset: bool | None = None,
                         rounds: int = 30, tolerance: float = 1e-4, priors: Priors | None = None) -> Calibration:
    """Calibrate where the markers of a layout sit on the hand.

    Parameters
    ----------
    markers : MarkerSequence
        The calibration take, metres.
    layout : MarkerLayout
        The markers to calibrate (a user's own layout works like a shipped one;
        markers without a ``position`` are placed where they are measured).
    hand : HandModel, optional
        OpenHand of the layout's side by default.
    betas : ndarray (10,), optional
        Known shape (e.g. from :func:`handcap.solve.shape.betas_from_scan`); zeros by default.
    frames : slice or sequence of int, optional
        Frames of ``markers`` to use (default all).
    max_frames : int
        At most this many frames, evenly spread, are used.
    fit_shape : bool, optional
        Estimate the shape values jointly with the attachment. None (default):
        when the layout constrains them (:func:`shape_is_constrained`) and no
        ``betas`` are given.
    estimate_offset : bool, optional
        Estimate each marker's height off the skin instead of the layout's
        radius; None: for the markers :func:`offsets_measurable` names.
    rounds : int
    tolerance : float
        Stop when no marker moves more than this, metres.
    priors : Priors, optional
        Defaults pull the fingers towards the open hand (``OPEN_HAND_WEIGHT``).

    Returns
    -------
    Calibration
        With warnings (also on its attachment, and issued as
        :class:`handcap.HandcapWarning`) when shape values end at their bounds
        or the calibration MRE exceeds :data:`handcap.solve.motion.MRE_WARNING`.

    Raises
    ------
    HandcapError
        A layout marker never seen in the calibration frames, or too few frames.
    """
    if hand is None:
        hand = OpenHand(layout.side)
    layout = layout.for_side(hand.side)
    if fit_shape is None:
        fit_shape = betas is None and shape_is_constrained(layout)
    betas = np.zeros(10) if betas is None else np.asarray(betas, dtype=np.float64)
    if betas.shape != (10,) or not np.isfinite(betas).all():
        raise HandcapError(f"betas must be 10 finite numbers, got shape {betas.shape}")
    target, observed, chosen = _calibration_frames(markers, layout, frames, max_frames)
    if priors is None:
        priors = Priors(rest=np.zeros(27), rest_weight=OPEN_HAND_WEIGHT)
    attachment = initial_attachment(layout, hand, betas)
    given = np.array([m.position is not None for m in layout.hand_markers])
    free_offset = offsets_measurable(layout) if estimate_offset is None else \
        np.full(len(given), bool(estimate_offset))
    radius = layout.marker_radius
    nominal = MarkerModel(hand, attachment).rest_markers
    step = relaxation(attachment, hand)
    previous_error = np.inf
    done = 0
    for done in range(1, rounds + 1):
        model = MarkerModel(hand, attachment)
        poses = solve_lm(model, target, observed, priors, 0.01, markers.rate, 12, 60, False)
        if fit_shape:
            betas = _fit_shape(hand, attachment, poses, target, observed)
            attachment = replace(attachment, betas=betas)
            model = MarkerModel(hand, attachment)
            poses = solve_lm(model, target, observed, priors, 0.01, markers.rate, 12, 60, False)
        fit = model.positions(poses.transl, poses.rot, poses.phi)
        error = float(np.mean(np.linalg.norm(fit - np.nan_to_num(target), axis=-1)[observed]))
        if step == 1.0 and error > 0.98 * previous_error:
            break  # sparse layout: the fit no longer improves (see relaxation)
        previous_error = error
        measured = rest_frame_medians(model, poses, target, observed)
        # Placed markers move part of the way (relaxation) and no further than MAX_SHIFT from their nominal
        # spots; markers without a layout position go where they were measured.
        goal = model.rest_markers + step * (measured - model.rest_markers)
        away = goal - nominal
        far = np.linalg.norm(away, axis=1, keepdims=True)
        capped = nominal + away * np.minimum(1.0, MAX_SHIFT / np.maximum(far, 1e-12))
        goal = np.where(given[:, None], capped, measured if done == 1 else goal)
        updated = _reattach(model, hand, attachment, goal, radius, free_offset)
        moved = np.linalg.norm(MarkerModel(hand, updated).rest_markers - model.rest_markers, axis=1).max()
        attachment = updated
        if moved < tolerance:
            break
    if fit_shape:
        # The shape fit's steps (lsq_linear's trust region) end just inside a bound: a value that ended within 0.02
        # of one is on it (and is reported so). Only at the end: snapping between rounds would change the rounds'
        # path.
        stuck = np.abs(attachment.betas) > SHAPE_BOUND - 0.02
        attachment = replace(attachment, betas=np.where(stuck, np.sign(attachment.betas) * SHAPE_BOUND,
                                                        attachment.betas))
    model = MarkerModel(hand, attachment)
    poses = solve_lm(model, target, observed, priors, 0.01, markers.rate, 12, 60, False)
    fit = model.positions(poses.transl, poses.rot, poses.phi)
    residuals = np.where(observed, np.linalg.norm(fit - np.nan_to_num(target), axis=-1), np.nan)
    messages = calibration_warnings(attachment.betas if fit_shape else None, residuals, attachment.marker_names)
    attachment = attach(attachment, messages)
    return Calibration(attachment, poses, chosen, residuals, done, bool(fit_shape), messages)


def calibration_warnings(betas, residuals, names=None) -> tuple[str, ...]:
    """Warnings about a calibration: fitted shape values at their bounds, a large MRE.

    Parameters
    ----------
    betas : ndarray (10,) or None
        Fitted shape values (None when the shape was not fitted).
    residuals : ndarray (F, M)
        Marker errors of the calibration fit, metres, NaN where unobserved.
    names : sequence of str, optional
        The M marker names, to name the markers fitted worst.

    Returns
    -------
    tuple of str
        One-line warnings (:func:`handcap.quality.plausibility.shape_warnings` and
        :func:`~handcap.quality.plausibility.residual_warnings`); not issued here.
    """
    out = [] if betas is None else shape_warnings(betas, bound=SHAPE_BOUND)
    out += residual_warnings(residuals, names=names, what="calibration MRE", limit=MRE_WARNING)
    return tuple(out)


def _calibration_frames(markers, layout, frames, max_frames):
    """Observed layout markers (F, M, 3), their mask (F, M) and frame numbers (F,) of the usable frames."""
    chosen = np.arange(markers.n_frames)[frames] if isinstance(frames, slice) else \
        (np.arange(markers.n_frames) if frames is None else np.asarray(frames, dtype=int))
    if len(chosen) > max_frames:
        chosen = chosen[np.linspace(0, len(chosen) - 1, max_frames).round().astype(int)]
    names = [m.name for m in layout.hand_markers]
    target, absent = observed_markers(markers, names)
    if absent:
        raise HandcapError(f"layout markers absent from the calibration take: {', '.join(absent)}")
    target = target[chosen]
    observed = ~np.isnan(target[..., 0])
    usable = observed.sum(axis=1) >= 3
    if usable.sum() < 3:
        raise HandcapError(f"only {usable.sum()} calibration frames show 3 or more markers; need at least 3")
    target, observed, chosen = target[usable], observed[usable], chosen[usable]
    never = [n for n, seen in zip(names, observed.any(axis=0)) if not seen]
    if never:
        raise HandcapError(f"{len(never)} of the layout's {len(names)} markers never seen in the calibration frames: "
                           f"{', '.join(never[:5])}" + (f" and {len(never) - 5} more" if len(never) > 5 else "")
                           + "; use frames where the hand shows every marker, or give --drop-unseen to calibrate the "
                           "others (dense patches: corners that no two cameras saw)")
    return target, observed, chosen


def rest_frame_medians(model, poses, target, observed) -> np.ndarray:
    """Median over frames of each observed marker moved into the rest pose (M, 3), metres.

    Each marker's own segment (largest skinning weight) is undone:
    ``x = R (r - J) + P`` gives ``r = R^T (x - P) + J``.

    Parameters
    ----------
    model : MarkerModel
        Its rest joints (the current shape) give ``J``.
    poses : Poses
        ``transl`` (T, 3) metres, ``rot`` (T, 3, 3), ``phi`` (T, 27) radians.
    target : ndarray (T, M, 3)
        Observed markers, metres (NaN allowed where not ``observed``).
    observed : ndarray (T, M) bool

    Returns
    -------
    ndarray (M, 3)
        Metres, rest pose; NaN for a marker never observed.
    """
    world_rot, world_pos, _ = model.kinematics(poses.transl, poses.rot, poses.phi)
    segment = np.argmax(model.marker_weights, axis=1)
    local = np.einsum("fmji,fmj->fmi", world_rot[:, segment], np.nan_to_num(target) - world_pos[:, segment])
    local += model.rest_joints[segment]
    local[~observed] = np.nan
    return np.nanmedian(local, axis=0)


def relaxation(attachment, hand) -> float:
    """How far each round moves the markers towards their new estimate.

    Poses and attachment are estimated in turn, which converges linearly;
    over-relaxing (1.5) halves the rounds when every marked segment carries
    at least four markers (patch layouts: each segment's pose is fixed by its
    own markers). Sparse layouts take plain steps (1.0): there the poses lean
    on the priors (an open hand), and once the fit stops improving (by 2 % a
    round) further rounds only drift the markers towards what makes the
    calibration frames look like the prior's flat hand, so they stop there.

    Parameters
    ----------
    attachment : MarkerAttachment
        A marker's segment is that of its triangle's first vertex.
    hand : HandModel

    Returns
    -------
    float
        1.5 or 1.0 (no unit).
    """
    segment = hand.segment_of_vertex[hand.faces[attachment.triangles, 0]]
    counts = np.bincount(segment, minlength=16)
    return 1.5 if counts[counts > 0].min() >= 4 else 1.0


def _reattach(model, hand, attachment, goal, radius, estimate_offset) -> MarkerAttachment:
    """New triangles, barycentric coordinates (and offsets) for markers placed at ``goal`` (rest pose).

    ``estimate_offset`` (M,) bool: whose offsets are measured; the others get ``radius``.
    """
    segment = np.argmax(model.marker_weights, axis=1)  # each marker's own segment
    median = goal
    rest_vertices, _, _ = hand.rest(attachment.betas)
    triangles = attachment.triangles.copy()
    bary = attachment.barycentric.copy()
    offset = attachment.offset.copy()
    faces = hand.faces
    tri_segment = hand.segment_of_vertex[faces]
    for seg in np.unique(segment):
        members = np.flatnonzero(segment == seg)
        own = np.flatnonzero((tri_segment == seg).all(axis=1))
        closest, face, b = closest_points_on_mesh(median[members], rest_vertices, faces[own], candidates=32)
        triangles[members] = own[face]
        bary[members] = b
        tri = rest_vertices[faces[own[face]]]
        normal = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        normal /= np.linalg.norm(normal, axis=1, keepdims=True)
        height = np.clip(((median[members] - closest) * normal).sum(axis=1), 0.0, 0.03)
        offset[members] = np.where(estimate_offset[members], height, radius)
    return MarkerAttachment(attachment.marker_names, triangles, bary, offset, attachment.betas,
                            attachment.model, attachment.side)


#: A shape value of 1 (one standard deviation) must pay for itself by this much RMS marker error, metres.
SHAPE_PRIOR = 0.0005


def _fit_shape(hand, attachment, poses: Poses, target, observed, steps: int = 4) -> np.ndarray:
    """Shape values that bring the posed markers closest to the observed ones (poses fixed).

    A Gaussian prior on the shape values (zero mean, unit deviation) keeps the
    hand average where the markers say little: moving a value by one unit must
    lower the mean square marker error by ``SHAPE_PRIOR**2``. Values stay
    within ``SHAPE_BOUND`` deviations.

    With the poses fixed, a marker moves almost linearly with the shape values (the rest vertices and joints are
    linear in them; only a marker's height along its triangle's normal is not). So one Jacobian, by forward
    differences at the start, serves every step: each step is the bounded linear least-squares problem of that
    Jacobian (``scipy.optimize.lsq_linear`` on its 10 x 10 triangular factor), kept while it lowers the cost, up
    to ``steps`` of them. On the demo's calibration take (395 markers, 100 frames, 30 rounds) the calibration
    took 58 s with least_squares making its Jacobian anew at each of its iterations (the shape fit half of
    it), 44 s with least_squares on this one Jacobian (its SVD of the whole Jacobian at each iteration then
    took a quarter), and 31-35 s with this, to the same error (0.26 mm) and shape values within 0.003.
    """
    rows = observed
    weight = SHAPE_PRIOR * np.sqrt(observed.sum())
    aim = target[rows]

    def residual(betas):
        model = MarkerModel(hand, replace(attachment, betas=betas))
        fit = model.positions(poses.transl, poses.rot, poses.phi)
        return np.concatenate([(fit[rows] - aim).ravel(), weight * betas])

    betas = np.clip(np.asarray(attachment.betas, dtype=np.float64), -SHAPE_BOUND, SHAPE_BOUND)
    now = residual(betas)
    away = np.where(betas + 1e-3 > SHAPE_BOUND, -1e-3, 1e-3)  # each difference away from the nearer bound
    jacobian = np.stack([(residual(betas + h * e) - now) / h for h, e in zip(away, np.eye(len(betas)))], axis=1)
    basis, factor = np.linalg.qr(jacobian)
    for _ in range(steps):
        move = lsq_linear(factor, -(basis.T @ now), bounds=(-SHAPE_BOUND - betas, SHAPE_BOUND - betas)).x
        trial = np.clip(betas + move, -SHAPE_BOUND, SHAPE_BOUND)
        after = residual(trial)
        if after @ after >= now @ now:
            break
        betas, now = trial, after
        if np.abs(move).max() < 1e-4:
            break
    return betas
