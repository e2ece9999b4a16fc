"""One live frame through every stage: label the unlabelled points, fill the hidden markers, solve the hand.

:class:`LivePipeline` chains the stages that the batch verbs run over a whole take, each in its per-frame form:

1. **label** (optional, with a :class:`~handcap.labeling.LabelingModel`): the frame's points, unlabelled and in
   any order, get the layout's labels from :class:`~handcap.labeling.OnlineLabeler` (strictly online: no
   look-ahead, the spatial model re-aligned to the take as it streams in);
2. **fill** (optional, with an occlusion model): the markers hidden in this frame are predicted by
   :class:`~handcap.occlusion.OcclusionFiller` (the autoencoder of the real-time occlusion paper, from the
   markers seen now and in the frames before);
3. **solve**: :class:`~handcap.stream.solver.FrameSolver`, warm-started from the frame before.

Each stage's time is measured per frame (:attr:`LivePipeline.last_ms`).
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from handcap.core.errors import HandcapError
from handcap.labeling import LabelingModel, OnlineLabeler, lap
from handcap.labeling.plausible import LabelTally, label_warnings, unnamed_body_warning
from handcap.occlusion import OcclusionFiller, OcclusionModel
from handcap.stream.solver import ITERATIONS, SMOOTHING, FrameSolver

#: Stages of a live frame, in order.
STAGES = ("label", "fill", "solve")
#: Assignment hypotheses per live frame (the paper and ``handcap label``: 5), and seconds between the labeler's
#: re-alignments to the take (``handcap label``: 25 frames). Measured on four synthetic takes of one subject
#: (random, grasp, precision, open-close; 20 s each at 120 Hz, joints-19, ghosts and swaps as ``handcap synth``
#: makes them; re-aligned every second): 90.1 % of the labels right with 2 or 3 hypotheses, 90.0 % with 5, for
#: 0.77, 0.91 and 1.20 ms per frame (p50): 2 it is (the tracking hypothesis comes on top). A re-alignment costs
#: about 3 ms (the first, a label-free registration, half a second): every 25 frames they raised the p99 from 1.4
#: to 3.3 ms on the random take.
LIVE_HYPOTHESES = 2
ADAPT_SECONDS = 1.0


@dataclass(frozen=True)
class LiveFrame:
    """What one frame gave.

    Attributes
    ----------
    joints : ndarray (21, 3)
        Metres; NaN when the hand could not be solved.
    phi : ndarray (27,)
        Joint angles, radians.
    markers : ndarray (M, 3)
        The attachment's markers as solved from (labelled and filled, with the labels the solve found swapped
        exchanged), metres, NaN where neither.
    seen : int
        Markers measured (labelled) in this frame.
    filled : int
        Markers predicted by the filler.
    rms : float
        RMS marker residual of the solve, metres.
    """

    joints: np.ndarray
    phi: np.ndarray
    markers: np.ndarray
    seen: int
    filled: int
    rms: float


class LivePipeline:
    """Label, fill and solve live frames of one hand.

    Parameters
    ----------
    attachment : MarkerAttachment
        The calibrated markers; the solve uses them in this order.
    hand : HandModel
        The attachment's model.
    rate : float
        Frames per second of the stream.
    labeling : LabelingModel, str, Path or None
        A labelling model (or its ``.npz``, ``handcap label --model``): frames are then unlabelled points.
        None: frames are the attachment's markers in its order.
    fill : OcclusionModel, str, Path or None
        An occlusion model, a shipped layout's name or a model ``.npz``: hidden markers are predicted before the
        solve. Its markers must be among the attachment's.
    iterations : int
        Gauss-Newton iterations of the warm-started solve.
    hypotheses : int
        The labeler's assignment hypotheses per frame.
    adapt_seconds : float
        Seconds between the labeler's re-alignments of its spatial model to the take.
    smoothing : float
        The solve's pull towards the angles the frames before predict (:class:`FrameSolver`; 0: none).
    mend_swaps : bool
        Labels the solved hand finds swapped are solved exchanged (:class:`FrameSolver`; measured markers only,
        not those the filler predicted); the filler sees the labels as given.
    """

    def __init__(self, attachment, hand, *, rate: float, labeling=None, fill=None, iterations: int = ITERATIONS,
                 hypotheses: int = LIVE_HYPOTHESES, adapt_seconds: float = ADAPT_SECONDS,
                 smoothing: float = SMOOTHING, mend_swaps: bool = True):
        self.names = tuple(attachment.marker_names)
        self.solver = FrameSolver(attachment, hand, iterations=iterations, smoothing=smoothing,
                                  mend_swaps=mend_swaps)
        self.labeler = self.label_columns = self.tally = None
        if labeling is not None:
            model = (labeling if isinstance(labeling, LabelingModel) else LabelingModel.load(labeling)).at_rate(rate)
            self.labeler = OnlineLabeler(model, lag=0, hypotheses=hypotheses,
                                         adapt_every=max(1, int(round(adapt_seconds * rate))), defer=True)
            lap.prepare()  # the compiled ranking of assignments, before the first frame
            self.label_columns = np.array([self.names.index(n) if n in self.names else -1
                                           for n in self.labeler.names])
            if (self.label_columns < 0).all():
                raise HandcapError(f"the labelling model's markers ({', '.join(model.names[:4])}...) are not the "
                                   f"attachment's ({', '.join(self.names[:4])}...): give the model of this layout")
            self.tally = LabelTally(len(self.labeler.names))  # what the labels add up to: label_warnings()
        self.filler = self.fill_columns = None
        if fill is not None:
            model = OcclusionModel.resolve(fill)
            known = [n for n in self.names if n in model.names]
            if len(known) < len(model.names) // 2:
                raise HandcapError(f"the occlusion model knows {', '.join(model.names[:4])}...; the attachment has "
                                   f"{', '.join(self.names[:4])}...: give the model of this layout")
            self.filler = OcclusionFiller(model, rate=rate, names=known, regress=False)
            self.fill_columns = np.array([self.names.index(n) for n in known])  # its input, in the given order
            self.filled_columns = np.array([self.names.index(n) if n in self.names else -1
                                            for n in self.filler.names])  # its output, in the model's order
        self.last_ms = dict.fromkeys(STAGES, 0.0)

    @property
    def stages(self) -> tuple[str, ...]:
        """The stages this pipeline runs."""
        return tuple(s for s, on in zip(STAGES, (self.labeler, self.filler, True)) if on is not None)

    def frame(self, data) -> LiveFrame:
        """One frame through every stage.

        Parameters
        ----------
        data : ndarray (K, 3) or (M, 3)
            With a labelling model, the frame's unlabelled points (metres, any order, NaN rows ignored);
            without, the attachment's markers in its order (NaN where hidden).

        Returns
        -------
        LiveFrame
        """
        clock = time.perf_counter
        start = clock()
        data = np.asarray(data, dtype=np.float64)
        if self.labeler is not None:
            points = data.reshape(-1, 3)
            labels = self.labeler.update(points)
            self.tally.add(labels, np.isfinite(points).all(axis=1), points)
            markers = np.full((len(self.names), 3), np.nan)
            kept = labels >= 0  # one label per point given, -1 for no marker (and for NaN rows)
            columns = self.label_columns[labels[kept]]
            markers[columns[columns >= 0]] = points[kept][columns >= 0]
        else:
            markers = data.reshape(len(self.names), 3).copy()
        measured = np.isfinite(markers).all(axis=1)
        seen = int(measured.sum())
        labelled = clock()
        filled = 0
        if self.filler is not None:
            result = self.filler.update(markers[self.fill_columns])
            ours = self.filled_columns >= 0
            columns, predicted = self.filled_columns[ours], result.markers[ours]
            hidden = ~np.isfinite(markers[columns]).all(axis=1) & np.isfinite(predicted).all(axis=1)
            markers[columns[hidden]] = predicted[hidden]
            filled = int(hidden.sum())
        completed = clock()
        joints, phi, rms = self.solver.solve(markers, measured)
        done = clock()
        self.last_ms = {"label": 1000 * (labelled - start), "fill": 1000 * (completed - labelled),
                        "solve": 1000 * (done - completed)}
        return LiveFrame(joints, phi, markers[self.solver.order], seen, filled, rms)

    def label_warnings(self, rate: float) -> list[str]:
        """The labels' plausibility so far, one line each (:func:`~handcap.labeling.plausible.label_warnings`: a
        rigid set re-learned, the hand frame often lost, labels hardly given, few points labelled, releases, a rigid
        body among the points left: an object not given); empty without a labelling model.

        Parameters
        ----------
        rate : float
            Frames per second.
        """
        if self.labeler is None:
            return []
        lab, model = self.labeler, self.labeler.model
        free = model.spatial.names
        body = self.tally.unnamed_body()
        return label_warnings(free, self.tally.shares([lab.names.index(n) for n in free]),
                              trained_rigid=model.rigid, rigid=None if lab.finder is None else lab.finder.rigid,
                              lost=len(lab.lost_frames), frames=self.tally.frames,
                              labelled=self.tally.labelled_share, released=lab.released, rate=rate,
                              found_wider=lab.widened) + ([] if body is None else [unnamed_body_warning(body, False)])

    def idle(self) -> None:
        """The work the last frame left for before the next one (the labeler's filters and its periodic
        re-alignment to the take, :meth:`OnlineLabeler.idle`; the solver's solve from the markers alone,
        :meth:`FrameSolver.idle`): call it once the frame's result is sent, so that its cost falls between frames.
        Without it, the next :meth:`frame` does it first (same labels, same joints)."""
        if self.labeler is not None:
            self.labeler.idle()
        self.solver.idle()
