"""Tracking a 2x2x2 cube turned in the hand: its pose, the angle of the turning layer, the moves (issue 18).

The cube's markers are in its description's order (eight cubies, :func:`handcap.objects.articulated.
load_articulated`). The state is every cubie's rotation in the cube's frame (:mod:`handcap.objects.cube`);
it starts as the arrangement of the first frame in which every cubie is seen (cubie DBL's pose is then the
cube's frame), and it changes only by committed moves.

1. At rest the cube's pose is Kabsch of every marker, each placed as the state has it.
2. For each axis, the two halves of the cube (the cubies on either side) are fitted on their own; the angle
   of one relative to the other about the axis is their layer's turn. A move begins where it exceeds
   :data:`MOVE_DEG` (from where it left :data:`REST_DEG`) and ends where the layer holds still at a quarter
   for :data:`HOLD_SECONDS`, so a half turn is one move and a layer turned back is none.
   The turning axis is the one along which both halves stay rigid (:func:`_bend`).
3. Which half turned: the one whose orientation departs from a smooth (quadratic in time) path over the
   move and :data:`SMOOTH_SECONDS` around it; the other half is the cube, carried smoothly by the hand. This is
   what tells a turn of D from a turn of U with the whole cube turned: both leave the same arrangement,
   and only the turning layer starts and stops.
4. The move (face, clockwise quarter turns seen from the face) is committed to the state; consecutive moves
   of one face merge (``R R`` gives ``R2``). During a move the cube's pose is its body half's, and the
   layer's angle is reported per frame.

Frames before the cube is first seen whole get its pose only. The track is checked against the cubies as each
is seen by its own markers (:mod:`handcap.objects.cube_check`): a turn missed or misread is said in
:attr:`CubeTrack.warnings`, not left silent.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.signal import savgol_filter
from scipy.spatial.transform import Rotation

from handcap.core.errors import HandcapError
from handcap.objects.articulated import ArticulatedObject
from handcap.objects.cube import FACE_ORDER, FACES, HOME, apply_moves, complete_state, format_moves, permutation
from handcap.objects.cube_start import (cubie_history, free_place, place_cubie, start_state, undo_moves, unplaced,
                                        unvouched)
from handcap.objects.cube_check import QUICK_TURN_SECONDS, check_track
from handcap.objects.rigid import kabsch_refit, smooth_pose

#: A layer within this of its last committed quarter (degrees) is at rest: the cube's spin is measured then.
REST_DEG = 3.0
#: A layer turned more than this from its last quarter (degrees) is moving: a move begins.
MOVE_DEG = 6.0
#: A move began where its layer last left this (degrees) from its quarter (its angle is measured from
#: :data:`HOLD_SECONDS` before that).
ONSET_DEG = 1.0
#: Time a layer must hold still at a quarter for its move to end (the move takes it in), seconds (5 frames at
#: 120 Hz, at least 2 frames). Counted in frames, it was a third of a second at 15 Hz: a quick hand's pause between
#: moves is shorter, and two moves merged into one (R U at 15 Hz with 0.15 s between them read as neither).
HOLD_SECONDS = 5 / 120
#: Markers per cubie (spread over it) that the search for moves looks at; a move's own frames use them all.
SEARCH_MARKERS = 8
#: Frames searched at once for the next move (more when a move outlasts them).
SPAN = 256
#: Time before and after a move over which the two halves' smoothness is compared, seconds (10 frames at 120 Hz).
#: Counted in frames at another rate, the window grew with it: at 20 Hz 10 frames are half a second each side, over
#: which the hand's carrying is no longer quadratic, and the body half's roughness came near the turning one's.
SMOOTH_SECONDS = 10 / 120
#: A marker farther than this (metres) from its fit is dropped (a swapped or misplaced label) and the pose fitted
#: again (:func:`handcap.objects.rigid.kabsch_refit`); on a cubie, one that does not fit the cubie's shape.
OUTLIER = 0.003


def cubie_poses(markers, cube: ArticulatedObject) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Every cubie's pose in every frame by Kabsch of its markers, a marker that does not fit the cubie's shape
    (more than :data:`OUTLIER` off: a label swapped with another cubie's) left out.

    Parameters
    ----------
    markers : ndarray (T, M, 3)
        The cube's markers in its description's order, metres, NaN where not seen.
    cube : ArticulatedObject
        Eight parts, in the order of :data:`handcap.objects.cube.HOME`.

    Returns
    -------
    rotation : ndarray (T, 8, 3, 3)
    translation : ndarray (T, 8, 3)
        ``world = rotation @ rest + translation``.
    seen : ndarray (T, 8) bool
        Cubies with 3 or more markers that fit their shape (elsewhere rotation and translation are NaN). With
        3 markers on a cubie, one of them misplaced spoils the fit of all: the cubie is not seen then.
    """
    markers = np.asarray(markers, dtype=np.float64)
    n = len(markers)
    rotation = np.full((n, 8, 3, 3), np.nan)
    translation = np.full((n, 8, 3), np.nan)
    seen = np.zeros((n, 8), bool)
    start = 0
    for c, part in enumerate(cube.parts):
        m = len(part.marker_names)
        obs = markers[:, start:start + m]
        start += m
        w = np.isfinite(obs).all(axis=2)
        ok = w.sum(axis=1) >= 3
        if not ok.any():
            continue
        rot, trans = kabsch_refit(part.markers, np.nan_to_num(obs[ok]), w[ok].astype(np.float64), OUTLIER)
        off = np.linalg.norm(np.einsum("fij,mj->fmi", rot, part.markers) + trans[:, None] - obs[ok], axis=-1)
        fits = np.isfinite(rot).all(axis=(1, 2)) & ((off <= OUTLIER).sum(axis=1) >= 3)
        seen[np.flatnonzero(ok)[fits], c] = True
        rotation[seen[:, c], c], translation[seen[:, c], c] = rot[fits], trans[fits]
    return rotation, translation, seen


@dataclass(frozen=True)
class CubeTrack:
    """What :func:`track_cube` found.

    Attributes
    ----------
    rotation, translation : ndarray (T, 3)
        The cube's pose (axis-angle, metres), cube frame to world; NaN where fewer than 3 markers were seen.
    layer_angle : ndarray (T, 6)
        Each face's layer angle (:data:`FACE_ORDER`) during its moves, from where the move began, radians,
        clockwise seen from the face; 0 elsewhere.
    moves : str
        The move sequence in standard notation.
    state : ndarray (8, 3, 3) int
        Every cubie's rotation in the cube's frame at the end (the identity for a cube that started solved).
    cubie_rotation : ndarray (T, 8, 3, 3)
        Every cubie's rotation in the cube's frame in every frame: the committed state at rest, the turning
        layer at its measured angle during a move.
    warnings : tuple of str
        Where the moves read may be wrong (:func:`handcap.objects.cube_check.check_track`).
    """

    rotation: np.ndarray
    translation: np.ndarray
    layer_angle: np.ndarray
    moves: str
    state: np.ndarray
    cubie_rotation: np.ndarray
    warnings: tuple = ()

    @property
    def permutation(self) -> np.ndarray:
        """The cubie (start index) at each home place at the end, (8,) int."""
        return permutation(self.state)


def _poses(local, world, weights):
    """Kabsch of ``local`` (M, 3) onto every frame's ``world`` (F, M, 3) with ``weights`` (F, M): rotations
    (F, 3, 3) and translations (F, 3); markers more than :data:`OUTLIER` off are dropped and the fit
    repeated; NaN where fewer than 3 markers weigh."""
    return kabsch_refit(local, world, weights, OUTLIER)


def _relative_angle(minus, plus, axis) -> np.ndarray:
    """Unwrapped angle (F,) of the ``plus`` half relative to the ``minus`` half about ``axis`` (a unit vector),
    radians; frames where either is missing take the last known angle."""
    ok = np.isfinite(minus).all(axis=(1, 2)) & np.isfinite(plus).all(axis=(1, 2))
    theta = np.full(len(minus), np.nan)
    if ok.any():
        rv = Rotation.from_matrix(np.einsum("fji,fjk->fik", minus[ok], plus[ok])).as_rotvec()
        theta[ok] = np.unwrap(rv @ axis)
    idx = np.where(np.isfinite(theta), np.arange(len(theta)), 0)
    np.maximum.accumulate(idx, out=idx)
    return np.nan_to_num(theta[idx]) if ok.any() else np.zeros(len(theta))


def _bend(x, world, seen, where) -> float:
    """How far the worse of two halves departs from a rigid body: the RMS distance (metres) of its seen markers
    from their rigid fit in one frame, inf where a half shows fewer than 3.

    ``x`` (M, 3) the markers in the cube's frame, ``world`` (M, 3) and ``seen`` (M,) bool one frame's, ``where``
    (M,) each marker's side of the axis (negative, positive).
    """
    worst = 0.0
    for side in (where < 0, where > 0):
        use = seen & side
        if use.sum() < 3:
            return np.inf
        # a swapped label or two (a sixth of the half's markers) may be dropped, not a layer's worth
        most = max(1, int(use.sum()) // 6)
        rot, trans = kabsch_refit(x, world[None], use[None].astype(np.float64), OUTLIER, most)
        if not np.isfinite(rot).all():
            return np.inf
        err = np.sort(np.linalg.norm(x[use] @ rot[0].T + trans[0] - world[use], axis=1))
        err = err[:len(err) - min(most, int((err > OUTLIER).sum()))]
        worst = max(worst, float(np.sqrt(np.mean(err ** 2))))
    return worst


def _roughness(rot) -> float:
    """How far rotations (F, 3, 3) depart from a smooth (quadratic in time) turn, radians: the noise for a cube
    moved by a hand, degrees for a layer that starts and stops turning.

    Robust: the median departure, of a fit repeated without the frames more than 3 times the median of those kept
    off, until they settle (a half seen by a few markers, one of them swapped into it for a few frames, jumps to the
    turning layer there).
    """
    ok = np.flatnonzero(np.isfinite(rot).all(axis=(1, 2)))
    if len(ok) < 4:
        return np.inf
    rv = Rotation.from_matrix(np.einsum("ji,fjk->fik", rot[ok[0]], rot[ok])).as_rotvec()
    basis = np.vander(ok - ok.mean(), 3)
    keep = np.ones(len(ok), bool)
    for _ in range(10):  # until the frames kept settle
        fit = np.linalg.lstsq(basis[keep], rv[keep], rcond=None)[0]
        off = np.linalg.norm(basis @ fit - rv, axis=1)
        kept = off <= 3 * np.median(off[keep])
        if kept.sum() < 4 or (kept == keep).all():
            break
        keep = kept
    return float(np.median(off))


def track_cube(markers, cube: ArticulatedObject, *, window: int = 9, rate: float = 120.0) -> CubeTrack:
    """Pose, layer angles and moves of a 2x2x2 cube from its labelled markers (see the module docstring).

    Parameters
    ----------
    markers : ndarray (T, M, 3)
        The cube's markers in its description's order, metres, NaN where not seen.
    cube : ArticulatedObject
        The cube's description (``load_articulated("cube2x2")``).
    window : int
        Frames of the quadratic Savitzky-Golay filter that smooths the cube's pose and the layers' angles
        (odd; 9 suits 100-120 Hz; below 5: none).
    rate : float
        Frames per second: :data:`SMOOTH_SECONDS` and :data:`HOLD_SECONDS` in frames (at least 2 each).

    Returns
    -------
    CubeTrack

    Raises
    ------
    HandcapError
        A description that is not a 2x2x2 cube, markers of the wrong shape, or a take in which every cubie
        is never seen at once.
    """
    if len(cube.parts) != 8 or cube.layers is None:
        raise HandcapError(f"{cube.name}: not a 2x2x2 cube (eight parts and a layers joint)")
    markers = np.asarray(markers, dtype=np.float64)
    if markers.ndim != 3 or markers.shape[1:] != (len(cube.marker_names), 3):
        raise HandcapError(f"cube markers must be (T, {len(cube.marker_names)}, 3), got {markers.shape}")
    w, w_trans, seen = cubie_poses(markers, cube)
    smooth = max(2, int(round(SMOOTH_SECONDS * rate)))
    hold = max(2, int(round(HOLD_SECONDS * rate)))  # frames
    cubie = np.repeat(np.arange(8), [len(p.marker_names) for p in cube.parts])
    rest = cube.markers
    # a marker that does not fit its cubie's shape (a label swapped with another cubie's) is not used; on a cubie
    # with fewer than 3 markers seen there is no shape to check
    valid = np.isfinite(markers).all(axis=2)
    counted = np.stack([valid[:, cubie == c].sum(axis=1) for c in range(8)], axis=1)[:, cubie] >= 3
    off = np.linalg.norm(np.einsum("tmij,mj->tmi", w[:, cubie], rest) + w_trans[:, cubie] - markers, axis=-1)
    valid &= ~counted | (off <= OUTLIER)
    world = np.nan_to_num(markers)
    n = len(markers)
    first, state, known = start_state(w, seen, world, valid, cubie, rest)
    usable = valid & known[cubie]  # the markers of cubies placed so far
    start = state.copy()
    rotation, translation = np.full((n, 3, 3), np.nan), np.full((n, 3), np.nan)
    angles = np.zeros((n, 6))
    cubies = np.repeat(start[None].astype(float), n, axis=0)
    committed: list[list] = []
    turns: list[tuple] = []  # every turn read: frames, face, the layer's rotation, quarters
    joins: list[tuple] = []  # cubies placed after the moves began to be read: cubie, frame, those placed before
    quickest = np.inf  # frames: the quickest turn read

    def local(state):
        return np.einsum("mij,mj->mi", state[cubie], rest)

    def settle(c, now, frame):
        """Cubie ``c`` placed at ``now`` (its rotation in the cube's frame) in ``frame``, where it started and its
        past from the turns read since."""
        joins.append((c, frame, known.copy()))
        state[c], known[c] = now, True
        start[c] = undo_moves(state, c, committed)
        cubies[:, c] = cubie_history(start[c], c, turns, n)
        usable[:] = valid & known[cubie]

    def join(frames):
        """Cubies not yet placed that ``frames`` (the cube at rest, its pose found) show with 2 markers."""
        for c in np.flatnonzero(~known):
            for f in frames:
                mine = (cubie == c) & valid[f]
                if mine.sum() >= 2 and np.isfinite(translation[f]).all():
                    now = place_cubie(rest[mine], world[f, mine], rotation[f], translation[f])
                    if now is not None and free_place(state, known, c, now):
                        settle(c, now, f)
                        break

    # the search for moves looks at a few markers spread over each cubie (a patched cube has dozens)
    few = np.concatenate([offset + np.unique(np.round(np.linspace(0, len(p.marker_names) - 1, SEARCH_MARKERS)))
                          for offset, p in zip(np.cumsum([0] + [len(p.marker_names) for p in cube.parts]),
                                              cube.parts)]).astype(int)

    def halves(state, a, frames, markers=slice(None)):
        """Poses of the minus and plus halves along axis ``a`` in ``frames``, and their relative angle."""
        where = np.einsum("nij,nj->ni", state, HOME)[cubie, a][markers]
        x = local(state)[markers]
        seen = usable[frames][:, markers]
        minus = _poses(x, world[frames][:, markers], seen & (where < 0))
        plus = _poses(x, world[frames][:, markers], seen & (where > 0))
        return minus, plus, _relative_angle(minus[0], plus[0], np.eye(3)[a])

    t, span = first, SPAN
    while t < n:
        frames = np.arange(t, min(t + span, n))
        theta = np.stack([halves(state, a, frames, few)[2] for a in range(3)])  # (3, F)
        moving = np.abs(theta) > np.deg2rad(MOVE_DEG)
        if not moving.any() and frames[-1] < n - 1:  # at rest throughout: on to the next stretch
            calm = slice(t, int(frames[-1]) + 1 - SPAN // 8)  # (named apart from the markers' rest places)
            rotation[calm], translation[calm] = _poses(local(state), world[calm], usable[calm].astype(float))
            cubies[calm] = state
            join(range(calm.start, calm.stop))
            t = calm.stop
            continue
        begin = int(np.argmax(moving.any(axis=0))) if moving.any() else len(frames)
        rot_all, trans_all = _poses(local(state), world[t:t + begin], usable[t:t + begin].astype(float))
        rotation[t:t + begin], translation[t:t + begin] = rot_all, trans_all  # at rest: every marker
        join(range(t, t + begin))
        if begin == len(frames):
            cubies[t:] = state
            break
        # The turning layer's axis: along it both halves stay rigid; along another, each half holds cubies of
        # the turning layer and of the still one, and bends. (The largest angle alone is not enough: with few
        # markers seen, halves that bend fit angles as large as the turn's, 7 deg against 9 at 12 Hz.)
        # Each axis is judged on every marker over the move's first 3 frames (the search's few may miss the
        # turning layer there).
        a = int(np.argmax(np.abs(theta[:, begin])))
        placed, side = local(state), np.einsum("nij,nj->ni", state, HOME)[cubie]
        bends = np.array([[_bend(placed, world[f], usable[f], side[:, k]) for f in frames[begin:begin + 3]]
                          for k in range(3)])
        bends = np.array([np.mean(b[np.isfinite(b)]) if np.isfinite(b).any() else np.inf for b in bends])
        if bends.min() <= OUTLIER:
            a = int(np.argmin(bends))
        s0 = begin
        while s0 > 0 and abs(theta[a, s0 - 1]) > np.deg2rad(ONSET_DEG):
            s0 -= 1
        s0 = max(s0 - hold, 0)  # a slow start hides in the noise: measure the layer from a little before
        # the move ends where the layer holds still at a quarter for hold frames
        off = np.abs(theta[a] - np.pi / 2 * np.round(theta[a] / (np.pi / 2)))
        still = np.convolve((off <= np.deg2rad(REST_DEG)).astype(int), np.ones(hold, int), "full")[hold - 1:]
        after = np.flatnonzero((np.arange(len(frames)) > begin) & (still >= hold))
        if (not len(after) or after[0] + hold > len(frames)) and frames[-1] < n - 1:
            span *= 2  # the move outlasts the stretch: look further
            continue
        span = SPAN
        end = min(int(after[0]) + hold, len(frames)) - 1 if len(after) else len(frames) - 1
        seg = frames[s0:end + 1]
        lo, hi = max(seg[0] - smooth, first), min(seg[-1] + smooth, n - 1)
        (m_rot, m_trans), (p_rot, p_trans), full = halves(state, a, np.arange(lo, hi + 1))
        body_is_minus = _roughness(m_rot) <= _roughness(p_rot)
        inside = slice(seg[0] - lo, seg[-1] - lo + 1)
        rotation[seg] = (m_rot if body_is_minus else p_rot)[inside]
        translation[seg] = (m_trans if body_is_minus else p_trans)[inside]
        face = ("R", "U", "F")[a] if body_is_minus else ("L", "D", "B")[a]
        # the moving half's turn about its face's outward normal is theta either way; clockwise is minus that
        progress = -full[inside]  # every marker's say, not only the search's few
        if window >= 5 and len(progress) >= window:
            progress = savgol_filter(progress, window, 2)
        angles[seg, FACE_ORDER.index(face)] = progress
        moving = np.flatnonzero((np.einsum("nij,nj->ni", state, HOME) @ np.array(FACES[face])) > 0)
        turn = Rotation.from_rotvec(np.outer(-progress, FACES[face])).as_matrix()
        cubies[t:seg[0]] = state
        cubies[seg] = state
        cubies[seg[:, None], moving] = np.einsum("fij,njk->fnik", turn, state[moving].astype(float))
        quarters = int(np.round(progress[-1] / (np.pi / 2)))
        turns.append((seg, face, turn, quarters))
        if quarters % 4:
            quickest = min(quickest, max(len(seg) - 2 * hold, 1))  # from leaving its quarter to holding the next
            state = apply_moves(state, [(face, quarters)])
            if committed and committed[-1][0] == face:
                committed[-1][1] += quarters
            else:
                committed.append([face, quarters])
        t = int(seg[-1]) + 1
    if (~known).sum() == 1:  # never seen at rest: the seven others leave it one place and one turn
        c = int(np.flatnonzero(~known)[0])
        settle(c, complete_state(state, known)[c], n - 1)
    if not known.all():
        raise unplaced(known)
    if first:  # before the cube was first seen whole: its pose only, as at the start
        rotation[:first], translation[:first] = _poses(local(start), world[:first], usable[:first].astype(float))
    rotation, translation = smooth_pose(rotation, translation, window | 1)
    found = np.isfinite(translation).all(axis=1)  # _poses leaves rotation and translation NaN together
    rotvec = np.full((n, 3), np.nan)
    rotvec[found] = Rotation.from_matrix(rotation[found]).as_rotvec()
    moves = format_moves(committed)
    quickest = quickest if np.isfinite(quickest) else QUICK_TURN_SECONDS * rate
    return CubeTrack(rotvec, translation, angles, moves, state, cubies,
                     unvouched(joins, cubies, seen, rate, first + quickest)
                     + check_track(w, seen, cubies, first, rate, moves, quickest))


def smoothing_window(rate: float) -> int:
    """Frames (odd) of the pose and angle smoothing of :func:`track_cube` for a take at ``rate`` Hz: 75 ms, 9 frames
    at 120 Hz; 1 (none) where 75 ms is under a frame and a half."""
    return max(int(round(0.075 * rate)) | 1, 1)
