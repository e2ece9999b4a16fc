"""Whether the cubies as seen agree with a cube's track: a turn missed or misread, said, not left silent.

Each cubie seen with its own markers gives the cube's orientation through the track's arrangement (its rotation
in the cube's frame). Where the track is right, every seen cubie gives the same one; a turn missed or misread
leaves a layer's cubies turned from the others about an axis of the cube.
"""

from __future__ import annotations

import numpy as np

from handcap.core.rotations import axis_angle_from_matrix
from handcap.objects.cube import HOME

#: Two cubies seen in one frame contradict the track when the cube's orientations they give differ by more than
#: this (degrees) about an axis of the cube. A missed or misread turn leaves a layer 90 deg off; over 100 synthetic
#: takes read right (3 markers a cubie, 0.5 mm noise, 4 or 6 cameras, 12-60 Hz) no frame passed 12 deg.
DISAGREE_DEG = 30.0
#: Frames that must contradict the track for a warning: one frame alone can be a cubie whose swapped labels still
#: fit its shape (before pairs turned about other axes were left out, one such frame gave 180 deg in a take read
#: right).
DISAGREE_FRAMES = 2
#: The quickest quarter turn of a hand, seconds (speed-cubers turn ten layers a second): where a take reads no
#: turn of its own, a start this long without a view of the cube could hide one.
QUICK_TURN_SECONDS = 0.1


def disagreement(seen_rotation, seen, cubie_rotation, *, axis_deg: float = 20.0) -> np.ndarray:
    """How far the cubies as seen disagree with an arrangement, frame by frame.

    Each seen cubie's rotation in the world and its rotation in the cube's frame give the cube's orientation;
    where the arrangement is right, every seen cubie gives the same one (within the noise). A turn missed or
    misread leaves a layer's cubies turned from the others about one of the cube's axes: pairs that differ about
    another axis (a cubie's own fit spoilt, e.g. two of its labels swapped across a symmetric triangle of
    markers, 180 deg about an axis in its plane) are not counted.

    Parameters
    ----------
    seen_rotation : ndarray (T, 8, 3, 3)
        Every cubie's rotation in the world (from its own markers), any value where not seen.
    seen : ndarray (T, 8) bool
    cubie_rotation : ndarray (T, 8, 3, 3)
        The arrangement: every cubie's rotation in the cube's frame.
    axis_deg : float
        Largest angle between a pair's turn axis and the nearest axis of the cube, degrees.

    Returns
    -------
    ndarray (T,)
        The largest angle between two seen cubies' cube orientations, radians; NaN where fewer than 2 are seen.
    """
    seen = np.asarray(seen, dtype=bool)
    cube = np.einsum("tcij,tckj->tcik", np.where(seen[..., None, None], seen_rotation, np.eye(3)), cubie_rotation)
    a, b = np.triu_indices(8, 1)  # the 28 pairs
    turn = axis_angle_from_matrix(np.einsum("tpji,tpjk->tpik", cube[:, a], cube[:, b]))  # (T, 28, 3): b from a
    angle = np.linalg.norm(turn, axis=-1)
    along = np.abs(turn).max(axis=-1) / np.maximum(angle, 1e-300)  # 1 for a turn about an axis of the cube
    pairs = seen[:, a] & seen[:, b] & (along >= np.cos(np.deg2rad(axis_deg)))
    out = np.where(pairs, angle, 0.0).max(axis=1)
    return np.where(seen.sum(axis=1) >= 2, out, np.nan)


def check_track(seen_rotation, seen, cubie_rotation, first: int, rate: float, moves: str,
                quickest: float) -> tuple[str, ...]:
    """Warnings where the cubies as seen contradict a track (a turn missed or misread), or cannot rule out a
    turn before its moves are read.

    Parameters
    ----------
    seen_rotation : ndarray (T, 8, 3, 3)
    seen : ndarray (T, 8) bool
        Every cubie's rotation in the world from its own markers, where seen
        (:func:`handcap.objects.cube_track.cubie_poses`).
    cubie_rotation : ndarray (T, 8, 3, 3)
        The track's arrangement (:attr:`handcap.objects.cube_track.CubeTrack.cubie_rotation`).
    first : int
        The frame the moves are read from; a turn before it is not read.
    rate : float
        Frames per second.
    moves : str
        The moves read.
    quickest : float
        Frames the quickest turn took (the take's own, or :data:`QUICK_TURN_SECONDS`).

    Returns
    -------
    tuple of str
        One line per finding:

        - frames before ``first`` that contradict its arrangement: a turn was not read;
        - else, a start with no pair of seen cubies across each axis (the two of a pair lie on either side; a
          turn about that axis would part them) for longer than ``quickest``: a turn could hide there;
        - :data:`DISAGREE_FRAMES` or more frames after ``first`` that contradict the track
          (:data:`DISAGREE_DEG`).
    """
    off = np.rad2deg(disagreement(seen_rotation, seen, cubie_rotation))
    bad = np.nan_to_num(off) > DISAGREE_DEG
    out = []
    side = np.einsum("nij,nj->ni", np.rint(cubie_rotation[max(first - 1, 0)]).astype(int), HOME)  # start places
    spans = np.stack([(seen & (side[:, a] < 0)).any(axis=1) & (seen & (side[:, a] > 0)).any(axis=1)
                      for a in range(3)], axis=1)[:first + 1]  # (first + 1, 3): a pair seen across each axis
    blind = max(int(np.argmax(spans[:, a])) if spans[:, a].any() else first for a in range(3))
    start = (f"the moves are read from {first / rate:.2f} s (frame {first}), where {int(seen[first].sum())} of the "
             f"cube's 8 cubies are first seen at once")
    if bad[:first].any():
        out.append(f"cube: a turn before {first / rate:.2f} s is not read: {start}, and {int(bad[:first].sum())} "
                   f"frames before it show cubies up to {np.nanmax(off[:first]):.0f} deg from that arrangement")
    elif blind > quickest:
        out.append(f"cube: {start}, and no cubies on either side of each axis are seen before {blind / rate:.2f} "
                   f"s: a turn then (the quickest read took {quickest / rate:.2f} s) would not be read")
    late = first + np.flatnonzero(bad[first:])
    if len(late) >= DISAGREE_FRAMES:
        out.append(f"cube: in {len(late)} frames ({late[0] / rate:.2f}-{late[-1] / rate:.2f} s) the cubies seen are "
                   f"up to {off[late].max():.0f} deg from where the moves read put them: a turn was missed or "
                   f"misread, and the moves {moves!r} may be wrong")
    return tuple(out)
