"""Steps of labeling: ``label`` unlabeled points with a trained model, ``score_labels`` against the truth."""

from __future__ import annotations

import json
import warnings

import numpy as np

from handcap.core.errors import HandcapError, HandcapWarning, merge_warnings
from handcap.core.markers import MarkerSequence
from handcap.io import atomic_output, check_not_input, check_output, read_markers, read_points, write_markers
from handcap.labeling import LabelingModel, label_take, objects_from_take, score_labels as score
from handcap.labeling.fingers import untangle
from handcap.labeling.model import is_labeling_model
from handcap.layouts import load_layout
from handcap.layouts.chains import finger_chains, thumb_chain
from handcap.solve import Priors, calibrate_attachment
from handcap.solve.relabel import CALIBRATION_PRIOR, check_labels
from handcap.steps.step import Step


def label(path, out, *, train, layouts, model=None, method: str = "viterbi", hypotheses: int = 5, lag: int = 0,
          offline: bool = False, seed: int = 0, objects=None, units: str | None = None,
          hand_check: bool = True) -> Step:
    """Label the unlabeled points of a take (see :func:`handcap.labeling.label_take`) and write the labeled markers.

    Parameters
    ----------
    path, out : str or Path
        Unlabeled points (any marker file, or a points .npz); the labeled markers to write.
    train : sequence of str or Path
        Labeled range-of-motion takes holding every layout's markers, or (with ``model``) one saved model .npz.
    layouts : sequence of str
        One marker layout per hand in the stream (shipped names or .toml files).
    model : str, Path or None
        Also save the trained model here; if ``train`` is one such model, it is used and not written again.
    method : {'viterbi', 'nearest'}
        The labeler, or the nearest-neighbour baseline.
    hypotheses, lag : int
        N best assignments per frame; look-ahead frames before deciding (0: online).
    offline : bool
        Decide on the whole take, in two passes.
    seed : int
        Seed of the mixture fits.
    objects : sequence of str or None
        Rigid objects in the stream: each the comma-separated names (or a pattern) of its markers in ``train[0]``.
    units : {'mm', 'cm', 'm'} or None
        Unit of the input's and the training takes' coordinates, overriding what the files say.
    hand_check : bool
        With ``offline`` and one hand's layout: move labels between the fingers' markers where the fingers'
        anatomy asks for it (:func:`handcap.labeling.fingers.untangle`), then check the labels against the hand
        solved from them (:func:`handcap.solve.relabel.check_labels`, its attachment calibrated on the labelled
        take).
    """
    train = list(train)
    check_not_input(out, path, *train)
    reuse = bool(model) and len(train) == 1 and is_labeling_model(train[0])
    if model and not reuse:
        check_not_input(model, path, *train, out)
    marker_layouts = [load_layout(name) for name in layouts]
    if len(marker_layouts) > 1 and (model or method == "nearest"):
        raise HandcapError("several --layout (hands) label with the viterbi labeler and save no --model; "
                           "give one --layout for those")
    points = read_points(path, units=units)
    if reuse:
        models = [LabelingModel.load(train[0])]
    else:
        hand = [m.name for layout in marker_layouts for m in layout.hand_markers]
        takes = [read_markers(take, units=units, hand=hand) for take in train]
        models = [LabelingModel.train(takes, layout.names, layout.rigid, seed=seed) for layout in marker_layouts]
    options = {} if method == "nearest" else dict(hypotheses=hypotheses, lag=lag)
    if objects:
        if method == "nearest":
            raise HandcapError("--object works with the viterbi labeler")
        if reuse:
            raise HandcapError("--object learns the object's shape from a labeled take: give one as --train")
        options["objects"] = objects_from_take(read_markers(train[0]), objects)
    result = label_take(points, models[0] if len(models) == 1 else models, offline=offline, method=method, **options)
    trained = [w for m in models for w in m.warnings]  # issued when trained; stored with the labels too
    labelled = result.markers.with_warnings(*trained) if trained else result.markers
    lines, found = (f"{out}: {result.summary()}",), merge_warnings(trained, result.warnings)
    if offline and hand_check and method != "nearest" and len(marker_layouts) == 1:
        labelled, line = untangled(labelled, models[0], marker_layouts[0])
        lines += (line,) if line else ()
        labelled, line = checked_by_hand(labelled, points, marker_layouts[0])
        lines, found = lines + (line,), merge_warnings(found, labelled.warnings)
    write_markers(labelled, out)
    written = (str(out),)
    if model and not reuse:
        models[0].save(model)
        written += (str(model),)
    return Step(lines, found, written, result)


def untangled(labelled: MarkerSequence, model: LabelingModel, layout) -> tuple[MarkerSequence, str]:
    """A labelled take's finger labels checked against the fingers' anatomy (:func:`handcap.labeling.fingers.untangle`).

    Parameters
    ----------
    labelled : MarkerSequence
        The labeler's output, metres.
    model : LabelingModel
        The model that labelled it.
    layout : MarkerLayout
        The hand's layout: its long fingers with 3 or more markers are checked; its palm markers keep their labels.

    Returns
    -------
    markers : MarkerSequence
        The labels after the check.
    line : str
        What changed; empty when the layout has fewer than two such fingers or the model no rigid set.
    """
    chains = finger_chains(layout)
    if len(chains) < 2 or model.rigid is None:
        return labelled, ""
    fixed = [m.name for m in layout.markers if m.segment == "palm"]
    result = untangle(labelled, model, chains, thumb=thumb_chain(layout), fixed=fixed)
    return result.markers, result.summary()


def checked_by_hand(labelled: MarkerSequence, points, layout) -> tuple[MarkerSequence, str]:
    """A labelled take's hand markers checked against the hand solved from them.

    The attachment is calibrated on the take itself, with only a slight pull to the open hand
    (:data:`handcap.solve.relabel.CALIBRATION_PRIOR`; see :func:`handcap.solve.relabel.check_labels`); markers
    of other layouts (objects) are left as they are.

    Parameters
    ----------
    labelled : MarkerSequence
        The labeler's output, metres.
    points : PointCloudSequence or MarkerSequence
        The take's unlabelled points, metres.
    layout : MarkerLayout
        The hand's layout.

    Returns
    -------
    markers : MarkerSequence
        The labels after the check, with its warnings (many labels removed, too few frames explained).
    line : str
        What changed, or why nothing was checked.
    """
    # A marker the labeler never gave (another subject's, far from where the model expects it) is left out of
    # the check rather than stopping it.
    given = {n for n in labelled.names if not np.isnan(labelled.positions[:, labelled.index(n)]).all()}
    never = [n for n in layout.names if n not in given]
    try:
        with warnings.catch_warnings():  # the calibration serves the check only: its own figures are no result
            warnings.simplefilter("ignore", HandcapWarning)
            layout = layout.subset(n for n in layout.names if n not in never)
            attachment = calibrate_attachment(labelled.select(layout.names), layout, priors=Priors(
                rest=np.zeros(27), rest_weight=CALIBRATION_PRIOR)).attachment
            check = check_labels(labelled, points, attachment, rigid=layout.rigid)
    except HandcapError as error:
        return labelled, f"labels not checked against the solved hand: {error}"
    positions = labelled.positions.copy()
    positions[:, [labelled.index(n) for n in check.markers.names]] = check.markers.positions
    line = check.summary() + (f" ({', '.join(never)} never labelled: not checked)" if never else "")
    return MarkerSequence(positions, labelled.names, labelled.rate, warnings=labelled.warnings), line


def score_labels(labeled, truth, *, out=None, units: str | None = None) -> Step:
    """Score a labeling against the truth in the categories of Table 1 (see :func:`handcap.labeling.score_labels`).

    Parameters
    ----------
    labeled, truth : str or Path
        Labeled markers (written by ``label``) and the true labels.
    out : str, Path or None
        Also write the scores as JSON.
    units : {'mm', 'cm', 'm'} or None
        Unit of both files' coordinates, overriding what they say.
    """
    if out:
        check_output(out, labeled, truth)
    result = score(read_markers(labeled, units=units), read_markers(truth, units=units))
    if out:
        with atomic_output(out, "w") as fh:
            json.dump(result.to_dict(), fh, indent=2)
    return Step((result.table(f"{labeled} against {truth}"),), (), (str(out),) if out else (), result)
