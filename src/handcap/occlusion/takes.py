"""A take's markers with the pose that made them, and how a layout's names find their columns in it.

Kept apart from :mod:`handcap.occlusion.data` (synthetic takes, which needs :mod:`handcap.synth`), so that
filling a take's gaps, and every process that only fills or triangulates, does not import the simulator.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from handcap.core.errors import HandcapError


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
