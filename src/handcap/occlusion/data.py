"""Training and test material: synthetic hands with known poses (:class:`~handcap.occlusion.takes.PosedTake`).

:func:`synthetic_hand_takes` moves the OpenHand through the synthetic motions
of :mod:`handcap.synth.motions` for several subjects (hand shape and marker
placement drawn as ``handcap synth`` draws them) and returns the markers with
their true poses. No cameras are simulated: the networks are trained on
complete frames and the occlusions are made during training, as in the paper.
"""

from __future__ import annotations


import numpy as np

from handcap.core.errors import HandcapError
from handcap.hand import OpenHand
from handcap.hand.attachment import MarkerAttachment
from handcap.layouts import MarkerLayout, load_layout
from handcap.occlusion.takes import PosedTake
from handcap.synth.motions import make_motion
from handcap.synth.objects import make_object
from handcap.synth.scene import DEFAULT_OBJECT, misplaced

TRAIN_MOTIONS = ("random", "open-close", "tapping", "pinch", "grasp", "precision", "rotate-cube", "wrist",
                 "calibration")


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
    m = make_motion(motion, hand, frames, rate, rng_motion, obj, betas=betas)
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
