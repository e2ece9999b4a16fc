"""Step ``track_object``: the 6-DoF motion of a rigid object from its markers, or of a 2x2x2 cube with its layers."""

from __future__ import annotations

import numpy as np

from handcap.core.errors import HandcapError
from handcap.core.markers import expand_names
from handcap.core.motion import ObjectMotion
from handcap.io import check_not_input, load_npz, read_markers, write_object_motion
from handcap.objects import load_articulated, track_rigid
from handcap.objects.cube_track import FACE_ORDER, track_cube
from handcap.quality import plausibility as q
from handcap.steps.step import Step, quality_line


def track_object(path, out, *, markers=None, canonical=None, name: str = "object", threshold: float = 0.005,
                 units: str | None = None, articulated=None) -> Step:
    """Track a rigid object by Kabsch with RANSAC per frame (see :func:`handcap.objects.track_rigid`).

    Parameters
    ----------
    path, out : str or Path
        Labeled markers; the object motion .npz to write.
    markers : str or sequence of str
        The object's markers (3 or more): names, comma-separated names or patterns such as ``'box:*'``.
    canonical : str, Path or None
        Object .npz with the canonical ``(M, 3)`` marker positions, metres (default: estimated from the take).
    name : str
        The object's name.
    threshold : float
        RANSAC inlier distance, metres.
    units : {'mm', 'cm', 'm'} or None
        Unit of the input's coordinates, overriding what the file says.
    articulated : str, Path or None
        A 2x2x2 cube's description (``cube2x2``, or a TOML file, :mod:`handcap.objects.articulated`): its
        markers are found by name, and the cube's pose, layer angles (``state_layer_angles`` (T, 6), faces
        in the order R L U D F B) and moves (``moves``, standard notation) are written.
    """
    if articulated is not None:
        return _track_cube(path, out, articulated, units)
    if markers is None:
        raise HandcapError("give the object's markers (--markers) or its description (--articulated)")
    check_not_input(out, path, canonical)
    take = read_markers(path, units=units)
    names = expand_names(take, markers)
    known = None if canonical is None else load_npz(canonical, ("canonical",), "object file")["canonical"]
    track = track_rigid(take, names, known, name=name, threshold=threshold)
    motion = q.attach(track.motion, [*take.warnings, *q.object_warnings(track, threshold=threshold)])
    write_object_motion(motion, out)
    return Step((f"{out}: {track.summary()}", quality_line(motion.warnings, "  quality: ")), motion.warnings,
                (str(out),), track)


def _track_cube(path, out, articulated, units) -> Step:
    check_not_input(out, path, articulated if str(articulated) != "cube2x2" else None)
    cube = load_articulated(articulated)
    take = read_markers(path, units=units)
    missing = [n for n in cube.marker_names if n not in take.names]
    if missing:
        raise HandcapError(f"{path} lacks {len(missing)} of the {cube.name} markers ({', '.join(missing[:6])}"
                           f"{' ...' if len(missing) > 6 else ''}): label them with the description's names")
    if any(j.kind == "revolute" for j in cube.joints):
        raise HandcapError(f"{cube.name}: tracking revolute joints is not built yet; only a 2x2x2 cube's layers")
    track = track_cube(take.select(list(cube.marker_names)).positions, cube)
    motion = ObjectMotion(track.rotation, track.translation, take.rate, cube.name, cube.marker_names, cube.markers,
                          {"layer_angles": track.layer_angle}, take.warnings)
    write_object_motion(motion, out, {"moves": np.array(track.moves), "faces": np.array("".join(FACE_ORDER))})
    lost = int(np.isnan(track.translation[:, 0]).sum())
    line = (f"{out}: {cube.name} over {take.n_frames} frames, {len(track.moves.split())} moves: "
            f"{track.moves or '(none)'}" + (f"; {lost} frames without a pose" if lost else ""))
    return Step((line,), motion.warnings, (str(out),), track)
