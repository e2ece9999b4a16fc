"""What a cube's track gives: the object motion written for it, every marker's fitted place, and its errors
against a known truth (synthetic takes, benchmarks).

The track itself is :func:`handcap.objects.cube_track.track_cube`.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from handcap.core.motion import ObjectMotion
from handcap.objects.articulated import ArticulatedObject
from handcap.core.rotations import rotation_angle
from handcap.objects.cube import FACE_ORDER
from handcap.objects.cube_track import CubeTrack


def cube_errors(track: CubeTrack, pose, cubie_rotation) -> dict:
    """How far a track is from the truth, frame by frame.

    Parameters
    ----------
    track : CubeTrack
    pose : ndarray (T, 4, 4)
        The true cube frame (its body, the cubies not turning) to the world, metres.
    cubie_rotation : ndarray (T, 8, 3, 3)
        The true cubie rotations in the cube's frame.

    Returns
    -------
    dict
        ``position_mm`` (T,) and ``rotation_deg`` (T,): the cube's pose; ``layer_deg`` (T,): the largest
        error of a cubie's rotation in the cube's frame (the turning layer's angle, which quarter it is
        at included); NaN where the track has no pose.
    """
    rot = Rotation.from_rotvec(np.nan_to_num(track.rotation)).as_matrix()
    found = np.isfinite(track.translation).all(axis=1)
    position = np.linalg.norm(track.translation - pose[:, :3, 3], axis=1) * 1000
    rotation = np.rad2deg(rotation_angle(np.einsum("tji,tjk->tik", rot, pose[:, :3, :3])))
    layer = np.rad2deg(rotation_angle(np.einsum("tnji,tnjk->tnik", track.cubie_rotation, cubie_rotation))).max(axis=1)
    rotation[~found] = np.nan
    return {"position_mm": position, "rotation_deg": rotation, "layer_deg": layer}


def cube_motion(track: CubeTrack, cube: ArticulatedObject, rate: float, warnings=()) -> tuple[ObjectMotion, dict]:
    """A cube's track as the object motion ``track-object --articulated`` writes, and the arrays written with it.

    Parameters
    ----------
    track : CubeTrack
    cube : ArticulatedObject
    rate : float
        Frames per second.
    warnings : sequence of str
        Stored with the motion, after the track's own (:attr:`CubeTrack.warnings`).

    Returns
    -------
    motion : ObjectMotion
        The cube's pose (NaN where none), its markers' places on it, ``layer_angles`` (T, 6) as extra.
    extra : dict
        ``moves``, ``faces`` (the order of the layer angles), ``cubie_rotation`` (T, 8, 3, 3) and
        ``cubie_of_marker`` (M,), for :func:`handcap.io.write_object_motion`.
    """
    motion = ObjectMotion(track.rotation, track.translation, rate, cube.name, cube.marker_names, cube.markers,
                          {"layer_angles": track.layer_angle}, tuple(track.warnings) + tuple(warnings))
    return motion, {"moves": np.array(track.moves), "faces": np.array("".join(FACE_ORDER)),
                    "cubie_rotation": track.cubie_rotation,
                    "cubie_of_marker": np.repeat(np.arange(8), [len(p.marker_names) for p in cube.parts])}


def fitted_markers(track: CubeTrack, cube: ArticulatedObject) -> np.ndarray:
    """Where the track puts every marker of the cube in every frame (the gaps of a take filled).

    Parameters
    ----------
    track : CubeTrack
    cube : ArticulatedObject
        The description it was tracked with.

    Returns
    -------
    ndarray (T, M, 3)
        Metres, description order; NaN where the track has no pose.
    """
    cubie = np.repeat(np.arange(8), [len(p.marker_names) for p in cube.parts])
    turn = Rotation.from_rotvec(np.nan_to_num(track.rotation)).as_matrix()
    local = np.einsum("tmij,mj->tmi", track.cubie_rotation[:, cubie], cube.markers)
    return np.einsum("tij,tmj->tmi", turn, local) + track.translation[:, None]
