"""The rigid marker set: a hand's back-of-hand markers (or a held object's), learned from labeled takes.

A :class:`RigidSet` holds the names of three or more markers that keep their
distances to each other, their shape in the set's own frame (metres) and the
distance tolerance within which a pair of points may pass for a pair of its
markers. It is learned from one labeled take (:meth:`RigidSet.from_training`),
pooled over several (:meth:`RigidSet.from_takes`), given for a rigid object
(:meth:`RigidSet.for_object`, :func:`objects_from_take`) and stored in a
model's ``.npz``. Finding the set among unlabeled points is
:mod:`handcap.labeling.frame`'s.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from handcap.core.errors import HandcapError
from handcap.core.markers import MarkerSequence, expand_names
from handcap.objects.rigid import canonical_from_markers


@dataclass(frozen=True)
class RigidSet:
    """The rigid markers of a hand: names and positions in the hand frame.

    Attributes
    ----------
    names : tuple of str (R,)
    canonical : ndarray (R, 3)
        Metres, hand frame (centred on the markers' mean).
    tolerance : float
        A pair of points matches a pair of markers when their distances differ
        by less than this, metres.
    """

    names: tuple
    canonical: np.ndarray
    tolerance: float

    @classmethod
    def from_training(cls, names, positions, *, min_tolerance: float = 0.003) -> "RigidSet":
        """From labeled training positions (T, R, 3) of the rigid markers, metres, NaN where missing.

        Parameters
        ----------
        names : sequence of str (R,)
            The rigid markers, 3 or more.
        positions : array_like (T, R, 3)
            Their labeled positions, metres, NaN where missing.
        min_tolerance : float
            Least distance tolerance, metres.

        Returns
        -------
        RigidSet
            Canonical shape (R, 3) in metres from :func:`~handcap.objects.rigid.canonical_from_markers`;
            tolerance four standard deviations of the most variable marker-to-marker distance
            over the take, at least ``min_tolerance``, metres.

        Raises
        ------
        HandcapError
            Fewer than 3 names, a marker never seen, or fewer than 3 frames with 3 markers seen together.
        """
        positions = np.asarray(positions, dtype=np.float64)
        if len(names) < 3:
            raise HandcapError(f"a hand frame needs at least 3 rigid markers, got {len(names)}: {', '.join(names)}")
        seen = ~np.isnan(positions[..., 0])
        for name, s in zip(names, seen.T):
            if not s.any():
                raise HandcapError(f"rigid marker {name!r} never appears in the training take")
        if (seen.sum(axis=1) >= 3).sum() < 3:
            raise HandcapError("the training take shows 3 rigid markers together in fewer than 3 frames")
        canonical = canonical_from_markers(positions)
        # How much the distances vary over the take (skin, glove, noise): tolerance = 4 standard deviations.
        i, j = np.triu_indices(len(names), 1)
        d = np.linalg.norm(positions[:, i] - positions[:, j], axis=-1)
        spread = np.nanstd(d, axis=0)
        tolerance = float(max(min_tolerance, 4 * np.nanmax(spread)))
        return cls(tuple(names), canonical, tolerance)

    @classmethod
    def from_takes(cls, names, takes) -> "RigidSet":
        """From the rigid markers of several labeled takes [(T_k, R, 3), ...], metres, NaN where missing.

        The shape is the first take's; the tolerance is four standard
        deviations of how each distance varies within a take (skin, glove,
        noise), pooled over the takes and taken at the most variable pair,
        but never under twice the rounding of a marker file (0.1 mm). A
        triad put on again between takes changes the distances from take to
        take: that is not noise, and :func:`handcap.labeling.relearn.rigid_from_take`
        finds the new shape in the take being labelled.

        Parameters
        ----------
        names : sequence of str (R,)
            The rigid markers, 3 or more.
        takes : sequence of array_like (T_k, R, 3)
            Their labeled positions in each take, metres, NaN where missing.

        Returns
        -------
        RigidSet
            Canonical shape (R, 3) and tolerance in metres.

        Raises
        ------
        HandcapError
            As :meth:`from_training`, for the first take.
        """
        takes = [np.asarray(p, dtype=np.float64) for p in takes]
        first = cls.from_training(names, takes[0])
        i, j = np.triu_indices(len(names), 1)
        spread = []
        for p in takes:
            d = np.linalg.norm(p[:, i] - p[:, j], axis=-1)
            spread.append(d - np.nanmedian(d, axis=0))
        spread = np.nanstd(np.concatenate(spread), axis=0)
        return cls(first.names, first.canonical, float(max(4 * np.nanmax(spread), 2e-4)))

    @classmethod
    def for_object(cls, names, canonical, *, tolerance: float = 0.0015) -> "RigidSet":
        """A rigid object's markers from their positions in its frame (M, 3), metres.

        Truly rigid bodies keep their distances to within the reconstruction
        noise, so the tolerance is tighter than a glove's (1.5 mm): a fingertip
        touching the object must not pass for one of its markers.

        Parameters
        ----------
        names : sequence of str (M,)
            The object's markers, 3 or more.
        canonical : array_like (M, 3)
            Their positions in the object frame, metres (used as given, not centred).
        tolerance : float
            Distance tolerance, metres.

        Returns
        -------
        RigidSet

        Raises
        ------
        HandcapError
            Fewer than 3 markers, or ``canonical`` not of shape (M, 3).
        """
        canonical = np.asarray(canonical, dtype=np.float64)
        if canonical.ndim != 2 or canonical.shape != (len(names), 3) or len(names) < 3:
            raise HandcapError(f"an object needs 3 or more markers with canonical positions (M, 3); got "
                               f"{len(names)} names and shape {canonical.shape}")
        return cls(tuple(names), canonical, float(tolerance))

    def to_arrays(self) -> dict:
        """The set as ``.npz`` entries: ``rigid_names``, ``rigid_canonical`` (R, 3) and ``rigid_tolerance``, metres."""
        return {"rigid_names": np.array(self.names), "rigid_canonical": self.canonical,
                "rigid_tolerance": np.float64(self.tolerance)}

    @classmethod
    def from_arrays(cls, data) -> "RigidSet":
        """The set stored by :meth:`to_arrays`.

        Parameters
        ----------
        data : mapping of str to ndarray
            Holds ``rigid_names``, ``rigid_canonical`` (R, 3) metres and ``rigid_tolerance`` metres.

        Returns
        -------
        RigidSet
        """
        return cls(tuple(str(n) for n in data["rigid_names"]), np.asarray(data["rigid_canonical"], dtype=np.float64),
                   float(data["rigid_tolerance"]))


#: The least distance tolerance of a rigid object's markers learned from a take, metres (a soft object varies more,
#: and its own spread then sets it).
OBJECT_MIN_TOLERANCE = 0.0015


def objects_from_take(markers: MarkerSequence, specs) -> list[RigidSet]:
    """Rigid objects for the labeler: per spec, those markers of a labeled take, with the shape and rigidity it shows.

    Parameters
    ----------
    markers : MarkerSequence
        A labeled take, metres.
    specs : sequence of str
        One per object: comma-separated names or patterns such as ``box:*`` (:func:`expand_names`).

    Returns
    -------
    list of RigidSet
        One per spec, canonical shape in metres, tolerance at least :data:`OBJECT_MIN_TOLERANCE` metres.

    Raises
    ------
    HandcapError
        A spec matching fewer than 3 markers (or none), or markers the take never shows together.
    """
    objects = []
    for spec in specs:
        names = expand_names(markers, spec)
        if len(names) < 3:
            raise HandcapError(f"--object {spec}: a rigid object needs 3 or more markers, got {len(names)}")
        positions = np.stack([markers.positions[:, markers.index(n)] for n in names], axis=1)
        objects.append(RigidSet.from_training(names, positions, min_tolerance=OBJECT_MIN_TOLERANCE))
    return objects
