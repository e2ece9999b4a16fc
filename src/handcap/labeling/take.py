"""Labeling a whole take: :func:`label_take`, online or offline in two passes, with its warnings.

Issue 14 (takes of other days): the spatial model is re-aligned to the take
(:mod:`handcap.labeling.adapt`; online every ``adapt_every`` frames, offline in
two passes), the rigid set is re-learned from the take when its distances
changed, offline a label the take hardly gets is searched for with wider
components (``MISSING_SPREAD``), and a hand frame lost in many frames, few
labelled points or a label given in few frames are warnings stored on the
:class:`LabelResult`.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from handcap.core.errors import HandcapError, warn
from handcap.core.markers import MarkerSequence
from handcap.core.points import PointCloudSequence
from handcap.labeling.baseline import NearestNeighbourLabeler
from handcap.labeling.discover import find_rigid_body
from handcap.labeling.model import LabelingModel, rigid_transforms
from handcap.labeling.multihand import MultiHandLabeler
from handcap.labeling.online import OnlineLabeler
from handcap.labeling.realign import adapt_means, register_to_model
from handcap.labeling.plausible import (LABELLED_WARNING, MISSING_SPREAD, UNNAMED, label_warnings, missing_labels,
                                        unnamed_body_warning)
from handcap.labeling.relearn import RELEARN_WIDTH, largest_change, rigid_from_take
from handcap.labeling.rigid_set import RigidSet


#: The offline second pass refits the spatial model only when the first pass's labels put the take's hand
#: frame further than this from the trained one (degrees, metres). A take of the training session measures
#: up to ~2.4 degrees / 1.3 mm from its different poses alone (real glove, 8 s and 40 s); there a refit follows
#: the take's poses, not the markers, and labels worse (99.96 -> 99.62 % correct).
REFIT_TURN_DEG = 3.0
REFIT_SHIFT = 0.003
#: Track births (``OnlineLabeler(birth=...)``) in the offline first pass (0: none). They were 5 when synthetic
#: takes let neighbouring fingers pass through each other (triad moved 13 deg / 13 mm: offline wrong 0.87 ->
#: 0.03 %). On takes whose fingers keep apart (:mod:`handcap.synth.clearance`) they change nothing on the other
#: day's takes nor on 10 of 11 other subjects, and on subject 3 of ``benchmarks/labeling.py`` section 8 took
#: wrong points: 99.95 / 0.000 % correct / wrong without them, 98.52 / 0.195 with.
FIRST_PASS_BIRTH = 0
#: Offline, where the rigid set searched for over the whole take is not the trained one (or its labels leave more
#: than 5 % of the points), the set an online pass re-learned (frame by frame, judged once the model is aligned)
#: replaces it when its two passes label this much more of the take's points. The
#: search can take a look-alike set of knuckle and finger markers for the back of another subject's hand
#: (synthetic subject 7, its triad 12 mm off: 54.1 -> 93.7 % correct, 76 -> 94 % of the points labelled), and
#: the online pass can too (subject 9: 73 % labelled against the search's 94 %).
ONLINE_RIGID_MARGIN = 0.01
#: Offline, the rigid bodies found one after the other among the points the labels leave (objects not given,
#: :data:`~handcap.labeling.plausible.UNNAMED`), each labelled before the next is searched for (and kept where its
#: labels cover ``ONLINE_RIGID_MARGIN`` more of the points), at most this many.
MOST_BODIES = 3
#: Offline, a label given in fewer than :data:`~handcap.labeling.plausible.MISSING_SHARE` of the frames the median
#: label is given in was not found where the training take puts it. The take is then labelled again with every
#: component widened by :data:`~handcap.labeling.plausible.MISSING_SPREAD` in the first pass and the means moved to
#: those labels, and that is kept when it labels ``ONLINE_RIGID_MARGIN`` more of the points.


@dataclass(frozen=True)
class LabelResult:
    """A labeled take.

    Attributes
    ----------
    markers : MarkerSequence
        (T, M, 3) positions of every label, NaN where the labeler reports a gap
        (its ``warnings`` hold this result's warnings too).
    labels : list of ndarray
        Per frame, the label index (into ``markers.names``) of every input point, -1 for none.
    lost_frames : ndarray (L,) int
        Frames where the hand frame could not be found.
    warnings : tuple of str
        One line per implausible figure (hand frame lost in many frames, few
        points labelled).
    model : LabelingModel or None
        The model as adapted to the take by the offline second pass (None otherwise).
    rigid : RigidSet or None
        The hand's rigid set as the labeler ended the take with it (re-learned from the take when its
        distances differed from training); None for several hands or without rigid markers.
    released : tuple of Release
        Labels whose tracks the spatial model disagreed with, released to it (:class:`OnlineLabeler`'s
        ``release``; the last pass offline): the labels are probably swapped before each, and a warning says so.
    widened : tuple of str
        Labels hardly given and so searched for wider, online (``OnlineLabeler.widened``); a warning says so.
    """

    markers: MarkerSequence
    labels: list
    lost_frames: np.ndarray
    warnings: tuple = ()
    model: LabelingModel | None = None
    rigid: RigidSet | None = None
    released: tuple = ()
    widened: tuple = ()

    def summary(self) -> str:
        """One line: frames, labels, the share of label-frames filled and the frames without a hand frame."""
        seen = float(np.mean(~np.isnan(self.markers.positions[..., 0]))) if self.markers.positions.size else 0.0
        lost = self.lost_frames
        return (f"{self.markers.n_frames} frames, {len(self.markers.names)} labels, {100 * seen:.1f} % of label-frames "
                f"filled; hand frame not found in {len(lost)} frames" + (f" (first: {lost[0]})" if len(lost) else ""))


def label_take(points, model: LabelingModel, *, transforms=None, offline: bool = False, method: str = "viterbi",
               progress: bool | None = None, adapt: bool = True, **options) -> LabelResult:
    """Label a whole take, frame by frame as a live labeler would (or on the whole take with ``offline``).

    Parameters
    ----------
    points : PointCloudSequence or MarkerSequence
        Unlabeled points; a MarkerSequence's names and columns are ignored.
    model : LabelingModel or sequence of LabelingModel
        Several: one per hand in the stream (:class:`MultiHandLabeler`; give
        ``prefixes`` when they share names).
    transforms : (ndarray (T, 3, 3), ndarray (T, 3)), optional
        Hand frame per frame (for models without rigid markers).
    offline : bool
        Decide every frame on the whole take (Viterbi over everything) instead
        of online. With ``adapt`` and one hand, in two passes: the rigid
        markers' shape re-learned from the take where it differs from
        training, a first labeling (adapting as it goes, track births as
        ``FIRST_PASS_BIRTH`` says: none), the spatial model
        registered to that pass's labels and its means moved toward them
        (:mod:`handcap.labeling.adapt`), and a second labeling with it. Where
        the re-learned set is not the trained one (or the labels leave over
        5 % of the points), the set a strictly online pass re-learned is tried
        too and kept when its labels cover ``ONLINE_RIGID_MARGIN`` more of the
        points. Without ``objects``, rigid bodies found among the points left
        (:data:`~handcap.labeling.plausible.UNNAMED`, :data:`MOST_BODIES`) are labelled as known objects'
        markers are.
    method : {"viterbi", "nearest"}
        The labeler, or the nearest-neighbour baseline
        (:class:`handcap.labeling.baseline.NearestNeighbourLabeler`).
    progress : bool, optional
    adapt : bool
        Re-align the spatial model to the take (see ``offline`` and
        :class:`OnlineLabeler`).
    options
        :class:`OnlineLabeler` settings (``hypotheses``, ``lag``, ``theta_min``, ...).

    Returns
    -------
    LabelResult
        With warnings (also issued as :class:`handcap.core.errors.HandcapWarning`)
        when the hand frame is lost in more than 5 % of the frames or fewer
        than 95 % of the points are labelled, and one naming a rigid body
        found among the points left (an object not given).
    """
    if isinstance(points, MarkerSequence):
        points = PointCloudSequence.from_markers(points)
    if method not in ("viterbi", "nearest"):
        raise HandcapError(f"unknown labeling method {method!r}; choose viterbi or nearest")
    if method == "nearest" and not isinstance(model, LabelingModel):
        raise HandcapError("the nearest-neighbour baseline labels one hand")
    model = model.at_rate(points.rate) if isinstance(model, LabelingModel) else [m.at_rate(points.rate) for m in model]
    result, adapted, found_wider = _labelled(points, model, transforms, offline, method, progress, adapt, options)
    bodies, search = [], method == "viterbi" and isinstance(model, LabelingModel) and not options.get("objects")
    while search and len(bodies) < MOST_BODIES and _labelled_share(result, points) < LABELLED_WARNING:
        name = f"{UNNAMED}{len(bodies) + 1 if bodies else ''}"  # object, object2, ...
        body = find_rigid_body([f[lab < 0] for f, lab in zip(points.frames, result.labels)], name=name)
        if body is None:  # (rigid bodies found among the points left: objects not given)
            break
        if not offline:  # online, only named: the points of one body are not told from another's
            bodies.append(body)
            break
        again = _labelled(points, model, transforms, offline, method, progress, adapt,
                          {**options, "objects": bodies + [body]})
        if _labelled_share(again[0], points) < _labelled_share(result, points) + ONLINE_RIGID_MARGIN:
            break  # its shape found too few of its points to be a body
        bodies.append(body)
        result, adapted, found_wider = again
    return _with_warnings(result, points, adapted, model, found_wider, bodies)


def _labelled(points, model, transforms, offline, method, progress, adapt, options):
    """:func:`label_take`'s labelling: the result, the model as adapted (offline) and the labels found wider."""
    two_pass = (offline and adapt and method == "viterbi" and isinstance(model, LabelingModel)
                and model.rigid is not None and transforms is None)
    adapted = None
    found_wider = ()
    if two_pass:
        chosen = _rigid_from_take(model, points.frames)
        result, adapted = _two_passes(points, chosen, progress, options)
        # A second opinion on the rigid set where the take's is not the trained one, or few points got a label.
        share = _labelled_share(result, points)
        doubt = chosen.rigid is not model.rigid or share < LABELLED_WARNING
        online = _run(points, model, None, False, method, progress, {**options, "adapt": True}).rigid if doubt else None
        if online is not None and largest_change(online, chosen.rigid) > 0.5 * model.rigid.tolerance:
            other = _two_passes(points, replace(model, rigid=online), progress, options)
            other_share = _labelled_share(other[0], points)
            if other_share > share + ONLINE_RIGID_MARGIN:
                result, adapted, chosen, share = other + (replace(model, rigid=online), other_share)
        # Labels the take (almost) never gave: searched for wider.
        missing = _missing_labels(result.markers, chosen)
        if missing.any():
            other = _two_passes(points, chosen, progress, options, missing=missing)
            if _labelled_share(other[0], points) > share + ONLINE_RIGID_MARGIN:
                result, adapted = other
                found_wider = tuple(np.array(chosen.spatial.names)[missing])
    else:
        if method == "viterbi":
            options["adapt"] = adapt
        result = _run(points, model, transforms, offline, method, progress, options)
    return result, adapted, found_wider


def _two_passes(points, model, progress, options, missing=None) -> tuple[LabelResult, LabelingModel]:
    """The offline labeling of a take in two passes with ``model``'s rigid set; its result and the refit model.

    With ``missing`` (a mask over the spatial model's labels), the first pass searches with every component
    widened by ``MISSING_SPREAD`` and the refit moves the missing labels' means even where the take sits as
    training did."""
    spread = MISSING_SPREAD if missing is not None else 0.0
    first_model = replace(model, spatial=model.spatial.widened(spread)) if spread else model
    first = _run(points, first_model, None, True, "viterbi", progress, {"birth": FIRST_PASS_BIRTH, **options,
                                                                          "adapt": True})
    adapted = refit_to_labels(model, first.markers, spread=spread, missing=missing)
    return _run(points, adapted, None, True, "viterbi", progress, {**options, "adapt": False}), adapted


def _given_shares(markers: MarkerSequence, model: LabelingModel) -> np.ndarray:
    """Share of the frames (M,) each of ``model.spatial.names`` is given in."""
    columns = [markers.index(n) for n in model.spatial.names]
    return np.mean(~np.isnan(markers.positions[:, columns, 0]), axis=0)


def _missing_labels(markers: MarkerSequence, model: LabelingModel) -> np.ndarray:
    """Mask (M,) over ``model.spatial.names``: labels given in under ``MISSING_SHARE`` of the frames the median
    label is given in."""
    return missing_labels(_given_shares(markers, model))


def _labelled_share(result: LabelResult, points) -> float:
    """The share of the take's points that got a label (NaN for a take without points)."""
    total = sum(int(np.isfinite(f).all(axis=1).sum()) for f in points.frames)
    return sum(int((lab >= 0).sum()) for lab in result.labels) / total if total else float("nan")


def _rigid_from_take(model: LabelingModel, frames) -> LabelingModel:
    """The model with its rigid set re-learned from the take when the take's shape differs from training."""
    rigid = model.rigid
    new = rigid_from_take(rigid, frames, spatial=model.spatial, width=max(RELEARN_WIDTH, 3 * rigid.tolerance))
    if new is None:
        return model
    if largest_change(new, rigid) <= 0.5 * rigid.tolerance:
        return model
    return replace(model, rigid=new)


def refit_to_labels(model: LabelingModel, labeled: MarkerSequence, *, spread: float = 0.0,
                    missing=None) -> LabelingModel:
    """The model's spatial model registered to a labelled take and its means moved toward it.

    Parameters
    ----------
    model : LabelingModel
        With rigid markers.
    labeled : MarkerSequence
        A labeling of a take by this model (its names in ``model.names`` order).
    spread : float
        Metres: the registration and the move of the means use the components widened by this
        (:meth:`SpatialModel.widened`), so labels far from their trained place count; the result keeps
        the trained spreads.
    missing : ndarray (M,) bool, optional
        Labels (of ``model.spatial.names``) the take hardly gave: their means move even where the take's
        hand frame is the trained one (the others' then stay).

    Returns
    -------
    LabelingModel
        The same rigid set and filters; the spatial model expressed in the
        hand frame the take's rigid markers give (:mod:`handcap.labeling.adapt`),
        or ``model`` itself when that frame is within ``REFIT_TURN_DEG`` and
        ``REFIT_SHIFT`` of the trained one (and no label is ``missing``).
    """
    n_rigid = len(model.rigid.names)
    positions = np.stack([labeled.positions[:, labeled.index(n)] for n in model.names], axis=1)
    rot, trans, ok = rigid_transforms(model.rigid.canonical, positions[:, :n_rigid])
    local = np.einsum("tji,tmj->tmi", rot[ok], positions[ok, n_rigid:] - trans[ok, None])
    labels = np.broadcast_to(np.arange(local.shape[1]), local.shape[:2])
    seen = ~np.isnan(local[..., 0])
    local, labels = local[seen], labels[seen]
    if len(local) < 50:
        return model
    spatial = model.spatial.widened(spread) if spread > 0 else model.spatial
    # From the label-free registration (the first pass's labels may be wrong where the take was most off).
    start = register_to_model(spatial, local[np.linspace(0, len(local) - 1, min(len(local), 3000)).astype(int)])
    r, t = register_to_model(spatial, local, labels, anneal=0.0, iterations=10, start=start)
    turn = np.degrees(np.arccos(np.clip((np.trace(r) - 1) / 2, -1.0, 1.0)))
    if turn < REFIT_TURN_DEG and np.linalg.norm(t) < REFIT_SHIFT:
        if missing is None or not np.any(missing):
            return model  # the take sits as the training take did: a refit would only follow this take's poses
        # ... but labels it never gave still move to where it puts them (the others stay as trained)
        r, t, labels = np.eye(3), np.zeros(3), np.where(np.asarray(missing)[labels], labels, -1)
    means = adapt_means(spatial, local @ r.T + t, labels).means
    return replace(model, spatial=replace(model.spatial, means=means).moved(r, t))


def _run(points, model, transforms, offline, method, progress, options) -> LabelResult:
    """One labeling pass over a take."""
    from tqdm import tqdm
    if method == "nearest":
        options.pop("adapt", None)
        labeler = NearestNeighbourLabeler(model, **options)
    else:
        if offline:
            options["lag"] = points.n_frames
        if isinstance(model, LabelingModel):
            labeler = OnlineLabeler(model, **options)
        else:
            labeler = MultiHandLabeler(model, **options)
    labels = []
    hidden = None if progress is None else not progress
    for t, frame in enumerate(tqdm(points.frames, desc="label", unit="frame", disable=hidden, leave=False)):
        transform = None if transforms is None else (transforms[0][t], transforms[1][t])
        out = labeler.update(frame, transform)
        if out is not None:
            labels.append(out)
    labels.extend(labeler.flush())
    names = labeler.names
    positions = np.full((points.n_frames, len(names), 3), np.nan)
    for t, (frame, lab) in enumerate(zip(points.frames, labels)):
        hit = lab >= 0
        positions[t, lab[hit]] = frame[hit]
    finder = getattr(labeler, "finder", None)
    return LabelResult(MarkerSequence(positions, names, points.rate), labels,
                       np.array(getattr(labeler, "lost_frames", []), dtype=int),
                       rigid=None if finder is None else finder.rigid,
                       released=tuple(getattr(labeler, "released", ())),
                       widened=tuple(getattr(labeler, "widened", ())))


def _with_warnings(result: LabelResult, points, model, trained=None, found_wider=(), bodies=()) -> LabelResult:
    """The result with its warnings (:func:`~handcap.labeling.plausible.label_warnings`, issued and stored on it
    and on its markers); ``model`` the adapted model (offline), ``trained`` the one given, ``found_wider`` the
    labels found only by a wider search, ``bodies`` the rigid bodies found among the points left (their markers
    labelled offline, only named online)."""
    one = isinstance(trained, LabelingModel)
    given = _given_shares(result.markers, trained) if one and result.markers.n_frames else np.zeros(0)
    lines = [warn(line, stacklevel=3) for line in label_warnings(
        trained.spatial.names if one else (), given, trained_rigid=trained.rigid if one else None, rigid=result.rigid,
        lost=len(result.lost_frames), frames=points.n_frames, labelled=_labelled_share(result, points),
        released=result.released, rate=points.rate, found_wider=found_wider or result.widened)]
    lines += [warn(unnamed_body_warning(b, b.names[0] in result.markers.names), stacklevel=3) for b in bodies]
    return replace(result, markers=result.markers.with_warnings(*lines), warnings=tuple(lines), model=model)
