"""Streaming occlusion filler: call ``update`` every frame, get complete markers and the hand pose.

    filler = OcclusionFiller.load("glove-13", rate=100.0)
    for frame in stream:                 # (M, 3) metres in filler.names order, NaN = occluded
        result = filler.update(frame)    # result.markers (M, 3), result.filled (M,), result.phi (27,)

Per hand and frame (section 3 of the paper):

1. **Registration**: the visible markers are carried onto the template (Kabsch).
2. **Prediction**: the autoencoder (or a baseline: ``lk``, ``ma``, ``ac``) gives
   the occluded markers.
3. **Discontinuity on occlusion**: whenever the set of visible markers changes,
   the predictor is run on the previous frame's output with the new set, and the
   difference to that output becomes an offset added to later predictions, so
   the occluded markers do not jump (section 3.2.2, Fig. 8). Beyond the paper,
   the network's error on the hidden markers over the last 2 s is learned as a
   linear function of the visible ones and added too
   (:mod:`~handcap.occlusion.history`; ``history_s=0`` leaves it out).
4. **Re-entry**: a marker that comes back starts where its fill was heading
   (in the hand's frame) and slides onto its measurement, the offset shrinking
   at ``reentry_speed`` metres per second (the paper's 25 cm/s).
5. **Joint regression** (when the model has a regressor): the completed
   markers give the hand pose (27 anatomical angles and the wrist's pose).

Several hands share one model: each has its own state, and a hand of the other
side than the model's is mirrored (x negated) on the way in and out (section 5).
A hand with fewer than 3 visible markers cannot be registered: it is reported
``lost`` (NaN markers and pose) and its state is reset.

The streaming code is numpy only and works on one frame at a time: no torch.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from handcap.core.errors import HandcapError
from handcap.core.checks import check_rate
from handcap.core.motion import check_side
from handcap.occlusion.baselines import MA_WINDOW_S, ac_apply, ac_weights, ma_velocity
from handcap.occlusion.history import HISTORY_S, check_history, correction_stages, history_frames
from handcap.occlusion.model import OcclusionModel
from handcap.occlusion.register import Registrar

METHODS = ("nn", "ac", "lk", "ma")
REENTRY_SPEED = 0.25  # metres per second (section 3.2.2)
MIRROR = np.array([-1.0, 1.0, 1.0])  # world reflection for the other hand
MODEL_MIRROR = np.diag([1.0, 1.0, -1.0])  # the hand model's left/right reflection (layouts mirror z)


@dataclass(frozen=True)
class FillResult:
    """One frame of :meth:`OcclusionFiller.update`.

    Shapes are for one hand; with several hands every array gets a leading
    axis H (one row per hand, in the filler's order).

    Attributes
    ----------
    markers : ndarray (M, 3)
        Every marker, metres: measured, or predicted where ``filled``. NaN if ``lost``.
    filled : ndarray (M,) bool
        Markers not measured in this frame.
    phi : ndarray (27,) or None
        Anatomical angles, radians (None without a joint regressor).
    global_orient : ndarray (3,) or None
        Wrist axis-angle in the world.
    transl : ndarray (3,) or None
        Wrist position, metres.
    lost : bool
        Fewer than 3 markers were visible: nothing could be predicted.
    """

    markers: np.ndarray
    filled: np.ndarray
    phi: np.ndarray | None
    global_orient: np.ndarray | None
    transl: np.ndarray | None
    lost: bool | np.ndarray


def _pose_from_outputs(out, r, c, tc):
    """Single-frame ``outputs_to_world``: (phi (27,), wrist rotation (3, 3), transl (3,))."""
    phi = out[:27]
    ax, ay, az, bx, by, bz = out[27:33].tolist()
    n = (ax * ax + ay * ay + az * az) ** 0.5
    ax, ay, az = ax / n, ay / n, az / n
    d = ax * bx + ay * by + az * bz
    bx, by, bz = bx - d * ax, by - d * ay, bz - d * az
    n = (bx * bx + by * by + bz * bz) ** 0.5
    bx, by, bz = bx / n, by / n, bz / n
    local = np.array([[ax, bx, ay * bz - az * by], [ay, by, az * bx - ax * bz], [az, bz, ax * by - ay * bx]])
    world = r @ local
    transl = r @ (out[33:36] - tc) + c
    return phi, world, transl


def _axis_angle_of(m) -> np.ndarray:
    """Axis-angle (3,) of one rotation matrix, via its unit quaternion (robust at every angle)."""
    (m00, m01, m02), (m10, m11, m12), (m20, m21, m22) = m.tolist()
    trace = m00 + m11 + m22
    # Shepperd: build the quaternion from its largest component.
    if trace >= max(m00, m11, m22):
        w = (1.0 + trace) ** 0.5 / 2
        x, y, z = (m21 - m12) / (4 * w), (m02 - m20) / (4 * w), (m10 - m01) / (4 * w)
    elif m00 >= m11 and m00 >= m22:
        x = (1.0 + m00 - m11 - m22) ** 0.5 / 2
        w, y, z = (m21 - m12) / (4 * x), (m01 + m10) / (4 * x), (m02 + m20) / (4 * x)
    elif m11 >= m22:
        y = (1.0 + m11 - m00 - m22) ** 0.5 / 2
        w, x, z = (m02 - m20) / (4 * y), (m01 + m10) / (4 * y), (m12 + m21) / (4 * y)
    else:
        z = (1.0 + m22 - m00 - m11) ** 0.5 / 2
        w, x, y = (m10 - m01) / (4 * z), (m02 + m20) / (4 * z), (m12 + m21) / (4 * z)
    if w < 0:
        w, x, y, z = -w, -x, -y, -z
    s = (x * x + y * y + z * z) ** 0.5
    if s < 1e-12:
        return np.array([2 * x, 2 * y, 2 * z])
    angle = 2.0 * np.arctan2(s, w)
    return np.array([x, y, z]) * (angle / s)


class _HandState:
    """What one hand remembers between frames."""

    def __init__(self, n_markers: int, history: int, past: int):
        self.n = n_markers
        self.history = np.full((history, n_markers, 3), np.nan)
        self.past = np.full((past, n_markers, 3), np.nan)  # measured frames for the history correction
        self.reset()

    def reset(self):
        self.clean = None  # last output (M, 3) without re-entry residuals, world (mirrored for a mirrored hand)
        self.local = None  # ``clean`` in the hand's registered frame
        self.step = np.zeros((self.n, 3))  # last frame-to-frame change of ``local``
        self.visible = None  # (M,) bool
        self.offset = np.zeros((self.n, 3))
        self.reentry = np.zeros((self.n, 3))
        self.reentering = False
        self.ac = None  # (known index, hidden index, weights)
        self.velocity = np.zeros((self.n, 3))
        self.history[:] = np.nan
        self.head = 0
        self.past[:] = np.nan
        self.past_head = 0
        self.correction = None  # (weights (3V, 3K), reference (V, 3)) of the history correction
        self.job = None  # the correction being learned, one stage a frame
        self.reference = None  # the visible markers (V, 3) on the frame the offset was taken on


class OcclusionFiller:
    """Fill occluded markers of one or more hands, frame by frame, and regress the hand pose.

    Parameters
    ----------
    model : OcclusionModel, str or path
        A model, a shipped layout name (``"glove-13"``, ``"active-9"``) or a model ``.npz``.
    rate : float
        Frames per second of the stream (for the moving average and the re-entry decay).
    hands : sequence of {"right", "left"}
        The side of each hand in the stream (default: the model's side).
    method : {"nn", "ac", "lk", "ma"}
        The autoencoder, or one of the paper's baselines.
    reentry_speed : float
        Metres per second at which a returning marker's offset shrinks; ``inf``
        snaps at once.
    names : sequence of str, optional
        Marker names of the columns that ``update`` gets (default: the model's
        ``names``). Model markers absent here are always occluded; names the
        model does not know are an error.
    regress : bool
        Run the joint regressor (if the model has one).
    history_s : float
        Seconds before a gap from which ``nn`` learns its own error on the hidden markers
        (:mod:`~handcap.occlusion.history`); 0 uses the network and its offset alone.
    """

    def __init__(self, model, *, rate: float, hands=None, method: str = "nn", reentry_speed: float = REENTRY_SPEED,
                 names=None, regress: bool = True, history_s: float = HISTORY_S):
        self.model = OcclusionModel.resolve(model)
        self.rate = check_rate(rate)
        if method not in METHODS:
            raise HandcapError(f"unknown fill method {method!r}; choose one of {', '.join(METHODS)}")
        self.method = method
        try:
            speed = float(reentry_speed)
        except (TypeError, ValueError):
            speed = np.nan
        if not speed >= 0:
            raise HandcapError(f"reentry_speed must be a non-negative number of metres per second, "
                               f"got {reentry_speed!r}")
        self.reentry_step = speed / self.rate
        hands = (self.model.side,) if hands is None else tuple(hands)
        if not hands:
            raise HandcapError("give at least one hand")
        self.hands = tuple(check_side(h) for h in hands)
        p = self.model.predictor
        self.names = tuple(p.names)
        if names is None:
            self.columns = np.arange(len(self.names))
            self.input_names = self.names
        else:
            names = tuple(str(n) for n in names)
            unknown = [n for n in names if n not in self.names]
            if unknown:
                raise HandcapError(f"the occlusion model was not trained on marker(s) {', '.join(unknown)}; "
                                   f"it knows {', '.join(self.names)}")
            if len(set(names)) != len(names):
                raise HandcapError("marker names given twice")
            self.columns = np.array([names.index(n) if n in names else -1 for n in self.names])
            self.input_names = names
        self.regress = regress and self.model.regressor is not None
        self._absent = bool((self.columns < 0).any())
        self._reorder = self.input_names != self.names
        self._history = int(round(MA_WINDOW_S * self.rate)) + 1
        history_s = check_history(history_s)
        self._past, self._past_step = history_frames(self.rate, history_s) if method == "nn" else (0, 1)
        self._states = [_HandState(len(self.names), self._history, self._past) for _ in self.hands]
        # Cached arrays of the networks, for the one-frame path.
        self._register = Registrar(p.template, p.weights)
        self._mean, self._scale, self._inv_scale = p.mean, p.scale, 1.0 / p.scale
        self._mask_input, self._ae = p.mask_input, p.net
        self._jr = None if self.model.regressor is None else self.model.regressor.net
        self._jr_inv_scale = None if self.model.regressor is None else 1.0 / self.model.regressor.scale
        jr = self.model.regressor
        same = jr is None or (np.array_equal(jr.template, p.template) and np.array_equal(jr.weights, p.weights))
        self._regress_register = None if same else Registrar(jr.template, jr.weights)

    @classmethod
    def load(cls, model="glove-13", **options) -> "OcclusionFiller":
        """A filler for a shipped layout name or a model file (``rate`` is required)."""
        if "rate" not in options:
            raise HandcapError("give the stream's rate (frames per second)")
        return cls(model, **options)

    @property
    def n_markers(self) -> int:
        """Number of markers M the filler fills (its model's)."""
        return len(self.names)

    def reset(self) -> None:
        """Forget every hand's state (a new take begins)."""
        for s in self._states:
            s.reset()

    # ------------------------------------------------------------------ per frame
    def update(self, markers) -> FillResult:
        """Take one frame and return it completed.

        Parameters
        ----------
        markers : ndarray (K, 3) or (H, K, 3)
            Metres, NaN where occluded; K columns in the order of ``names``
            (the model's by default); one row per hand when there are several.

        Returns
        -------
        FillResult
        """
        frame = np.asarray(markers, dtype=np.float64)
        k = len(self.input_names)
        single = frame.shape == (k, 3)
        if single:
            frame = frame[None]
        if frame.shape != (len(self.hands), k, 3):
            want = f"({k}, 3)" if len(self.hands) == 1 else f"({len(self.hands)}, {k}, 3)"
            raise HandcapError(f"update takes one frame of shape {want} (hands, markers, xyz), got {frame.shape}")
        if np.isinf(frame).any():
            raise HandcapError("marker positions must be finite or NaN (missing), got infinity")
        results = [self._update_hand(i, frame[i]) for i in range(len(self.hands))]
        if single:
            return results[0]
        stack = lambda key: None if getattr(results[0], key) is None else np.stack([getattr(r, key) for r in results])  # noqa: E731
        return FillResult(stack("markers"), stack("filled"), stack("phi"), stack("global_orient"), stack("transl"),
                          np.array([r.lost for r in results]))

    def _update_hand(self, i: int, raw: np.ndarray) -> FillResult:
        state = self._states[i]
        mirrored = self.hands[i] != self.model.side
        if self._absent:
            x = np.full((self.n_markers, 3), np.nan)
            x[self.columns >= 0] = raw[self.columns[self.columns >= 0]]
        else:
            x = raw[self.columns] if self._reorder else raw
        if mirrored:
            x = x * MIRROR
        visible = ~np.isnan(x).any(axis=1)
        if np.count_nonzero(visible) < 3:
            state.reset()
            nan = np.full((self.n_markers, 3), np.nan)
            pose = (np.full(27, np.nan), np.full(3, np.nan), np.full(3, np.nan)) if self.regress else (None,) * 3
            return FillResult(nan, ~visible, *pose, True)
        pose = self._register.fit(x, visible)
        r, c, tc = pose
        local = (x - c) @ r + tc
        hidden = ~visible
        any_hidden = not visible.all()
        changed = state.visible is not None and bool((visible != state.visible).any())

        # 1. Occluded markers.
        if any_hidden:
            local = self._fill(state, x, local, visible, hidden, changed, pose)
        if self.method == "ma":
            self._record_history(state, x)
        if self._past:
            state.past[state.past_head % self._past] = x
            state.past_head += 1

        # 2. Markers coming back slide from where they were onto their measurement. The residual is
        #    kept apart from the filled positions ("clean") and shrinks every frame, seen or not. The
        #    marker restarts where its fill was heading (last fill + its last step, in the hand's
        #    frame). A residual still left from an earlier return is dropped, not carried: a marker
        #    that flickers in and out every frame would otherwise pile up its fill errors (measured on
        #    the real glove: 9 cm after 6 s of flicker) instead of staying within one fill error.
        if changed and self.reentry_step != np.inf:
            back = visible & ~state.visible
            if back.any():
                was = state.local[back] + state.step[back]
                jump = was - local[back]
                if np.isnan(jump).any():  # a marker never seen before (baselines): no offset
                    jump = np.nan_to_num(jump)
                state.reentry[back] = jump
                state.reentering = True
        clean = (local - tc) @ r.T + c
        clean[visible] = x[visible]  # measured markers pass through exactly
        world = clean
        if state.reentering:
            norms = np.sqrt((state.reentry ** 2).sum(axis=1))
            moving = norms > 0
            world = clean.copy()
            world[moving] = (local[moving] + state.reentry[moving] - tc) @ r.T + c
            shrink = np.maximum(norms - self.reentry_step, 0.0) / np.where(moving, norms, 1.0)
            state.reentry *= shrink[:, None]
            state.reentering = bool(shrink.any())
        if state.local is not None:
            np.subtract(local, state.local, out=state.step)
        state.clean, state.local, state.visible = clean, local, visible

        # 3. Hand pose from the completed markers.
        phi = orient = transl = None
        if self.regress:
            phi, rot, transl = self._regress(world, visible, pose)
            if mirrored:
                rot = MIRROR[:, None] * rot @ MODEL_MIRROR
                transl = transl * MIRROR
            orient = _axis_angle_of(rot)
        if mirrored:
            world = world * MIRROR
        return FillResult(world, hidden, phi, orient, transl, False)

    def _fill(self, state, x, local, visible, hidden, changed, pose):
        """Registered positions with the hidden markers predicted (``local`` is overwritten there)."""
        r, c, tc = pose
        method = self.method
        if method == "nn":
            if changed:
                # Section 3.2.2: the offset that makes the prediction on the previous frame, with
                # today's visible set, land on what was output there. The previous frame is registered
                # anew on today's set: reusing its own registration, or today's, saves a fit but breaks
                # continuity (jumps of 3-9 mm on the real glove; test_no_jump catches both).
                pr, pc, ptc = self._register.fit(state.clean, visible)
                before = (state.clean - pc) @ pr + ptc
                state.offset[hidden] = before[hidden] - self._predict(before, visible)
                state.correction = None
                state.job = self._history_job(state, visible, before) if self._past else None
                state.reference = before[visible]
            elif state.visible is None:
                state.offset[:] = 0.0
                state.correction = state.job = None
            elif state.job is not None:
                try:
                    next(state.job)
                except StopIteration as done:
                    w = done.value
                    state.correction = (w, state.reference) if w.any() else None
                    state.job = None
            local[hidden] = self._predict(local, visible) + state.offset[hidden]
            if state.correction is not None:
                w, reference = state.correction
                local[hidden] += ((local[visible] - reference).ravel() @ w).reshape(-1, 3)
            return local
        if state.visible is None:  # nothing seen before: the baselines have nothing to go on
            local[hidden] = np.nan
            return local
        if method == "lk":
            world = state.clean[hidden]
        elif method == "ma":
            if changed:
                fresh = hidden & state.visible
                state.velocity[fresh] = self._velocity(state)[fresh]
            world = state.clean[hidden] + state.velocity[hidden]
        else:  # ac
            if changed or state.ac is None:
                # Markers never seen have no last position to learn weights from.
                known_i = np.flatnonzero(visible & ~np.isnan(state.clean[:, 0]))
                hidden_i = np.flatnonzero(hidden)
                w = ac_weights(state.clean[known_i], state.clean[hidden_i])
                state.ac = (known_i, hidden_i, w)
            known_i, hidden_i, w = state.ac
            world = ac_apply(w, x[known_i])
        local[hidden] = (world - c) @ r + tc
        return local

    def _predict(self, local, visible):
        """Predicted registered positions (..., K, 3) of the K hidden markers from frames ``local`` (..., M, 3).

        ``MarkerPredictor.predict_local`` with one visible set (two single rows are faster than one pair).
        """
        z = np.where(visible[:, None], (local - self._mean) * self._inv_scale, 0.0)
        z = z.reshape(z.shape[:-2] + (-1,))
        if self._mask_input:
            z = np.concatenate([z, np.broadcast_to(visible, z.shape[:-1] + visible.shape)], axis=-1)
        out = self._ae(z).reshape(z.shape[:-1] + (-1, 3)) * self._scale + self._mean
        return out[..., ~visible, :]

    def _history_job(self, state, visible, before):
        """:func:`~handcap.occlusion.history.correction_stages` for today's visible set, with the filler's fast
        registration and network; run one stage a frame from the frame after the change, so that no frame
        pays for all three (the correction applies once :data:`~handcap.occlusion.history.DELAY_FRAMES`
        frames of a gap have passed)."""
        order = (np.arange(self._past) + state.past_head) % self._past
        past = state.past[order[::-1][::self._past_step][::-1]]
        return correction_stages(past, visible, before, state.offset.copy(), self._register_many, self._predict)

    def _register_many(self, frames, visible):
        r, c, tc = self._register.fit_many(frames, visible)
        return (frames - c[:, None]) @ r + tc

    def _regress(self, world, visible, pose):
        jr = self.model.regressor
        if self._regress_register is not None:  # a regressor with a template of its own
            pose = self._regress_register.fit(world, visible)
        r, c, tc = pose
        z = (((world - c) @ r + (tc - jr.mean)) * self._jr_inv_scale).ravel()
        out = self._jr(z) * jr.out_scale + jr.out_mean
        return _pose_from_outputs(out, r, c, tc)

    def _record_history(self, state, x):
        state.history[state.head % self._history] = x
        state.head += 1

    def _velocity(self, state):
        """Mean velocity (M, 3) per frame over the recorded history (oldest first)."""
        order = (np.arange(self._history) + state.head) % self._history
        return ma_velocity(state.history[order], self.rate)
