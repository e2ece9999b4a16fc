"""Steps of camera calibration from a checkerboard or ChArUco board: ``intrinsics`` and ``rig``."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from handcap.core.cameras import CameraRig, check_rig_suffix
from handcap.core.errors import HandcapError
from handcap.io import check_output
from handcap.io.camera_formats import read_rig
from handcap.multiview.board_guess import board_hint
from handcap.multiview.boards import detect_in_files, parse_board
from handcap.multiview.board_sync import board_offsets, shift_boards
from handcap.multiview.calibration import calibrate_intrinsics, calibrate_rig
from handcap.multiview.rig import MAX_EVALUATIONS
from handcap.multiview.sync import Sync, parse_offsets
from handcap.quality import plausibility as q
from handcap.steps.step import Step, quality_line


def _camera_file_out(out, inputs) -> None:
    """Check a camera file's name before the slow work: .toml, in a folder that can be written, not an input."""
    check_rig_suffix(out)
    check_output(out, *inputs)


def _check_seen(detections, recordings) -> None:
    """One line naming the cameras that never see the board, with what the first of them shows instead
    (:func:`handcap.multiview.board_guess.board_hint`: the spec that finds the board there, if one near it does)."""
    never = [(d, path) for d, path in zip(detections, recordings) if not d.found.any()]
    if never:
        (first, path), board = never[0], never[0][0].board
        cameras = ", ".join(f"{d.source} ({d.n_frames} frames)" for d, _ in never)
        raise HandcapError(f"the board {board.spec} is never seen in {cameras}; in {Path(first.source).name}, "
                           f"{board_hint(path, board)}")


def intrinsics(inputs, out, *, board: str, name: str | None = None, every: int = 1, fix_k3: bool = False,
               keep_outliers: bool = False) -> Step:
    """One camera's matrix and distortion from images or a video of a board (see
    :func:`handcap.multiview.calibration.calibrate_intrinsics`), written as an anipose-style TOML at the origin.

    Parameters
    ----------
    inputs : sequence of str or Path
        Image files, a folder of images, or one video.
    out : str or Path
        Camera file (.toml).
    board : str
        ``checkerboard:COLSxROWS:SQUARE_M`` or ``charuco:...`` (see :func:`handcap.multiview.boards.parse_board`).
    name : str or None
        Camera name (default: the file or folder name).
    every : int
        Video: use every N-th frame.
    fix_k3, keep_outliers : bool
        Keep k3 = 0; keep every view.
    """
    inputs = list(inputs)
    parsed = parse_board(board)
    _camera_file_out(out, inputs)
    detections = detect_in_files(inputs, parsed, every=every)
    _check_seen([detections], [inputs])
    result = calibrate_intrinsics(detections, name=name, fix_k3=fix_k3, reject_outliers=not keep_outliers)
    rig = q.attach(CameraRig([result.camera]), q.camera_warnings(result.rms, names=[result.camera.name]))
    rig.save(out)  # the warnings go to the file's [metadata]
    rejected = ", ".join(detections.labels[t] for t in result.rejected)
    lines = (f"{out}: {result.summary()}",
             f"reprojection RMS {result.rms:.3f} px over {len(result.views)} views (board seen in "
             f"{int(detections.found.sum())} of {detections.n_frames} frames), worst view "
             f"{result.labels[int(result.view_rms.argmax())]} {result.view_rms.max():.3f} px"
             + (f"; rejected as outliers: {rejected}" if len(result.rejected) else ""),
             quality_line(rig.warnings))
    return Step(lines, rig.warnings, (str(out),), result)


def rig(recordings, out, *, board: str, names=None, every: int = 1, intrinsics=None,
        refine_intrinsics: bool | None = None, fix_k3: bool = False, origin: str = "board",
        origin_frame: int | None = None, loss: str = "soft_l1", f_scale: float = 1.0, sync=None,
        max_offset: int | None = None) -> Step:
    """Every camera of a rig from synchronised recordings of a board, by bundle adjustment (see
    :func:`handcap.multiview.calibration.calibrate_rig`), written as an anipose-style TOML.

    Parameters
    ----------
    recordings : sequence of str or Path
        One video or image folder per camera, all of the same frames.
    out : str or Path
        Rig file (.toml).
    board : str
        The board (see :func:`handcap.multiview.boards.parse_board`).
    names : sequence of str or None
        Camera names in the order of the recordings (default: their file names).
    every : int
        Videos: use every N-th frame.
    intrinsics : str, Path or None
        A camera file with one camera per recording, in the same order: known intrinsics.
    refine_intrinsics : bool or None
        Refine the intrinsics in the bundle adjustment (default: yes, unless ``intrinsics``).
    fix_k3 : bool
    origin : {'board', 'camera'}
        World frame: the board at ``origin_frame`` or the first camera.
    origin_frame : int or None
    loss : str
        Robust loss (one of :data:`handcap.multiview.calibration.LOSSES`).
    f_scale : float
        Pixel error where the robust loss starts to discount.
    sync : None, 'auto', str or sequence of str
        Cameras not triggered together (:mod:`handcap.multiview.board_sync`): ``'auto'`` finds each camera's
        offset from the board's motion; ``'CAM=FRAMES'`` items give them (camera c's frame f shows the first
        camera's frame f + offset). The recordings may then differ in length.
    max_offset : int or None
        How far ``'auto'`` searches, frames either way (default: half the shortest recording).
    """
    recordings = list(recordings)
    parsed = parse_board(board)
    if names is not None and len(names) != len(recordings):
        raise HandcapError(f"{len(names)} camera names for {len(recordings)} cameras; give one name per camera")
    _camera_file_out(out, recordings + ([intrinsics] if intrinsics else []))
    cameras = None if intrinsics is None else read_rig(intrinsics, positions=False)  # extrinsics unused
    detections = [detect_in_files(path, parsed, every=every) for path in recordings]
    _check_seen(detections, recordings)
    lines, sync_warnings = [], []
    if sync is not None:
        found = _synchronise(detections, names, cameras, sync, max_offset, fix_k3)
        detections = shift_boards(detections, found.offsets)
        lines.append(found.summary())
        sync_warnings = list(found.warnings)
    result = calibrate_rig(detections, names=names, cameras=cameras, refine_intrinsics=refine_intrinsics,
                           fix_k3=fix_k3, origin=origin, origin_frame=origin_frame, loss=loss, f_scale=f_scale)
    checks = q.camera_warnings(result.rms, names=result.names)
    if not result.converged:
        checks.append(f"the bundle adjustment stopped after {MAX_EVALUATIONS} evaluations before it converged; the "
                      f"rig may be less exact than it could be")
    if checks and sync is None:
        checks.append("cameras started one by one pair frames of different moments of a moving board: "
                      "calibrate rig --sync auto finds each camera's offset")
    calibrated = q.attach(result.rig, [*sync_warnings, *checks])
    calibrated.save(out)  # the warnings go to the file's [metadata]
    warnings = calibrated.warnings
    lines = (*lines, result.summary(), f"{out}: {len(result.rig)} cameras; "
             + (f"{len(warnings)} warning(s), see below" if warnings else "no warnings"))
    return Step(lines, warnings, (str(out),), result)


def _synchronise(detections, names, cameras, sync, max_offset, fix_k3):
    """The cameras' offsets: found from the board's motion, or given by name (see :func:`rig`)."""
    names = list(names) if names is not None else [Path(d.source).stem for d in detections]
    if sync != "auto":
        given = parse_offsets(sync)
        unknown = sorted(set(given) - set(names))
        if unknown:
            raise HandcapError(f"an offset for camera {unknown[0]!r}, which the rig lacks (it has {', '.join(names)})")
        offsets = np.array([given.get(n, 0.0) for n in names])
        return Sync(tuple(names), offsets - offsets[0], names[0], np.nan, np.nan, 0, ())
    if cameras is None:
        cameras = [calibrate_intrinsics(d, name=n, fix_k3=fix_k3).camera for d, n in zip(detections, names)]
    if max_offset is None:
        max_offset = max(1, min(d.n_frames for d in detections) // 2)
    return board_offsets(detections, list(cameras), max_offset=max_offset, names=names)
