"""Whether a labelling is plausible: the warnings a labelled take, offline or streamed live, carries.

A labeler given another subject, another glove or a marker stuck back elsewhere still labels, and its labels
may be wrong without any error. What shows it is counted as it labels: the rigid set re-learned from the take
(its distances more than :data:`RIGID_CHANGE_WARNING` from training), the hand frame lost in more than
:data:`LOST_WARNING` of the frames, a label given in under :data:`MISSING_SHARE` as many frames as the median
label (hidden, missing, or far from where training puts it), fewer than :data:`LABELLED_WARNING` of the points
labelled, and labels released to the spatial model (:mod:`handcap.labeling.release`). :func:`label_warnings`
says each in one line; :func:`handcap.labeling.label_take` stores them with its result, and a live stream
(:class:`LabelTally` counting frame by frame) prints them at its end.
"""

from __future__ import annotations

from collections import deque

import numpy as np

from handcap.labeling.discover import find_rigid_body
from handcap.labeling.release import release_warning
from handcap.labeling.rigid_set import RigidSet
from handcap.labeling.relearn import largest_change

#: A label given in fewer than this share of the frames the median label is given in was not found where the
#: training take puts it (another subject's knuckle marker 15 mm off, its components 1 mm wide): warned, and
#: searched for ``MISSING_SPREAD`` wider.
MISSING_SHARE = 0.5
#: How much wider (metres, isotropic standard deviation added to each component) such a label is searched for.
#: Chosen offline on synthetic subjects 7, 9 and 11 of the labeling benchmark (correct % of the points): 3 and 5 mm
#: gave the same, 8 mm confused neighbouring labels (subject 7: 96.9 % at 5 mm, 85.8 % at 8 mm).
MISSING_SPREAD = 0.005
#: Warn when the hand frame is lost in more than this share of the frames.
LOST_WARNING = 0.05
#: Warn when fewer than this share of the points in the stream get a label.
LABELLED_WARNING = 0.95
#: Warn when the rigid markers' distances in the take differ from training by more than this (metres): the
#: rigid set was re-learned from the take (a marker stuck back elsewhere, another glove or subject), and the
#: labels rest on that.
RIGID_CHANGE_WARNING = 0.002
#: Where the labels leave more than ``1 - LABELLED_WARNING`` of the points, a rigid body among the points left (an
#: object not given, :func:`~handcap.labeling.discover.find_rigid_body`) is named in a warning; offline
#: (``label_take``) its markers are then labelled ``object:0``, ``object:1``, ... as a known object's: a synthetic
#: glove-13 grasp of a cylinder (its 10 markers found) 98.81 / 0.831 -> 100.00 / 0.000 % correct / wrong.
UNNAMED = "object"
#: A live stream keeps every this-many-th frame's points left without a label ...
LEFT_EVERY = 10
#: ... of the last this-many such frames, for :meth:`LabelTally.unnamed_body`.
LEFT_KEPT = 300
#: Points each of two labels needs before :func:`reversed_pairs` compares where they lie: half of a widening trial's
#: 200 frames, several poses (in a few dozen frames, one pose, a curled finger can hold its tip behind its DIP:
#: judged on 30 points, section 9's seed 13 exchanged ``pinky_tip`` and ``pinky_dip`` wrongly).
REVERSED_LEAST = 100


def unnamed_body_warning(body: RigidSet, labelled: bool) -> str:
    """One line naming a rigid body found among the points no label was given (:func:`find_rigid_body`).

    Parameters
    ----------
    body : RigidSet
        The body found, its markers named ``object:0``, ...
    labelled : bool
        Whether its markers were then labelled as an object's (offline), or only found (online, live).
    """
    return (f"{len(body.names)} of the points no label was given keep their distances, as a rigid body's markers do "
            "(an object not given to the labeler?): " + (
                f"labelled {body.names[0]}-{body.names[-1]} and kept out of the hand's labels" if labelled else
                f"they may pass for the hand's markers; label the take offline, which labels them "
                f"{body.names[0].split(':')[0]}:0-{len(body.names) - 1}, or give the object"))


def missing_labels(given) -> np.ndarray:
    """Mask (M,) of labels given in under :data:`MISSING_SHARE` of the frames the median label is given in.

    Parameters
    ----------
    given : ndarray (M,)
        Share of the frames each label is given in.
    """
    given = np.asarray(given, dtype=np.float64)
    return given < MISSING_SHARE * np.median(given)


def reversed_pairs(expected, points) -> np.ndarray:
    """Pairs of labels whose points lie the other way round than the model's means say.

    Another subject's knuckles sit millimetres otherwise than the training subject's, but not in another order:
    where the mean of label a's points lies on the far side of label b's mean (the difference of the two means
    points against the difference of the model's means), one of the two labels holds the other's marker.

    Parameters
    ----------
    expected : ndarray (M, 3)
        Each label's mean in the model, metres, hand frame.
    points : ndarray (N, M, 3)
        Labelled points in the same frame (N frames), NaN where a label has none.

    Returns
    -------
    ndarray (M, M) bool
        Symmetric; only pairs of labels with :data:`REVERSED_LEAST` points each.
    """
    points = np.asarray(points, dtype=np.float64)
    seen = np.isfinite(points).all(axis=-1)
    counts = seen.sum(axis=0)
    means = np.where(seen[..., None], points, 0.0).sum(axis=0) / np.maximum(counts, 1)[:, None]
    expected = np.asarray(expected, dtype=np.float64)
    along = np.einsum("abi,abi->ab", means[:, None] - means[None], expected[:, None] - expected[None])
    enough = counts >= REVERSED_LEAST
    return (along < 0) & enough[:, None] & enough[None]


def label_warnings(names, given, *, trained_rigid=None, rigid=None, lost: int = 0, frames: int = 0,
                   labelled=float("nan"), released=(), rate: float = 1.0, found_wider=()) -> list[str]:
    """The one-line warnings of a labelling (not issued: the caller warns and stores them).

    Parameters
    ----------
    names : sequence of str (M,)
        The free labels (the spatial model's).
    given : ndarray (M,)
        Share of the frames each is given in.
    trained_rigid, rigid : RigidSet, optional
        The rigid set trained and the one the labels rest on (re-learned from the take, or the same).
    lost : int
        Frames in which the hand frame was lost.
    frames : int
        Frames labelled.
    labelled : float
        Share of the points that got a label (NaN: no points).
    released : sequence of Release
        Labels released to the spatial model.
    rate : float
        Frames per second (for the releases' times).
    found_wider : sequence of str
        Labels searched for :data:`MISSING_SPREAD` wider than training (hardly given otherwise).

    Returns
    -------
    list of str
    """
    lines = []
    if len(found_wider):
        these = "these labels" if len(found_wider) > 1 else "this label"
        lines.append(f"{', '.join(found_wider)} not found where the training take puts "
                     f"{'them' if len(found_wider) > 1 else 'it'}; labelled after a search {1000 * MISSING_SPREAD:.0f} "
                     f"mm wider (another subject or marker placement): check {these}, or train on a take of this "
                     "subject")
    if trained_rigid is not None and rigid is not None:
        change = largest_change(trained_rigid, rigid)
        if change > RIGID_CHANGE_WARNING:
            lines.append(f"the rigid markers' distances in this take differ from training by up to "
                         f"{1000 * change:.1f} mm (re-learned from the take; plausible <= "
                         f"{1000 * RIGID_CHANGE_WARNING:.0f} mm): a marker moved, or another glove or subject; "
                         "check the labels, or train on a take of this session")
    given = np.asarray(given, dtype=np.float64)
    if frames and len(given):
        missing = missing_labels(given)
        if missing.any():
            starved = [n for n, m in zip(names, missing) if m]
            them = "them" if len(starved) > 1 else "it"
            lines.append(f"{', '.join(starved)} labelled in {', '.join(f'{100 * g:.0f}' for g in given[missing])} "
                         f"% of the frames, against {100 * np.median(given):.0f} % for the median label: hidden most "
                         f"of the take, missing from it, or far from where the training take puts {them}; check the "
                         "markers, or train on a take of this subject")
    if lost > LOST_WARNING * max(frames, 1):
        lines.append(f"hand frame lost in {100 * lost / max(frames, 1):.1f} % of the frames ({lost} of {frames}; "
                     f"plausible <= {100 * LOST_WARNING:.0f} %): the rigid markers were not found at their trained "
                     "distances; check the layout's rigid markers or train on a take of this session")
    line = release_warning(released, rate)
    if line:
        lines.append(line)
    if labelled < LABELLED_WARNING:  # False for NaN: no points, nothing to label
        lines.append(f"labels for {100 * labelled:.1f} % of the points in the stream (plausible >= "
                     f"{100 * LABELLED_WARNING:.0f} %): many points fit no label; check the layout and the "
                     "training take")
    return lines


class LabelTally:
    """What a stream's labels add up to, frame by frame, for :func:`label_warnings` at its end.

    Parameters
    ----------
    labels : int
        Labels (the labeler's ``names``), each frame's labels index them.
    """

    def __init__(self, labels: int):
        self.frames = 0
        self.given = np.zeros(labels, dtype=np.int64)  # frames each label was given in
        self.points = self.labelled = 0
        self.left: deque = deque(maxlen=LEFT_KEPT)  # points left without a label, every LEFT_EVERY-th frame

    def unnamed_body(self) -> RigidSet | None:
        """A rigid body among the points left without a label (:func:`find_rigid_body`), where the labels leave
        more than ``1 - LABELLED_WARNING`` of the points; else None."""
        if not self.labelled_share < LABELLED_WARNING or not self.left:
            return None
        return find_rigid_body(list(self.left), name=UNNAMED)

    def add(self, labels, valid=None, points=None) -> None:
        """Count one frame's labels.

        Parameters
        ----------
        labels : ndarray (K,) int
            Each point's label, -1 for none.
        valid : ndarray (K,) bool, optional
            The points that were points (not NaN rows); default every one.
        points : ndarray (K, 3), optional
            The points (metres): every :data:`LEFT_EVERY`-th frame's points left without a label are kept (the
            last :data:`LEFT_KEPT` such frames) for :meth:`unnamed_body`.
        """
        labels = np.asarray(labels)
        if points is not None and self.frames % LEFT_EVERY == 0:
            left = labels < 0 if valid is None else (labels < 0) & np.asarray(valid, dtype=bool)
            self.left.append(np.asarray(points, dtype=np.float64)[left])
        self.frames += 1
        self.points += int(len(labels) if valid is None else np.count_nonzero(valid))
        given = labels[labels >= 0]
        self.labelled += len(given)
        self.given[np.unique(given)] += 1

    def shares(self, columns) -> np.ndarray:
        """Share of the frames each of the labels ``columns`` (indices) was given in."""
        return self.given[np.asarray(columns, dtype=int)] / max(self.frames, 1)

    @property
    def labelled_share(self) -> float:
        """Share of the points that got a label (NaN for none)."""
        return self.labelled / self.points if self.points else float("nan")
