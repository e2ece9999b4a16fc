"""A whole camera rig from synchronised board recordings: relative poses chained over a spanning tree of
the cameras, then bundle adjustment; see :mod:`handcap.multiview.calibration`."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from handcap.core.cameras import Camera, CameraRig
from handcap.core.errors import HandcapError
from handcap.core.rotations import axis_angle_from_matrix
from handcap.core.transforms import invert_homogeneous, robust_mean_pose
from handcap.multiview.boards import Board, BoardDetections
from handcap.multiview.bundle import BundleAdjustment, bundle_adjust, view_rms
from handcap.multiview.intrinsics import Intrinsics, board_poses, calibrate_intrinsics

ORIGINS = ("board", "camera")
# A board pose from solvePnP that reprojects worse than this is not trusted
# to start the bundle adjustment from (the view still enters it).
_PNP_START_RMS_PX = 5.0


@dataclass(frozen=True, eq=False)
class RigCalibration:
    """A calibrated rig and the numbers that say how good it is.

    Attributes
    ----------
    rig : CameraRig
        The cameras in the world frame chosen by ``origin`` (module docstring).
    board2world : ndarray of shape (T, 4, 4)
        Board pose at each frame, metres; NaN where no camera saw it.
    errors : ndarray of shape (C, T, N)
        Final reprojection error of every corner used, pixels; NaN elsewhere.
    rms : ndarray of shape (C,)
        Final reprojection RMS per camera, pixels.
    start_rms : ndarray of shape (C,)
        Reprojection RMS per camera before the bundle adjustment, pixels.
    intrinsic_rms : ndarray of shape (C,)
        RMS of each camera's own intrinsic calibration (NaN for given cameras).
    views : ndarray of int, shape (C,)
        Frames in which each camera saw the board and the view was used.
    shared_views : ndarray of int, shape (C, C)
        Frames in which both cameras of a pair saw the board.
    tree : tuple of (int, int)
        The (parent, child) camera pairs whose relative poses placed the cameras.
    origin : str
        The world frame, in words.
    frames : ndarray of int, shape (T,)
        The frame numbers (of the first camera's source).
    converged : bool
        Whether the bundle adjustment converged within :data:`MAX_EVALUATIONS` evaluations per pass.
    """

    rig: CameraRig
    board2world: np.ndarray
    errors: np.ndarray
    rms: np.ndarray
    start_rms: np.ndarray
    intrinsic_rms: np.ndarray
    views: np.ndarray
    shared_views: np.ndarray
    tree: tuple[tuple[int, int], ...]
    origin: str
    frames: np.ndarray
    converged: bool = True

    @property
    def names(self) -> tuple[str, ...]:
        """Camera names (C,), in the rig's order."""
        return self.rig.names

    def summary(self) -> str:
        """A few lines for a person: per camera views, focal length, intrinsic and rig RMS."""
        names = self.names
        width = max(6, *(len(n) for n in names))
        lines = [f"{len(names)} cameras, board seen at {int(np.isfinite(self.board2world[:, 0, 0]).sum())} of "
                 f"{len(self.frames)} instants; world: {self.origin}",
                 f"{'camera':<{width}}  views  f (px)   intrinsic RMS  start RMS  rig RMS (px)  placed from"]
        parent = {child: p for p, child in self.tree}
        for c, camera in enumerate(self.rig):
            placed = "origin" if c not in parent else f"{names[parent[c]]} ({self.shared_views[parent[c], c]} shared)"
            intrinsic = "given" if np.isnan(self.intrinsic_rms[c]) else f"{self.intrinsic_rms[c]:.3f}"
            lines.append(f"{names[c]:<{width}}  {self.views[c]:5d}  {camera.matrix[0, 0]:7.1f}  {intrinsic:>13}  "
                         f"{self.start_rms[c]:9.3f}  {self.rms[c]:12.3f}  {placed}")
        return "\n".join(lines)

    def __repr__(self) -> str:
        return f"RigCalibration({', '.join(f'{n}: {r:.2f} px' for n, r in zip(self.names, self.rms))})"


def _camera_names(detections, names) -> list[str]:
    if names is not None:
        names = [str(n) for n in names]
        if len(names) != len(detections):
            raise HandcapError(f"{len(names)} camera names for {len(detections)} cameras; give one name per camera")
        return names
    stems = [Path(d.source).stem or f"cam_{i}" for i, d in enumerate(detections)]
    return stems if len(set(stems)) == len(stems) else [f"cam_{i}" for i in range(len(detections))]


def _spanning_tree(shared: np.ndarray, root: int = 0) -> tuple[list[tuple[int, int]], list[int]]:
    """Maximum spanning tree (Prim) over cameras weighted by shared views; returns edges and unreached cameras."""
    c_count = len(shared)
    placed = {root}
    edges = []
    while True:
        best = (0, None, None)
        for p in placed:
            for c in range(c_count):
                if c not in placed and shared[p, c] > best[0]:
                    best = (shared[p, c], p, c)
        if best[1] is None:
            break
        edges.append((best[1], best[2]))
        placed.add(best[2])
    return edges, [c for c in range(c_count) if c not in placed]


#: Most evaluations of each pass of the bundle adjustment. A rig of synchronised cameras converges in a few dozen;
#: frames of different moments (cameras not triggered together) make it crawl for hours without a bound, and the
#: cameras' reprojection RMS then tells what went wrong.
MAX_EVALUATIONS = 300


def calibrate_rig(detections: Sequence[BoardDetections], *, names: Sequence[str] | None = None,
                  cameras: Sequence[Camera] | CameraRig | None = None, refine_intrinsics: bool | None = None,
                  fix_k3: bool = False, origin: str = "board", origin_frame: int | None = None,
                  loss: str = "soft_l1", f_scale: float = 1.0) -> RigCalibration:
    """Calibrate a rig of cameras that filmed the same board at the same instants.

    Parameters
    ----------
    detections : sequence of BoardDetections
        One per camera (C >= 2), from synchronised recordings: frame ``t`` of
        every camera shows the same instant, so all have the same frames.
    names : sequence of str, optional
        Camera names (default: the sources' file names, or ``cam_0``, ...).
    cameras : sequence of Camera or CameraRig, optional
        Known intrinsics (matrix, distortions), one camera per detections; by
        default each camera is calibrated from its own views first
        (:func:`calibrate_intrinsics`). Their extrinsics are not used.
    refine_intrinsics : bool, optional
        Refine every camera's intrinsics in the bundle adjustment too. By
        default they are refined when calibrated here (a board filmed for the
        rig seldom fills the image as an intrinsic calibration should; every
        camera seeing the same board poses pins them far better) and kept
        when ``cameras`` gives them.
    fix_k3 : bool
        Keep k3 = 0 in the intrinsic calibrations (and fixed in the adjustment).
    origin : {"board", "camera"}
        The world frame (module docstring).
    origin_frame : int, optional
        With ``origin="board"``: the frame number (as in ``detections[0].frames``)
        whose board pose is the world; default the first frame in which the
        first camera sees the board.
    loss, f_scale
        Robust loss and its scale in pixels, see :func:`bundle_adjust`.

    Returns
    -------
    RigCalibration

    Raises
    ------
    HandcapError
        Fewer than two cameras; different boards or frame counts (the cameras
        are named with their counts); a camera that never sees the board (named
        with its source); cameras that share no board view with the first one,
        directly or through others (all named); a checkerboard whose
        orientation is ambiguous; a bad option.
    """
    detections = list(detections)
    if len(detections) < 2:
        raise HandcapError(f"a rig needs at least two cameras, got {len(detections)}")
    for d in detections:
        if not isinstance(d, BoardDetections):
            raise HandcapError(f"calibrate_rig needs BoardDetections per camera, got {type(d).__name__}")
    if origin not in ORIGINS:
        raise HandcapError(f"origin must be one of {', '.join(ORIGINS)}, got {origin!r}")
    names = _camera_names(detections, names)
    if len(set(names)) != len(names):
        raise HandcapError(f"camera names must be unique, got {', '.join(names)}")
    board = detections[0].board
    for name, d in zip(names, detections):
        if d.board != board:
            raise HandcapError(f"camera {name} ({d.source}) looked for {d.board.spec}, the first camera for "
                               f"{board.spec}; all cameras must look for the same board")
    if board.kind == "checkerboard" and (board.columns + board.rows) % 2 == 0:
        raise HandcapError(f"a {board.columns}x{board.rows} checkerboard looks the same turned half round, so "
                           f"cameras could number its corners differently; use a board with an odd and an even "
                           f"number of inner corners (e.g. 9x6) or a charuco board")
    counts = [d.n_frames for d in detections]
    if len(set(counts)) > 1 or any(not np.array_equal(d.frames, detections[0].frames) for d in detections):
        listing = ", ".join(f"{n} ({d.source}) {c}" for n, d, c in zip(names, detections, counts))
        raise HandcapError(f"cameras have different frame counts: {listing}; synchronised recordings need the "
                           f"same frames from every camera")
    never = [f"{n} ({d.source})" for n, d in zip(names, detections) if not d.found.any()]
    if never:
        raise HandcapError(f"the board {board.spec} is never seen by camera {', '.join(never)}; check the board "
                           f"spec and that the camera films it")
    if refine_intrinsics is None:
        refine_intrinsics = cameras is None
    if cameras is not None:
        cameras = list(cameras)
        if len(cameras) != len(detections):
            raise HandcapError(f"{len(cameras)} cameras given for {len(detections)} recordings; give one per camera")
    c_count, t_count = len(detections), counts[0]

    # 1. intrinsics of each camera and the views they keep
    used = np.zeros((c_count, t_count), dtype=bool)
    intrinsic_rms = np.full(c_count, np.nan)
    start = []
    for c, (name, d) in enumerate(zip(names, detections)):
        if cameras is None:
            intrinsics = calibrate_intrinsics(d, name=name, fix_k3=fix_k3)
            intrinsic_rms[c] = intrinsics.rms
            used[c] = d.found
            used[c, intrinsics.rejected] = False
            camera = intrinsics.camera
        else:
            given = cameras[c]
            if not isinstance(given, Camera):
                raise HandcapError(f"cameras must be Camera objects, got {type(given).__name__}")
            if tuple(given.size) != tuple(d.size):
                raise HandcapError(f"camera {name}: given intrinsics are for {given.size[0]}x{given.size[1]} px "
                                   f"but {d.source} is {d.size[0]}x{d.size[1]}")
            camera = given
            used[c] = d.found
        start.append(Camera(name, camera.size, camera.matrix, camera.distortions))

    # 2. board pose in every used view
    board2camera = np.full((c_count, t_count, 4, 4), np.nan)
    pnp_rms = np.full((c_count, t_count), np.nan)
    for c, d in enumerate(detections):
        board2camera[c], pnp_rms[c] = board_poses(d, start[c], views=np.flatnonzero(used[c]))
    used &= np.isfinite(pnp_rms)
    good = used & (pnp_rms < _PNP_START_RMS_PX)
    lost = [f"{names[c]} ({detections[c].source})" for c in range(c_count) if not used[c].any()]
    if lost:
        raise HandcapError(f"no usable board view in camera {', '.join(lost)}")

    # 3. relative poses of camera pairs and a spanning tree from the first camera
    shared = (good[:, None, :] & good[None, :, :]).sum(axis=2)
    np.fill_diagonal(shared, 0)
    edges, unreached = _spanning_tree(shared)
    if unreached:
        connected = [names[c] for c in range(c_count) if c not in unreached]
        which = ", ".join(names[c] for c in unreached)
        raise HandcapError(f"{'camera ' + which + ' shares' if len(unreached) == 1 else 'cameras ' + which + ' share'}"
                           f" no board view with {', '.join(connected)} (directly or through other cameras), so "
                           f"{'it' if len(unreached) == 1 else 'they'} cannot be placed; film the board where the "
                           f"cameras overlap")
    world2camera = np.full((c_count, 4, 4), np.nan)
    world2camera[0] = np.eye(4)  # start in the first camera's frame
    for parent, child in edges:
        both = np.flatnonzero(good[parent] & good[child])
        child2parent = board2camera[parent, both] @ invert_homogeneous(board2camera[child, both])
        world2camera[child] = invert_homogeneous(robust_mean_pose(child2parent)) @ world2camera[parent]

    # 4. board pose at each instant from the camera that sees most corners
    seen = np.isfinite(np.stack([d.pixels[..., 0] for d in detections])).sum(axis=2) * good
    board2ref = np.full((t_count, 4, 4), np.nan)
    for t in np.flatnonzero(seen.max(axis=0) > 0):
        c = int(np.argmax(seen[:, t]))
        board2ref[t] = invert_homogeneous(world2camera[c]) @ board2camera[c, t]

    pixels = np.stack([d.pixels for d in detections])
    pixels = np.where(used[..., None, None], pixels, np.nan)
    rig = CameraRig([Camera(s.name, s.size, s.matrix, s.distortions, axis_angle_from_matrix(w[:3, :3]), w[:3, 3])
                     for s, w in zip(start, world2camera)])
    start_errors = _reprojection_errors(pixels, board, rig, board2ref)

    # 5. bundle adjustment of everything
    adjusted = bundle_adjust(pixels, board, rig, board2ref, refine_intrinsics=refine_intrinsics,
                             fix_k3=fix_k3, loss=loss, f_scale=f_scale, max_nfev=MAX_EVALUATIONS)

    # 6. the world frame
    if origin == "camera":
        description = f"camera {names[0]} (x right, y down, z along its optical axis)"
        ref2world = np.eye(4)
    else:
        posed = np.isfinite(adjusted.board2world[:, 0, 0])
        frames = detections[0].frames
        if origin_frame is None:
            candidates = np.flatnonzero(used[0] & posed)
            position = int(candidates[0]) if len(candidates) else int(np.flatnonzero(posed)[0])
        else:
            matches = np.flatnonzero(frames == origin_frame) if isinstance(origin_frame, (int, np.integer)) \
                and not isinstance(origin_frame, bool) else []
            if len(matches) == 0 or not posed[matches[0]]:
                seen = frames[posed]
                raise HandcapError(f"origin_frame {origin_frame!r} is not a frame in which a camera sees the board; "
                                   f"those are {_ranges(seen)}")
            position = int(matches[0])
        # x along the board, z out of its printed face: the board frame turned half round about x.
        flip = np.diag([1.0, -1.0, -1.0, 1.0])
        ref2world = flip @ invert_homogeneous(adjusted.board2world[position])
        description = f"the board at frame {int(frames[position])} (x along the board, z out of its printed face)"
    world2ref = invert_homogeneous(ref2world)
    final = CameraRig([Camera(c.name, c.size, c.matrix, c.distortions,
                              axis_angle_from_matrix((c.world2camera @ world2ref)[:3, :3]),
                              (c.world2camera @ world2ref)[:3, 3]) for c in adjusted.rig])
    board2world = ref2world @ adjusted.board2world
    views = np.isfinite(adjusted.errors).any(axis=2).sum(axis=1)
    return RigCalibration(final, board2world, adjusted.errors, adjusted.rms, view_rms(start_errors), intrinsic_rms,
                          views, shared, tuple(edges), description, detections[0].frames.copy(),
                          bool(adjusted.success))


def _ranges(frames) -> str:
    """'0-12, 15, 20-31' for sorted frame numbers."""
    frames = [int(f) for f in frames]
    parts, begin = [], None
    for i, f in enumerate(frames):
        begin = f if begin is None else begin
        if i + 1 == len(frames) or frames[i + 1] != f + 1:
            parts.append(str(f) if begin == f else f"{begin}-{f}")
            begin = None
    return ", ".join(parts) if parts else "none"


def _reprojection_errors(pixels: np.ndarray, board: Board, rig: CameraRig, board2world: np.ndarray) -> np.ndarray:
    """Pixel distance (C, T, N) between detected corners and the board projected through the rig."""
    points = np.einsum("tij,nj->tni", board2world[:, :3, :3], board.object_points) + board2world[:, None, :3, 3]
    projected, _ = rig.project(points)
    return np.linalg.norm(projected - pixels, axis=-1)


__all__ = ["BundleAdjustment", "Intrinsics", "RigCalibration", "board_poses", "bundle_adjust",
           "calibrate_intrinsics", "calibrate_rig"]
