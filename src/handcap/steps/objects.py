"""Step ``track_object``: the 6-DoF motion of a rigid object from its markers."""

from __future__ import annotations

from handcap.core.markers import expand_names
from handcap.io import check_not_input, load_npz, read_markers, write_object_motion
from handcap.objects import track_rigid
from handcap.quality import plausibility as q
from handcap.steps.step import Step, quality_line


def track_object(path, out, *, markers, canonical=None, name: str = "object", threshold: float = 0.005,
                 units: str | None = None) -> Step:
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
    """
    check_not_input(out, path, canonical)
    take = read_markers(path, units=units)
    names = expand_names(take, markers)
    known = None if canonical is None else load_npz(canonical, ("canonical",), "object file")["canonical"]
    track = track_rigid(take, names, known, name=name, threshold=threshold)
    motion = q.attach(track.motion, [*take.warnings, *q.object_warnings(track, threshold=threshold)])
    write_object_motion(motion, out)
    return Step((f"{out}: {track.summary()}", quality_line(motion.warnings, "  quality: ")), motion.warnings,
                (str(out),), track)
