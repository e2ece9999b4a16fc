"""Steps from camera data to clean 3D markers: ``triangulate`` 2D detections and ``clean`` the markers."""

from __future__ import annotations

import time
from dataclasses import replace

import numpy as np

from handcap.core.errors import HandcapError
from handcap.io import check_not_input, marker_suffix, read_markers, write_markers
from handcap.io.camera_formats import read_rig
from handcap.layouts import load_layout, sides_named
from handcap.markerless import repair_handedness
from handcap.markerless.keypoints import is_keypoints
from handcap.multiview import merge_detections, quality_path, read_detections, triangulate_detections, write_quality
from handcap.multiview import clean as cleaning
from handcap.multiview.sync import (MAX_OFFSET_S, NOISE_PX, check_sync, estimate_sync, offsets_from_names,
                                    parse_offsets, shift_detections)
from handcap.quality import plausibility as q
from handcap.steps.step import Step

#: Default inlier threshold for 2D hand keypoints, pixels: a detector's keypoints are typically 2-5 px off on a
#: full-HD image, and a view three times further off is another hand or a wrong keypoint.
KEYPOINT_THRESHOLD_PX = 12.0


def triangulate(detections, cameras, out, *, min_views: int = 3, threshold_px: float | None = None,
                chunk_frames: int | None = None, scheduler=None, workers: int | None = None,
                units: str | None = None, handedness: bool = True, sync=None, sync_reference: str | None = None,
                max_offset_s: float = MAX_OFFSET_S) -> Step:
    """3D markers from the 2D detections of calibrated cameras (see
    :func:`handcap.multiview.triangulate_detections`); per-marker quality beside them (``OUT_STEM.triangulation.npz``).

    Parameters
    ----------
    detections : sequence of str or Path
        2D detections .npz files (merged).
    cameras : str or Path
        The calibrated rig (anipose or caliscope TOML, OpenCV YAML/XML, Qualisys QCA).
    out : str or Path
        Markers to write (.c3d .trc .npz).
    min_views : int
        Inlier views a marker needs.
    threshold_px : float or None
        Reprojection error of an inlier view, pixels (default 5, and :data:`KEYPOINT_THRESHOLD_PX` for hand
        keypoints: detectors place them a few pixels off).
    chunk_frames, scheduler, workers
        Frames per block of work; a Dask scheduler address; local processes (see :mod:`handcap.parallel`).
    units : {'mm', 'cm', 'm'} or None
        Unit of the camera file's translations, overriding what it says.
    handedness : bool
        For 2D hand keypoints (every marker name a keypoint name, see :mod:`handcap.markerless.keypoints`):
        first decide which candidate hand of each camera and frame is which hand by agreement between the
        views (:func:`handcap.markerless.repair_handedness`), as detectors swap left and right.
    sync : None, 'auto', str or dict
        Cameras not triggered together (:mod:`handcap.multiview.sync`): ``'auto'`` finds each camera's offset from
        the detections; ``'CAM=FRAMES, ...'`` or ``{camera: frames}`` gives them (camera c's frame f shows the
        reference's frame f + offset; cameras not named 0). None: the offsets ``detect --sync`` stored in the
        detections files where they hold some; else the cameras are taken as synchronised, and a quick check warns
        when they seem not to be.
    sync_reference : str or None
        The camera whose frames the output counts (default: the detections' first camera).
    max_offset_s : float
        How far ``'auto'`` searches, seconds either way.
    """
    detections = list(detections)
    check_not_input(out, cameras, *detections)
    check_not_input(quality_path(out), cameras, *detections)
    given = None if sync in (None, "auto") else dict(sync) if isinstance(sync, dict) else parse_offsets(sync)
    files = [read_detections(path) for path in detections]
    stored = _stored_clocks(detections) if sync is None else None
    merged = merge_detections(files, same_length=sync is None and stored is None)
    rig = read_rig(cameras, units=units)
    start = time.perf_counter()
    lines, sync_warnings, synced = [], [], None
    keypoints = is_keypoints(merged.marker_names)
    if threshold_px is None:
        threshold_px = KEYPOINT_THRESHOLD_PX if keypoints else 5.0
    if len(merged.camera_names) > 1:
        merged.camera_order(rig)  # every camera in the rig, before the work
        if sync == "auto":
            found = estimate_sync(merged, rig, max_offset_s=max_offset_s, reference=sync_reference,
                                  noise_px=threshold_px / 2 if keypoints else NOISE_PX)
            if np.isfinite(found.offsets).sum() < 2:
                raise HandcapError(f"--sync auto placed no camera beside {found.reference}: "
                                   + "; ".join(found.warnings))
        elif stored is not None:  # detect --sync found or was given them: the corners are at each camera's moments
            found = _stored_sync(merged, rig, stored, sync_reference)
        else:
            offsets = None if given is None else offsets_from_names(merged, given, sync_reference)
            found = check_sync(merged, rig, offsets, reference=sync_reference)
        sync_warnings = list(found.warnings)
        if sync is not None or stored is not None:
            merged, lost = shift_detections(merged, found.offsets, found.drift)
            synced = found
            lines.append(f"{found.summary()}; {lost} of the detections fall outside {found.reference}'s frames or "
                         f"come from a camera with no offset, and are left out")
    if handedness and keypoints:
        repair = repair_handedness(merged, rig)
        merged = repair.detections
        lines.append(repair.summary())
    result = triangulate_detections(merged, rig, min_views=min_views, threshold_px=threshold_px,
                                    chunk_frames=chunk_frames, scheduler=scheduler, workers=workers)
    seconds = time.perf_counter() - start
    markers = result.to_markers()
    pitch_figures, pitch_warnings = q.pitch_check(markers, merged.pitch)
    seen = np.zeros((merged.n_frames, len(merged.marker_names)), dtype=np.int64)
    looks = np.unique(np.stack([merged.frame, merged.marker, merged.camera]), axis=1)  # one per camera
    np.add.at(seen, (looks[0], looks[1]), 1)
    markers = q.attach(markers, [*rig.warnings, *sync_warnings, *q.triangulation_warnings(
        result.error_px, result.views, threshold_px=threshold_px, used=result.used, seen=seen,
        min_views=min_views), *q.marker_warnings(markers), *pitch_warnings])
    write_markers(markers, out)
    quality = write_quality(result, out, sync=synced)
    s = result.counts()
    line = q.summary(f"{out}: {result.summary()}, {s['frames'] * s['markers'] / max(seconds, 1e-9):,.0f} "
                     f"marker-frames/s; per-marker errors and view counts in {quality}",
                     q.marker_figures(markers) | pitch_figures, markers.warnings)
    return Step((*lines, line), markers.warnings, (str(out), str(quality)), result)


def clean(path, out, *, layout: str | None = None, radius: float | None = None, window: int = cleaning.WINDOW,
          z: float = cleaning.Z, floor: float = cleaning.FLOOR, max_linear_frames: int | None = None,
          max_rigid_frames: int = cleaning.MAX_RIGID, max_spline_frames: int | None = None,
          rigid_tolerance: float = cleaning.RIGID_TOLERANCE, units: str | None = None) -> Step:
    """Remove mislabelled points and spikes from 3D markers and fill short gaps (see
    :func:`handcap.multiview.clean.clean_markers`, whose parameters these are; lengths in metres, gaps in frames;
    linear and spline gaps by default 0.02 s and 0.1 s of the take's frames).

    Parameters
    ----------
    path, out : str or Path
        Labeled markers in; cleaned markers out (.c3d .trc .npz).
    layout : str or None
        Marker layout for clustering and the rigid fill (None: those steps are skipped).
    units : {'mm', 'cm', 'm'} or None
        Unit of the input's coordinates, overriding what the file says.
    """
    check_not_input(out, path)
    marker_suffix(out, write=True)  # before the work
    marker_layout = None if layout is None else load_layout(layout)
    markers = read_markers(path, units=units,
                           hand=None if marker_layout is None else [m.name for m in marker_layout.hand_markers])
    sides = sides_named(markers.names)
    if marker_layout is not None and len(sides) == 1 and sides != {marker_layout.side}:
        marker_layout = marker_layout.for_side(sides.pop())  # one hand's take, named so (left:...): its layout
    cleaned, report = cleaning.clean_markers(
        markers, marker_layout, radius=radius, window=window, z=z, floor=floor, max_linear_frames=max_linear_frames,
        max_rigid_frames=max_rigid_frames, max_spline_frames=max_spline_frames, rigid_tolerance=rigid_tolerance)
    hand = None if marker_layout is None else marker_layout.names
    cleaned = q.attach(cleaned, [*markers.warnings, *q.clean_warnings(report, markers.missing),
                                 *q.marker_warnings(cleaned, hand=hand)])
    write_markers(cleaned, out)
    line = q.summary(f"{out}: {report.summary()}", q.marker_figures(cleaned, hand=hand), cleaned.warnings)
    return Step((line,), cleaned.warnings, (str(out),), report)


def _stored_clocks(paths) -> tuple[dict, str] | None:
    """The offsets ``detect --sync`` stored in detections files: ({camera: (offset, drift)} in frames, their
    reference camera), or None where no file holds them. Files whose offsets count from different cameras cannot
    be joined: refused."""
    clocks, references = {}, set()
    for path in paths:
        try:
            with np.load(path, allow_pickle=False) as data:
                if "sync_offsets" not in data.files:
                    continue
                names = [str(n) for n in np.asarray(data["sync_cameras"]).reshape(-1)]
                offsets, drift = (np.asarray(data[k], dtype=np.float64).reshape(-1)
                                  for k in ("sync_offsets", "sync_drift"))
                references.add(str(data["sync_reference"]))
        except (OSError, ValueError, TypeError, KeyError) as err:
            raise HandcapError(f"{path}: its stored camera offsets cannot be read ({err})") from None
        if not len(names) == len(offsets) == len(drift):
            raise HandcapError(f"{path}: {len(names)} cameras but {len(offsets)} stored offsets and {len(drift)} "
                               f"drifts")
        clocks.update({n: (float(o), float(d)) for n, o, d in zip(names, offsets, drift)})
    if len(references) > 1:
        raise HandcapError(f"the detections files carry camera offsets that count from different cameras "
                           f"({', '.join(sorted(references))}); give the offsets with --sync, or find them again with "
                           f"--sync auto")
    return (clocks, references.pop()) if clocks else None


def _stored_sync(merged, rig, stored: tuple, reference: str | None):
    """A :class:`~handcap.multiview.sync.Sync` of the stored offsets, counted from ``reference`` (default: the
    stored reference); cameras they lack get none, and their detections are left out."""
    clocks, reference = stored[0], reference or stored[1]
    names = list(merged.camera_names)
    if reference not in names:
        raise HandcapError(f"the reference camera {reference!r} of the offsets stored with the detections is not in "
                           f"them ({', '.join(names)}); give the offsets with --sync, or find them with --sync auto")
    offsets, drift = (np.array([clocks.get(n, (np.nan, 0.0))[k] for n in names]) for k in (0, 1))
    ref = names.index(reference)
    if not np.isfinite(offsets[ref]):
        raise HandcapError(f"the offsets stored with the detections do not place {reference}; give another reference "
                           f"with --sync auto --sync-reference")
    found = check_sync(merged, rig, np.nan_to_num(offsets - offsets[ref]), reference=reference)
    lacking = [n for n, o in zip(names, offsets) if not np.isfinite(o)]
    warnings = [f"no stored offset for camera {', '.join(lacking)}: its detections are left out"] if lacking else []
    return replace(found, offsets=offsets - offsets[ref], drift=drift - drift[ref],
                   warnings=(*found.warnings, *warnings), notes=("offsets as detect --sync stored them",))
