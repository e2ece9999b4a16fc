"""Step ``track_object``: the 6-DoF motion of a rigid object from its markers, or of a 2x2x2 cube with its layers."""

from __future__ import annotations

import numpy as np

from handcap.core.errors import HandcapError
from handcap.core.markers import MarkerSequence, expand_names
from handcap.core.motion import ObjectMotion
from handcap.io import check_not_input, load_npz, read_markers, read_points, write_markers, write_object_motion
from handcap.objects import load_articulated, track_rigid
from handcap.objects.articulated import SHIPPED
from handcap.objects.cube_label import label_cube
from handcap.objects.cube_output import cube_motion, fitted_markers
from handcap.objects.cube_track import smoothing_window, track_cube
from handcap.objects.jointed import track_jointed
from handcap.quality import plausibility as q
from handcap.steps.step import Step, quality_line


def track_object(path, out, *, markers=None, canonical=None, name: str = "object", threshold: float = 0.005,
                 units: str | None = None, articulated=None, start=None, labeled=None, filled=None) -> Step:
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
        An articulated object's description (``cube2x2``, or a TOML file, :mod:`handcap.objects.articulated`):
        its markers are found by name. For a 2x2x2 cube its pose, layer angles (``state_layer_angles``
        (T, 6), faces in the order R L U D F B), every cubie's rotation (``cubie_rotation`` (T, 8, 3, 3)) and
        the moves (``moves``, standard notation) are written; for revolute joints the root part's pose, the
        joint angles (``state_joint_angles`` (T, J), radians, joints named by their child part in
        ``joints``) and the fit's RMS per frame (``fit_rms``, metres).
    start, labeled : str, Path or None
        With a 2x2x2 cube: ``path`` holds unlabelled points, and ``start`` the cube's labelled markers in at
        least one frame of the take (frame numbers as in ``path``; the first frame in which every cubie shows
        2 markers starts the labeling, :func:`handcap.objects.cube_label.label_cube`); ``labeled`` also
        writes the cube's markers so labelled.
    filled : str, Path or None
        With a 2x2x2 cube: also write its markers with every gap filled where the track puts them (seen
        markers kept as they are).
    """
    if articulated is not None:
        return _track_cube(path, out, articulated, units, start, labeled, filled)
    if start is not None or labeled is not None or filled is not None:
        raise HandcapError("--start, --labeled and --filled are for a 2x2x2 cube: give --articulated too")
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


def _track_cube(path, out, articulated, units, start, labeled, filled) -> Step:
    shipped = str(articulated) in SHIPPED
    check_not_input(out, path, None if shipped else articulated, start)
    for extra in (labeled, filled):
        if extra is not None:
            check_not_input(extra, path, None if shipped else articulated, start, out)
    obj = load_articulated(articulated)
    if start is not None:
        take, positions = _label_cube(path, obj, start, units)
        if labeled is not None:
            write_markers(take, labeled)
    else:
        if labeled is not None:
            raise HandcapError("--labeled writes the markers that --start labels: give --start too")
        take = read_markers(path, units=units)
        missing = [n for n in obj.marker_names if n not in take.names]
        short = [part.name for part in obj.parts if sum(n not in missing for n in part.marker_names) < 3]
        if short:
            raise HandcapError(f"{path} lacks {len(missing)} of the {obj.name} markers ({', '.join(missing[:6])}"
                               f"{' ...' if len(missing) > 6 else ''}): label them with the description's names, "
                               f"or give --start to label them from a labelled frame")
        # A file may leave out markers never seen (a patch corner no two cameras saw): they are missing throughout,
        # where each part keeps three to be fitted by.
        positions = take.positions_of(obj.marker_names)
        if missing:
            take = take.with_warnings(f"{path} holds {len(obj.marker_names) - len(missing)} of the {obj.name} "
                                      f"markers; the other {len(missing)} ({', '.join(missing[:3])}"
                                      f"{' ...' if len(missing) > 3 else ''}) are taken as never seen")
    if obj.layers is None:
        return _track_jointed(take, positions, obj, out)
    if any(j.kind == "revolute" for j in obj.joints):
        raise HandcapError(f"{obj.name}: a puzzle cube's layers and revolute joints in one object are not "
                           f"tracked together; describe them as two objects")
    track = track_cube(positions, obj, window=smoothing_window(take.rate), rate=take.rate)
    warnings = [*take.warnings]
    lost = int(np.isnan(track.translation[:, 0]).sum())
    if lost:
        warnings.append(f"{obj.name}: no pose in {lost} of {take.n_frames} frames (fewer than 3 markers seen)")
    motion, extra = cube_motion(track, obj, take.rate, warnings)
    write_object_motion(motion, out, extra)
    line = (f"{out}: {obj.name} over {take.n_frames} frames, {len(track.moves.split())} moves: "
            f"{track.moves or '(none)'}")
    written = (str(out),)
    if filled is not None:
        complete = np.where(np.isfinite(positions), positions, fitted_markers(track, obj))
        write_markers(MarkerSequence(complete, obj.marker_names, take.rate), filled)
        gaps = int((~np.isfinite(positions).all(axis=2) & np.isfinite(complete).all(axis=2)).sum())
        line += f"\n{filled}: the cube's markers with {gaps} missing samples filled from the track"
        written += (str(filled),)
    return Step((line, quality_line(motion.warnings, "  quality: ")), motion.warnings, written, track)


def _label_cube(path, obj, start, units):
    """The cube's markers labelled in the unlabelled points of ``path`` from the labelled frame of ``start``."""
    if obj.layers is None:
        raise HandcapError(f"{obj.name}: --start labels a 2x2x2 cube's markers; label other objects' markers first")
    points = read_points(path, units=units)
    given = read_markers(start, units=units)
    missing = [n for n in obj.marker_names if n not in given.names]
    if missing:
        raise HandcapError(f"{start} lacks {len(missing)} of the {obj.name} markers ({', '.join(missing[:6])}): "
                           f"it must hold the cube's labelled markers")
    first = given.select(list(obj.marker_names)).positions[:points.n_frames]
    counts = np.isfinite(first).all(axis=2).reshape(len(first), len(obj.parts), -1).sum(axis=2)
    whole = np.flatnonzero((counts >= 2).all(axis=1))
    if not len(whole):
        raise HandcapError(f"{start}: no frame shows 2 labelled markers of every cubie; label one such frame")
    labels = label_cube(points.frames, obj, first[whole[0]], int(whole[0]))
    take = MarkerSequence(labels.positions, obj.marker_names, points.rate)
    return take, labels.positions


def _track_jointed(take, positions, obj, out) -> Step:
    track = track_jointed(positions, obj)
    motion = ObjectMotion(track.rotation, track.translation, take.rate, obj.name, obj.marker_names, obj.markers,
                          {"joint_angles": track.angles}, (*take.warnings, *track.warnings))
    write_object_motion(motion, out, {"joints": np.array(track.joint_names), "fit_rms": track.rms})
    ranges = ", ".join(f"{name} {np.nanmin(a):.0f}..{np.nanmax(a):.0f} deg" if np.isfinite(a).any() else
                       f"{name} never measured" for name, a in zip(track.joint_names, np.rad2deg(track.angles).T))
    line = f"{out}: {obj.name} over {take.n_frames} frames, joints {ranges}"
    return Step((line, quality_line(motion.warnings, "  quality: ")), motion.warnings, (str(out),), track)
