"""Which camera sees which marker: image bounds, facing, and occlusion by ray casting.

A marker is seen by a camera when it projects inside the image, lies in front
of the camera, faces it (printed patch corners only: within
``max_view_angle`` of the surface normal) and nothing lies on the straight
line between the camera centre and the marker: no triangle of the hand (its
own skin included) or of the object. The ray test is exact (Moller-Trumbore,
in camera coordinates); the triangles tried for each marker are found in the
image first: those facing the camera whose bounding box holds its projection.
Frames are tested together (arrays over frames, markers and triangles), one
camera at a time.
"""

from __future__ import annotations

import numpy as np

from handcap.core.geometry import segments_cross_triangles


#: Marker-triangle pairs compared at once in the image (memory bound of the candidate search).
PAIRS_AT_ONCE = 2_000_000
#: Widening of the triangles' boxes in the image (share of the largest normalised coordinate) before their
#: single-precision test: many times its rounding (6e-8), so no triangle a point lies in is left out.
BOX_SLACK = 1e-5


class _Surface:
    """The occluding triangles of T frames, shared by every camera: vertices (T, V, 3), the corners of each
    face as three index columns (F,) and the face normals as three component arrays (T, F) with their offsets
    ``n . a`` (T, F), metres."""

    def __init__(self, vertices, faces):
        self.vertices = np.asarray(vertices, dtype=np.float64)
        self.faces = np.asarray(faces).reshape(-1, 3)
        self.corner = tuple(np.ascontiguousarray(self.faces[:, k]) for k in range(3))
        # Components as separate (T, F) arrays: NumPy is slow on products over axes of length 3.
        axes = [np.ascontiguousarray(self.vertices[..., d]) for d in range(3)]
        a, b, c = ([np.take(x, i, axis=1) for x in axes] for i in self.corner)
        u, v = [q - p for p, q in zip(a, b)], [q - p for p, q in zip(a, c)]
        self.normal = (u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2], u[0] * v[1] - u[1] * v[0])
        self.offset = self.normal[0] * a[0] + self.normal[1] * a[1] + self.normal[2] * a[2]


def occluded(camera, points, vertices, faces, *, end_gap: float = 1e-4) -> np.ndarray:
    """Whether the line from the camera to each point crosses the occluding surface.

    Parameters
    ----------
    camera : Camera
    points : ndarray (M, 3)
        Metres, in front of the camera and outside the surface.
    vertices : ndarray (V, 3)
    faces : ndarray (F, 3)
        Closed, outward-facing surfaces (hand and objects), metres.
    end_gap : float
        The last stretch of each line (metres) is not tested, so a marker is
        not hidden by the skin it sits on.

    Returns
    -------
    hidden : ndarray (M,) bool

    Notes
    -----
    A line from the camera to a point outside a closed surface that passes
    through it enters through a triangle facing the camera, so only those
    (about half) are tested, and only those whose bounding box in the image
    holds the point's projection (a point can only be behind a triangle it
    projects into).
    """
    points = np.asarray(points, dtype=np.float64).reshape(1, -1, 3)
    return _hidden(_Surface(np.asarray(vertices)[None], faces), camera, points, end_gap)[0]


def _boxes(surface: _Surface, camera, cam: np.ndarray) -> tuple:
    """The image boxes (T, F) of the triangles facing ``camera`` (normalised coordinates, single precision,
    widened by ``BOX_SLACK``), empty (low +inf, high -inf) for the others."""
    depth = cam[..., 2]
    ahead = depth > 1e-6
    i, j, k = surface.corner
    # In front of the camera, and facing it: the normal points against the line of sight (n . (a - centre) < 0).
    n, (x, y, z) = surface.normal, camera.center
    facing = ahead[:, i] & ahead[:, j] & ahead[:, k] & (surface.offset < n[0] * x + n[1] * y + n[2] * z)
    # Normalised image coordinates in single precision, and the boxes from them, widened by far more than its
    # rounding (rounding keeps the order, so a box's corners are its true corners rounded): the box test only
    # picks the triangles the exact test (double precision) tries, and half the bytes make it faster.
    inverse = 1.0 / np.where(ahead, depth, 1.0)
    # Widened by 1e-5 of the largest coordinate of a vertex in front (at least that of any facing triangle's).
    coords = [(cam[..., axis] * inverse).astype(np.float32) for axis in (0, 1)]
    largest = np.maximum(*(np.abs(np.where(ahead, c, np.float32(0.0))).max(axis=1) for c in coords))
    widen = (BOX_SLACK * (1.0 + largest[:, None])).astype(np.float32)
    # The triangles not facing get empty boxes: +inf added to their low ends and taken from their high ends.
    shut = np.where(facing, np.float32(0.0), np.float32(np.inf))
    out = []
    for c in coords:
        # np.take keeps the (T, F) arrays C-ordered (c[:, i] would not), as the pair test wants them.
        corners = np.take(c, i, axis=1), np.take(c, j, axis=1), np.take(c, k, axis=1)
        low = np.minimum(np.minimum(corners[0], corners[1]), corners[2])
        high = np.maximum(np.maximum(corners[0], corners[1]), corners[2])
        low -= widen
        low += shut
        high += widen
        high -= shut
        out += [low, high]
    return tuple(out)


def _hidden(surface: _Surface, camera, points: np.ndarray, end_gap: float = 1e-4) -> np.ndarray:
    """Whether each point (T, M, 3) of each frame is hidden from ``camera`` by its frame's surface (T, M);
    NaN points are not tested (not hidden)."""
    n_frames, n_points = points.shape[:2]
    hidden = np.zeros((n_frames, n_points), bool)
    tested = np.isfinite(points).all(axis=-1)
    n_faces = len(surface.faces)
    if not tested.any() or n_faces == 0:
        return hidden
    rot, trans = camera.rotation_matrix, camera.translation
    cam = surface.vertices @ rot.T + trans  # (T, V, 3) camera coordinates
    x_low, x_high, y_low, y_high = _boxes(surface, camera, cam)
    pt_cam = np.where(tested[..., None], points, 0.0) @ rot.T + trans
    with np.errstate(divide="ignore", invalid="ignore"):
        pt_x = np.where(tested, pt_cam[..., 0] / pt_cam[..., 2], np.nan).astype(np.float32)
        pt_y = np.where(tested, pt_cam[..., 1] / pt_cam[..., 2], np.nan).astype(np.float32)
    frames, which, cand = [], [], []
    step = max(1, PAIRS_AT_ONCE // (n_points * n_faces))
    for start in range(0, n_frames, step):
        s = slice(start, start + step)
        # A point can only be behind a triangle it projects into: inside its bounding box in the image. Across
        # first (every pair), then up and down (the few pairs left).
        x = pt_x[s, :, None]
        flat = np.flatnonzero((x >= x_low[s, None, :]) & (x <= x_high[s, None, :]))
        t, rest = np.divmod(flat, n_points * n_faces)
        m, f = np.divmod(rest, n_faces)
        t += start
        y = pt_y[t, m]
        inside = (y >= y_low[t, f]) & (y <= y_high[t, f])
        frames.append(t[inside])
        which.append(m[inside])
        cand.append(f[inside])
    frames, which, cand = np.concatenate(frames), np.concatenate(which), np.concatenate(cand)
    if len(which) == 0:
        return hidden
    seg = pt_cam[frames, which]
    ends = seg * (1.0 - end_gap / np.linalg.norm(seg, axis=1, keepdims=True))
    hit = segments_cross_triangles(np.zeros_like(ends), ends, cam[frames[:, None], surface.faces[cand]])
    hidden[frames[hit], which[hit]] = True
    return hidden


def take_visibility(points, rig, vertices, faces, *, normals=None, max_view_angle: float | None = None,
                    end_gap: float = 1e-4) -> np.ndarray:
    """Visibility of markers in every camera of a rig over T frames, tested together.

    Parameters
    ----------
    points : ndarray (T, M, 3)
        Marker centres in metres (NaN rows are never visible).
    rig : CameraRig
    vertices : ndarray (T, V, 3)
        Each frame's closed occluding surfaces (hand and objects), metres.
    faces : ndarray (F, 3)
        The surfaces' triangles (vertex indices, the same in every frame).
    normals : ndarray (T, M, 3), optional
        Outward surface normals at the markers.
    max_view_angle : float, optional
        Radians; markers seen more obliquely than this are not detected
        (needs ``normals``).
    end_gap : float
        The last stretch of each line of sight (metres) is not tested, so a
        marker is not hidden by the skin it sits on.

    Returns
    -------
    visible : ndarray (T, C, M) bool

    Notes
    -----
    Memory grows with T x F and T x M x F / ``PAIRS_AT_ONCE``: give a long
    take in chunks of frames (``handcap.synth.scene`` gives 64).
    """
    points = np.asarray(points, dtype=np.float64)
    valid = ~np.isnan(points).any(axis=-1)
    out = np.zeros((points.shape[0], len(rig), points.shape[1]), bool)
    surface = _Surface(vertices, faces)
    safe = np.where(valid[..., None], points, 0.0)
    for c, camera in enumerate(rig):
        pixels, depth = camera.project(safe)
        ok = valid & (depth > 0) & camera.in_image(pixels)
        if normals is not None and max_view_angle is not None:
            to_camera = camera.center - points
            to_camera /= np.linalg.norm(to_camera, axis=-1, keepdims=True)
            ok &= np.einsum("tmi,tmi->tm", normals, to_camera) > np.cos(max_view_angle)
        ok &= ~_hidden(surface, camera, np.where(ok[..., None], points, np.nan), end_gap)
        out[:, c] = ok
    return out


def camera_visibility(points, rig, vertices, faces, *, normals=None,
                      max_view_angle: float | None = None) -> np.ndarray:
    """Visibility of markers in every camera of a rig for one frame.

    Parameters
    ----------
    points : ndarray (M, 3)
        Marker centres in metres (NaN rows are never visible).
    rig : CameraRig
    vertices, faces : ndarrays (V, 3), (F, 3)
        Closed occluding surfaces (hand and objects) in metres.
    normals : ndarray (M, 3), optional
        Outward surface normals at the markers.
    max_view_angle : float, optional
        Radians; markers seen more obliquely than this are not detected
        (needs ``normals``).

    Returns
    -------
    visible : ndarray (C, M) bool
    """
    return take_visibility(np.asarray(points, dtype=np.float64)[None], rig, np.asarray(vertices)[None], faces,
                           normals=None if normals is None else np.asarray(normals)[None],
                           max_view_angle=max_view_angle)[0]
