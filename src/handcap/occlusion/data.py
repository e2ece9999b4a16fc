"""Training and test material: synthetic hands with known poses, and a user's takes.

:func:`synthetic_hand_takes` moves the OpenHand through the synthetic motions
of :mod:`handcap.synth.motions` for several subjects (hand shape and marker
placement drawn as ``handcap synth`` draws them) and returns the markers with
their true poses. No cameras are simulated: the networks are trained on
complete frames and the occlusions are made during training, as in the paper.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from handcap.core.errors import HandcapError
from handcap.hand import OpenHand
from handcap.hand.attachment import MarkerAttachment
from handcap.layouts import MarkerLayout, load_layout
from handcap.synth.motions import make_motion
from handcap.synth.objects import make_object
from handcap.synth.scene import DEFAULT_OBJECT, misplaced

TRAIN_MOTIONS = ("random", "open-close", "tapping", "pinch", "grasp", "precision", "rotate-cube", "wrist",
                 "calibration")


@dataclass(frozen=True)
class PosedTake:
    """Markers with the hand pose that made them.

    Attributes
    ----------
    positions : ndarray (T, M, 3)
        Metres, NaN where missing.
    names : tuple of str (M,)
    rate : float
    phi, global_orient, transl : ndarray (T, 27), (T, 3), (T, 3) or None
        The pose (radians, axis-angle, metres); None when unknown.
    betas : ndarray (10,) or None
    joints : ndarray (T, 21, 3) or None
        Metres.
    side : str
    attachment : MarkerAttachment or None
        Where the markers truly sit (synthetic takes).
    subject : str or None
        Who wore the markers (takes of one subject share it); None when unknown.
    synthetic : bool
        Made by :func:`simulate_take`, not recorded.
    """

    positions: np.ndarray
    names: tuple
    rate: float
    phi: np.ndarray | None = None
    global_orient: np.ndarray | None = None
    transl: np.ndarray | None = None
    betas: np.ndarray | None = None
    joints: np.ndarray | None = None
    side: str = "right"
    attachment: object = None
    subject: str | None = None
    synthetic: bool = False

    @property
    def has_poses(self) -> bool:
        """Whether the take carries its hand pose (``phi`` is set)."""
        return self.phi is not None


def marker_columns(take_names, names, source: str) -> list[int]:
    """Columns of ``names`` among a take's marker names, ``Subject:`` prefixes allowed.

    The same matching as :meth:`handcap.core.markers.MarkerSequence.index`, so
    ``train-occlusion`` and ``fill`` accept the same files (issue 14).

    Parameters
    ----------
    take_names : sequence of str
        The take's marker names, possibly prefixed (``Subject:name``).
    names : sequence of str
        The names wanted (a layout's), unprefixed or exact.
    source : str
        The take's file or name, for messages.

    Returns
    -------
    list of int
        Column of each of ``names`` in ``take_names``, in the order of ``names``.

    Raises
    ------
    HandcapError
        If a name is absent, or matches several prefixed markers.
    """
    take_names = tuple(take_names)
    short = tuple(n.rsplit(":", 1)[-1] for n in take_names)
    missing = [n for n in names if n not in take_names and n not in short]
    if missing:
        raise HandcapError(f"{source} lacks marker(s) {', '.join(missing)} of the layout; its markers are "
                           f"{', '.join(take_names)}")
    columns = []
    for n in names:
        if n in take_names:
            columns.append(take_names.index(n))
            continue
        matches = [i for i, s in enumerate(short) if s == n]
        if len(matches) > 1:
            raise HandcapError(f"{source}: marker name {n!r} is ambiguous: "
                               f"{', '.join(take_names[i] for i in matches)}; keep one subject's markers")
        columns.append(matches[0])
    return columns


def simulate_take(layout, motion: str, frames: int, rate: float, seed: int, *, side: str = "right",
                  noise_mm: float = 0.3, placement_mm: float = 3.0, betas=None,
                  subject_seed: int | None = None) -> PosedTake:
    """One synthetic take of a hand's markers with its true pose (no cameras, no occlusion).

    Parameters
    ----------
    layout : str or MarkerLayout
        Shipped layout name, TOML path, or a loaded layout (its hand markers are used).
    motion : str
        One of :data:`handcap.synth.motions.MOTIONS`.
    frames : int
    rate : float
    seed : int
        Draws the motion and the noise (and the subject, unless ``subject_seed`` is given).
    side : {"right", "left"}
    noise_mm : float
        Standard deviation of the marker jitter, millimetres.
    placement_mm : float
        Marker placement error, millimetres (see ``SynthConfig``).
    betas : ndarray (10,), optional
        Subject shape; drawn from the seed (standard deviation 0.5) when omitted.
    subject_seed : int, optional
        Draws the subject (shape, marker placement): takes with the same subject seed
        share them, like the takes of one session.
    """

    rng_shape, rng_place, rng_motion, rng_noise = (np.random.default_rng(s)
                                                   for s in np.random.SeedSequence(seed).spawn(4))
    if subject_seed is not None:
        rng_shape, rng_place = (np.random.default_rng(s) for s in np.random.SeedSequence([subject_seed, 1]).spawn(2))
    hand = OpenHand(side)
    betas = rng_shape.normal(0, 0.5, 10) if betas is None else np.asarray(betas, dtype=np.float64)
    attachment = MarkerAttachment.from_layout(_misplaced_hand_layout(layout, side, hand, placement_mm, rng_place),
                                              hand, betas)
    kind = DEFAULT_OBJECT.get(motion)
    obj = make_object(kind, seed=seed) if kind else None
    m = make_motion(motion, hand, frames, rate, rng_motion, obj)
    out = hand.forward(betas, m.global_orient, hand.hand_pose_from_phi(m.phi), m.transl)
    markers = attachment.positions(out.vertices, hand.faces)
    markers = markers + rng_noise.normal(0, noise_mm / 1000, markers.shape)
    subject = f"synthetic subject {seed if subject_seed is None else subject_seed}"
    return PosedTake(markers, attachment.marker_names, float(rate), m.phi, m.global_orient, m.transl, betas,
                     out.joints, side, attachment, subject, True)


def worn_by_another_subject(take: PosedTake, layout, subject_seed: int, *, placement_mm: float = 3.0,
                            betas_sd: float = 0.5, noise_mm: float = 0.3) -> PosedTake:
    """The same synthetic motion, worn by another subject: new hand shape and marker placement.

    Making a motion (grasps close until contact) costs far more than moving a
    hand through it, so many subjects are had cheaply by re-rendering a take.

    Parameters
    ----------
    take : PosedTake
        With poses (``phi``, ``global_orient``, ``transl``).
    layout : str or MarkerLayout
    subject_seed : int
        Draws the shape, the placement and the noise.
    placement_mm : float
        Marker placement error, millimetres (on the marker's own segment).
    betas_sd : float
        Standard deviation of the shape values.
    noise_mm : float
        Marker jitter, millimetres.

    Returns
    -------
    PosedTake
    """

    if not take.has_poses:
        raise HandcapError("only a take with poses can be worn by another subject")
    rng_shape, rng_place, rng_noise = (np.random.default_rng(s)
                                       for s in np.random.SeedSequence([subject_seed, 2]).spawn(3))
    hand = OpenHand(take.side)
    betas = rng_shape.normal(0, betas_sd, 10)
    attachment = MarkerAttachment.from_layout(_misplaced_hand_layout(layout, take.side, hand, placement_mm, rng_place),
                                              hand, betas)
    out = hand.forward(betas, take.global_orient, hand.hand_pose_from_phi(take.phi), take.transl)
    markers = attachment.positions(out.vertices, hand.faces)
    markers = markers + rng_noise.normal(0, noise_mm / 1000, markers.shape)
    return PosedTake(markers, attachment.marker_names, take.rate, take.phi, take.global_orient, take.transl, betas,
                     out.joints, take.side, attachment, f"synthetic subject w{subject_seed}", True)


def _misplaced_hand_layout(layout, side, hand, placement_mm, rng):

    layout = layout.for_side(side) if isinstance(layout, MarkerLayout) else load_layout(layout, side=side)
    hand_only = type(layout)(layout.name, layout.side, layout.hand_markers, layout.rigid, layout.marker_radius,
                             layout.marker_kind, layout.description)
    return misplaced(hand_only, hand, placement_mm / 1000, rng)


def synthetic_hand_takes(layout, *, subjects: int = 8, seconds_per_motion: float = 6.0, rate: float = 100.0,
                         motions=TRAIN_MOTIONS, seed: int = 0, side: str = "right", worn_by: int = 0,
                         placement_mm: float = 3.0, progress=None) -> list:
    """Synthetic takes of several subjects doing every motion: a training set for a layout.

    Parameters
    ----------
    layout : str or MarkerLayout
    subjects : int
        Subjects (shape and marker placement) per motion; each take draws its own.
    seconds_per_motion : float
    rate : float
    motions : sequence of str
    seed : int
        Take ``i`` uses seed ``seed * 100003 + i``.
    side : str
    worn_by : int
        Every take is also worn by this many other subjects
        (:func:`worn_by_another_subject`, shape values of standard deviation 1).
    placement_mm : float
        Marker placement error of those other subjects, millimetres.
    progress : callable (done, total), optional

    Returns
    -------
    list of PosedTake
        ``subjects * len(motions) * (1 + worn_by)`` takes.
    """
    if subjects < 1 or seconds_per_motion <= 0 or worn_by < 0:
        raise HandcapError("need at least one subject, a positive duration and worn_by >= 0")
    frames = max(int(round(seconds_per_motion * rate)), 2)
    takes, total = [], subjects * len(motions)
    for s in range(subjects):
        for j, motion in enumerate(motions):
            take_seed = seed * 100003 + s * len(motions) + j
            takes.append(simulate_take(layout, motion, frames, rate, take_seed, side=side))
            if progress is not None:
                progress(len(takes), total)
    others = [worn_by_another_subject(take, layout, (seed * 100003 + i) * 1009 + k, placement_mm=placement_mm,
                                      betas_sd=1.0)
              for i, take in enumerate(takes) for k in range(worn_by)]
    return takes + others
