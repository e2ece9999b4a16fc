"""Labels untangled between fingers: a whole take's labels checked against the fingers' anatomy (issue 14).

A labeler that knows where markers usually sit around the back of the hand
can, on another subject (other proportions, other marker placement), hand a
finger's markers to the neighbouring finger for hundreds of frames: on a
synthetic joints-19 take of another subject, ``index_dip``, ``middle_dip``
and ``ring_tip`` went round in a circle over 80 % of the take, and the
offline labeler's second pass, refitted to the first pass's labels, learned
the circle. :func:`untangle` looks at what the spatial model cannot see:

- **straight fingers**: a long finger's markers lie in its flexion plane,
  which stands across the back of the hand, so seen from the back (projected
  along the normal of the rigid back-of-hand markers) they lie on a line; a
  marker of the neighbouring finger sits a finger's width (15-20 mm) off it
  (not the thumb, which flexes across the palm: its labels take part in the
  moves and are judged by the other terms);
- **constant spans**: consecutive markers of a finger (thumb too) keep their distance
  (its length on this subject is the most frequent one in the take, within
  0.8-1.25 times the training's; its spread the training's);
- **the spatial model** (trained, in the take's hand frame), and
- **continuity**: a label that changes its point between two frames jumps.

Each cost is a squared z-score capped at :data:`CAP`. For every swap of two
labels and every 3-cycle of three (of at least two fingers), the frames where
relabelling pays are found by a two-state Viterbi (label as given / as
permuted): emissions are the cost saved per frame less :data:`MARGIN`, a
switch costs the jumps it makes plus :data:`SWITCH`. The best permutation
whose total saving exceeds :data:`MIN_GAIN` is applied, and the search
repeats. Points are never added or removed: labels only change points.

:data:`MARGIN` and :data:`MIN_GAIN` were chosen on synthetic joints-19 takes of
six subjects (seeds 3-15, labelled by a model of subject 5) and checked on
five others (seeds 17-25): ``benchmarks/labeling.py`` prints both.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import numpy as np

from handcap.core.errors import HandcapError
from handcap.core.markers import MarkerSequence
from handcap.labeling.model import LabelingModel, own_shape, rigid_transforms

#: Largest cost of one term (a squared z-score): beyond 3 standard deviations evidence counts no more.
CAP = 9.0
#: Standard deviation of a finger's markers off their line, seen from the back of the hand, metres.
LINE_SD = 0.004
#: Most a finger turns at one of its markers (the joints flex up to about 110 degrees), radians, and the spread
#: of the cost beyond it.
MAX_BEND, BEND_SD = np.deg2rad(120.0), np.deg2rad(15.0)
#: Added to each span's training spread (quadrature), metres: another subject's markers sit elsewhere.
SPAN_FLOOR = 0.0015
#: A span's length on this subject is searched within these times the training's.
SPAN_BAND = (0.8, 1.25)
#: Share of the frames in the densest stretch of a span's distances (its length in the take).
SPAN_SHARE = 0.1
#: Per frame, a relabelling must save this much more than it costs (the labeler's own labels are trusted).
MARGIN = 5.0
#: Least total saving of one relabelling.
MIN_GAIN = 200.0
#: Cost of starting or ending a relabelling, on top of the jumps it makes.
SWITCH = 5.0
#: A label's last position is remembered this many frames for the jumps.
HOLD = 5
#: Frames evaluated at once (memory: candidates x frames).
CHUNK = 256


@dataclass(frozen=True)
class Untangled:
    """What :func:`untangle` changed.

    Attributes
    ----------
    markers : MarkerSequence
        The labels after the check (same points, some labels moved), metres.
    changes : tuple of (str, int, int, int)
        Per relabelling: the moves (``"index_dip<-middle_dip, ..."``: each label takes the point the other had),
        the frames relabelled, the first and the last of them.
    """

    markers: MarkerSequence
    changes: tuple

    def summary(self) -> str:
        """One line: how many labels moved in how many frames."""
        if not self.changes:
            return "fingers checked: every finger's labels consistent"
        frames = sum(c[1] for c in self.changes)
        return (f"fingers checked: {len(self.changes)} relabelling(s) over {frames} frames "
                f"({'; '.join(f'{c[0]} in {c[1]} frames from {c[2]}' for c in self.changes[:3])}"
                + (", ..." if len(self.changes) > 3 else "") + ")")


def untangle(markers: MarkerSequence, model: LabelingModel, chains, *, thumb=(), fixed=(),
             rounds: int = 20) -> Untangled:
    """Labels moved between the fingers' markers where the fingers' anatomy says they belong elsewhere.

    Parameters
    ----------
    markers : MarkerSequence
        A labelled take (the labeler's output), metres, with the model's rigid markers.
    model : LabelingModel
        The model that labelled it (its rigid set, spatial model and spans).
    chains : sequence of sequence of str
        Each long finger's labels from the palm outward
        (:func:`handcap.layouts.chains.finger_chains`); 3 or more each.
    thumb : sequence of str
        The thumb's labels from its base outward (:func:`handcap.layouts.chains.thumb_chain`): they take part
        in the moves, their spans and bends count, but not the line (the thumb flexes across the palm).
    fixed : sequence of str
        Labels that keep their points (markers of the palm).
    rounds : int
        Most relabellings.

    Returns
    -------
    Untangled
    """
    chains = [tuple(c) for c in chains if len(c) >= 3]
    if model.rigid is None:
        raise HandcapError("untangling the fingers needs a model with rigid back-of-hand markers")
    thumb = tuple(thumb)
    members = [n for c in chains for n in c] + list(thumb)
    missing = [n for n in members + list(model.rigid.names) if n not in markers.names]
    if missing:
        raise HandcapError(f"labels not in the take: {', '.join(missing)}")
    if len(chains) < 2:
        return Untangled(markers, ())
    owner = np.concatenate([[k] * len(c) for k, c in enumerate(chains + [thumb])])
    fixed = set(fixed)
    moves = _candidates([i for i, n in enumerate(members) if n not in fixed], owner)
    perms = np.array([_permutation(mv, len(members)) for mv in moves])  # (C, M)
    columns = [markers.index(n) for n in members]
    x = markers.positions[:, columns].copy()
    frames = _HandFrames(markers, model)
    spatial = [model.spatial.names.index(n) for n in members]
    terms = _Terms(model, chains, thumb, spatial)
    changes = []
    length = terms.lengths(x)  # measured once, on the take as labelled
    gain = terms.gain(x, frames, perms, np.arange(len(x)), length) - MARGIN
    for _ in range(rounds):
        enter, leave = _jumps(x, moves)
        total, chosen = _best_stretch(gain, enter, leave)
        k = int(np.argmax(total))
        if total[k] < MIN_GAIN:
            break
        where, perm = chosen(k), perms[k]
        x[where] = x[where][:, perm]
        gain[:, where] = terms.gain(x, frames, perms, np.flatnonzero(where), length) - MARGIN  # only those changed
        at = np.flatnonzero(where)
        described = ", ".join(f"{members[a]}<-{members[perm[a]]}" for a in range(len(members)) if perm[a] != a)
        changes.append((described, int(len(at)), int(at[0]), int(at[-1])))
    positions = markers.positions.copy()
    positions[:, columns] = x
    return Untangled(MarkerSequence(positions, markers.names, markers.rate, warnings=markers.warnings),
                     tuple(changes))


def _candidates(movable, owner) -> np.ndarray:
    """(C, 3, 2) moves (label, source) of every swap of two labels and every 3-cycle of labels of 2 or more
    fingers (a swap's third move is a label onto itself)."""
    out = []
    for a, b in itertools.combinations(movable, 2):
        out.append([(a, b), (b, a), (a, a)])
    for a, b, c in itertools.combinations(movable, 3):
        if len({owner[a], owner[b], owner[c]}) > 1:
            out += [[(a, b), (b, c), (c, a)], [(a, c), (c, b), (b, a)]]
    return np.array(out, dtype=np.intp).reshape(-1, 3, 2)


def _permutation(move, m) -> np.ndarray:
    """The labels' sources (M,) of one candidate's moves (3, 2): label i takes the point of label ``perm[i]``."""
    perm = np.arange(m)
    real = move[:, 0] != move[:, 1]
    perm[move[real, 0]] = move[real, 1]
    return perm


class _HandFrames:
    """Per frame: the hand frame of the take's rigid markers (their own shape turned onto the model's) and the
    normal of the back of the hand."""

    def __init__(self, markers, model):
        rigid = np.stack([markers.positions[:, markers.index(n)] for n in model.rigid.names], axis=1)
        canonical = own_shape(model.rigid.canonical, rigid)
        self.rotation, self.translation, self.ok = rigid_transforms(canonical, rigid)
        centred = canonical - canonical.mean(axis=0)
        normal = np.linalg.svd(centred)[2][-1]
        self.normal = self.rotation @ normal
        self.normal[~self.ok] = np.nan


class _Terms:
    """The costs of labels on points: straight fingers, spans and the spatial model."""

    def __init__(self, model, chains, thumb, spatial):
        self.model, self.spatial = model, spatial
        first = np.cumsum([0] + [len(c) for c in chains] + [len(thumb)])
        self.groups = [np.arange(first[k], first[k + 1]) for k in range(len(chains))]  # straight: the line test
        self.bent = self.groups + ([np.arange(first[-2], first[-1])] if len(thumb) >= 2 else [])
        pairs = [(g[i], g[i + 1]) for g in self.bent for i in range(len(g) - 1)]
        self.a, self.b = (np.array(p, dtype=np.intp) for p in zip(*pairs))
        self.spans = None
        if model.spans is not None:
            s = model.spans[np.array(spatial)[self.a], np.array(spatial)[self.b]]  # (E, 2)
            if np.isfinite(s).all():
                self.spans = s
        self.top = model.spatial.typical_fit()

    def gain(self, x, frames, perms, at, length) -> np.ndarray:
        """(C, F): cost of the labels as given minus as each candidate's permutation (C, M) gives them, in the
        frames ``at`` (F,) of ``x`` (T, M, 3), with the spans' ``length`` (:meth:`lengths`; terms seen both
        ways only)."""
        perms = np.vstack([np.arange(x.shape[1])[None], perms])  # the labels as given first
        out = np.zeros((len(perms) - 1, len(at)))
        for start in range(0, len(at), CHUNK):
            part = at[start:start + CHUNK]
            out[:, start:start + len(part)] = self._gain(x[part], frames, part, perms, length)
        return out

    def lengths(self, x) -> np.ndarray | None:
        """Each span's length in the take (E,), metres: the middle of its densest stretch of distances in the
        band; None without the training spans."""
        if self.spans is None:
            return None
        dist = np.linalg.norm(x[:, self.a] - x[:, self.b], axis=-1)
        out = self.spans[:, 0].copy()
        for e in range(len(out)):
            v = np.sort(dist[:, e][np.isfinite(dist[:, e])])
            v = v[(v > SPAN_BAND[0] * out[e]) & (v < SPAN_BAND[1] * out[e])]
            n = max(2, int(SPAN_SHARE * len(v)))
            if len(v) >= 2 * n:
                k = int(np.argmin(v[n - 1:] - v[:len(v) - n + 1]))
                out[e] = np.median(v[k:k + n])
        return out

    def _gain(self, x, frames, part, perms, length) -> np.ndarray:
        m = x.shape[1]
        cost = np.zeros((len(perms), len(x)))

        def add(z):  # z (C+1, T, ...): a term compared only where both the labels as given and permuted have it
            nonlocal cost
            z = np.minimum(z, CAP)
            both = np.isfinite(z) & np.isfinite(z[:1])
            cost += np.where(both, z - np.where(both, z[:1], 0), 0).reshape(len(perms), len(x), -1).sum(-1)

        # Straight fingers, seen from the back of the hand: the smaller spread of the points in the plane.
        normal = frames.normal[part]
        flat = x - np.einsum("tmi,ti->tm", x, normal)[..., None] * normal[:, None]
        for g in self.groups:
            pts = flat[:, perms[:, g]].transpose(1, 0, 2, 3)  # (C+1, T, k, 3)
            centred = pts - pts.mean(axis=2, keepdims=True)
            c = np.einsum("ctki,ctkj->ctij", centred, centred) / len(g)
            # Projected points: eigenvalues 0 (the normal), then the two in the plane, whose sum is the trace and
            # whose product is the sum of the principal 2 x 2 minors; the smaller is the spread off the line.
            trace = c[..., 0, 0] + c[..., 1, 1] + c[..., 2, 2]
            minors = (c[..., 0, 0] * c[..., 1, 1] - c[..., 0, 1] ** 2 + c[..., 0, 0] * c[..., 2, 2]
                      - c[..., 0, 2] ** 2 + c[..., 1, 1] * c[..., 2, 2] - c[..., 1, 2] ** 2)
            minor = 0.5 * (trace - np.sqrt(np.maximum(trace ** 2 - 4 * minors, 0.0)))
            add(np.maximum(minor, 0.0)[..., None] / LINE_SD ** 2)
        # Fingers bend at most MAX_BEND at a joint: a chain of markers that turns back on itself is out of order.
        for g in (g for g in self.bent if len(g) >= 3):
            pts = x[:, perms[:, g]]  # (T, C+1, k, 3)
            u, v = pts[:, :, 1:-1] - pts[:, :, :-2], pts[:, :, 2:] - pts[:, :, 1:-1]
            turn = np.arctan2(np.linalg.norm(np.cross(u, v), axis=-1), np.einsum("tcki,tcki->tck", u, v))
            add((np.maximum(turn - MAX_BEND, 0.0) / BEND_SD).transpose(1, 0, 2) ** 2)
        if length is not None:
            scale = np.hypot(self.spans[:, 1], SPAN_FLOOR)
            dist = np.linalg.norm(x[:, perms[:, self.a]] - x[:, perms[:, self.b]], axis=-1)  # (T, C+1, E)
            add((((dist - length) / scale) ** 2).transpose(1, 0, 2))
        rot, trans, ok = frames.rotation[part], frames.translation[part], frames.ok[part]
        local = np.einsum("tji,tmj->tmi", rot, x - trans[:, None])
        local[~ok] = np.nan
        flat_local = np.nan_to_num(local.reshape(-1, 3))
        ll = self.model.spatial.log_likelihood(flat_local)[self.spatial].reshape(m, len(x), m)  # (label, T, point)
        ll[:, ~np.isfinite(local).all(axis=-1)] = np.nan
        labels = np.arange(m)
        mismatch = np.maximum(self.top - ll, 0.0)  # (label, T, point)
        add(mismatch[labels[None, :], :, perms].transpose(0, 2, 1))
        return -cost[1:]


def _held(x) -> np.ndarray:
    """Each label's last position before each frame (within :data:`HOLD` frames), NaN otherwise."""
    out = np.full_like(x, np.nan)
    last = np.full(x.shape[1:], np.nan)
    age = np.full(x.shape[1], HOLD + 1)
    for t in range(len(x)):
        out[t] = np.where((age <= HOLD)[:, None], last, np.nan)
        seen = np.isfinite(x[t, :, 0])
        last = np.where(seen[:, None], x[t], last)
        age = np.where(seen, 1, age + 1)
    return out


def _jumps(x, moves) -> tuple[np.ndarray, np.ndarray]:
    """(C, T) each: what starting (``enter``) or ending (``leave``) a candidate's relabelling at a frame adds to
    the jumps of its labels, against leaving them (squared steps over twice the median step, capped)."""
    before = _held(x)
    step = np.linalg.norm(x - before, axis=-1)
    scale = 2 * np.nanmedian(step) + 1e-3 if np.isfinite(step).any() else 1e-3

    def jump(a, b):
        z = np.minimum((np.linalg.norm(a - b, axis=-1) / scale) ** 2, CAP)
        return np.where(np.isfinite(z), z, 0.0)

    label, source = moves[..., 0], moves[..., 1]  # (C, 3)
    enter, leave = np.zeros((2, len(moves), len(x)))
    for start in range(0, len(x), CHUNK):
        part = slice(start, start + CHUNK)
        now, was = x[part], before[part]
        stay = jump(now, was)[:, label]  # (t, C, 3)
        enter[:, part] = (jump(now[:, source], was[:, label]) - stay).sum(-1).T
        leave[:, part] = (jump(now[:, label], was[:, source]) - stay).sum(-1).T
    return enter, leave


def _best_stretch(gain, enter, leave):
    """Two-state Viterbi per candidate: the most a candidate's relabelling can save (C,), and a function giving
    the frames (T,) bool where it applies."""
    c, t_all = gain.shape
    keep, moved = np.zeros(c), np.full(c, -np.inf)
    back = np.zeros((t_all, 2, c), dtype=bool)
    for t in range(t_all):
        from_moved = moved - leave[:, t] - SWITCH
        into = keep - enter[:, t] - SWITCH
        back[t, 0] = from_moved > keep
        back[t, 1] = moved > into
        keep, moved = np.maximum(keep, from_moved), np.maximum(into, moved) + gain[:, t]
    total = np.maximum(keep, moved)
    last = moved > keep

    def chosen(k):
        state, where = int(last[k]), np.zeros(t_all, dtype=bool)
        for t in range(t_all - 1, -1, -1):
            where[t] = state == 1
            state = int(back[t, state, k])
        return where

    return total, chosen
