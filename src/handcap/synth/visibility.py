"""Which camera sees which marker: image bounds, facing, and occlusion by ray casting.

A marker is seen by a camera when it projects inside the image, lies in front
of the camera, faces it (printed patch corners only: within
``max_view_angle`` of the surface normal) and nothing lies on the straight
line between the camera centre and the marker: no triangle of the hand (its
own skin included) or of the object. The ray test is exact (Moller-Trumbore,
in camera coordinates); the triangles tried for each marker are found in the
image first: those facing the camera whose bounding box holds its projection.
Where numba is installed the test runs compiled (:func:`hidden_compiled`, one
loop over each frame's triangles, the markers sorted in the image), else in
numpy (arrays over frames, markers and triangles); both give the same answers
(tested). One camera at a time.
"""

from __future__ import annotations

import functools

import numpy as np

from handcap.core.compiled import AVAILABLE as COMPILED
from handcap.core.compiled import njit as _njit
from handcap.core.geometry import segments_cross_triangles


#: Marker-triangle pairs compared at once in the image (memory bound of the candidate search).
PAIRS_AT_ONCE = 2_000_000
#: Widening of the triangles' boxes in the image (share of the largest normalised coordinate) before their
#: single-precision test: many times its rounding (6e-8), so no triangle a point lies in is left out.
BOX_SLACK = 1e-5


class _Surface:
    """The occluding triangles of T frames, shared by every camera: vertices (T, V, 3) and faces (F, 3), metres.
    The numpy test also takes the corners of each face as three index columns (F,) and the face normals as three
    component arrays (T, F) with their offsets ``n . a`` (T, F), made when it first asks for them."""

    def __init__(self, vertices, faces):
        self.vertices = np.asarray(vertices, dtype=np.float64)
        self.faces = np.asarray(faces).reshape(-1, 3)

    @functools.cached_property
    def corner(self) -> tuple:
        return tuple(np.ascontiguousarray(self.faces[:, k]) for k in range(3))

    @functools.cached_property
    def normal(self) -> tuple:
        # Components as separate (T, F) arrays: NumPy is slow on products over axes of length 3.
        a, b, c = self._corners
        u, v = [q - p for p, q in zip(a, b)], [q - p for p, q in zip(a, c)]
        return u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2], u[0] * v[1] - u[1] * v[0]

    @functools.cached_property
    def offset(self) -> np.ndarray:
        a, n = self._corners[0], self.normal
        return n[0] * a[0] + n[1] * a[1] + n[2] * a[2]

    @functools.cached_property
    def _corners(self) -> tuple:
        axes = [np.ascontiguousarray(self.vertices[..., d]) for d in range(3)]
        return tuple([np.take(x, i, axis=1) for x in axes] for i in self.corner)


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
    if COMPILED:
        pt_cam = np.where(tested[..., None], points, np.nan) @ rot.T + trans
        ends = pt_cam * (1.0 - end_gap / np.linalg.norm(pt_cam, axis=-1, keepdims=True))
        # Writable, C-ordered arrays of these types: one compiled signature for every caller.
        arrays = [np.require(a, dtype, ("C", "W")) for a, dtype in
                  ((cam, np.float64), (surface.faces, np.int64), (ends, np.float64))]
        return hidden_compiled(*arrays)
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


@_njit
def _bucket(x, start, scale, buckets):
    """The bucket (0 .. buckets - 1) of a coordinate ``x``: monotonic in ``x``, clamped as a float first (so an
    x far out cannot overflow the integer)."""
    return int(min(buckets - 1.0, max(0.0, (x - start) * scale)))


@_njit
def hidden_compiled(cam, faces, ends):
    """The test of :func:`_hidden`, compiled: whether each line from the camera to ``ends`` crosses a triangle
    in front of the camera and facing it (the same Moller-Trumbore arithmetic as
    :func:`segments_cross_triangles`, so the same answers).

    Parameters
    ----------
    cam : ndarray (T, V, 3)
        The surfaces' vertices in camera coordinates, metres.
    faces : ndarray (F, 3)
    ends : ndarray (T, M, 3)
        The lines' far ends in camera coordinates (shortened by the end gap), metres; NaN: not tested.

    Returns
    -------
    hidden : ndarray (T, M) bool

    Notes
    -----
    Each frame's points are sorted by their image x and put in buckets of equal width along it; each
    triangle's box in the image (widened by far more than double precision's rounding) starts at the first
    point of its low end's bucket, walks to the points within its x range, and tries those within its y
    range too. A triangle faces the camera when its normal points against the line of sight,
    ``n . a < 0`` in camera coordinates (the numpy test asks the same in world coordinates): the two can
    differ only for a triangle seen exactly edge on, which no line of sight crosses.
    """
    n_frames, n_points, n_vertices = ends.shape[0], ends.shape[1], cam.shape[1]
    hidden = np.zeros((n_frames, n_points), np.bool_)
    image_x, image_y, ahead = np.empty(n_vertices), np.empty(n_vertices), np.empty(n_vertices, np.bool_)
    point_x, point_y, which = np.empty(n_points), np.empty(n_points), np.empty(n_points, np.int64)
    first = np.empty(2 * n_points, np.int64)
    for t in range(n_frames):
        count, largest = 0, 0.0
        for m in range(n_points):
            d0, d1, d2 = ends[t, m, 0], ends[t, m, 1], ends[t, m, 2]
            if np.isnan(d0) or np.isnan(d1) or np.isnan(d2) or d2 == 0.0:  # (in the camera's plane: no image)
                continue
            point_x[count], point_y[count], which[count] = d0 / d2, d1 / d2, m
            largest = max(largest, abs(point_x[count]), abs(point_y[count]))
            count += 1
        if count == 0:
            continue
        order = np.argsort(point_x[:count])
        sorted_x, sorted_y, sorted_m = point_x[:count][order], point_y[:count][order], which[:count][order]
        bottom, top = sorted_y.min(), sorted_y.max()
        # Buckets of equal width over the points' x range, each with its first point: a box's first point then
        # lies at or after its low end's bucket's first (the bucket of a point is monotonic in its x).
        buckets = 2 * count
        spread = sorted_x[count - 1] - sorted_x[0]
        scale = buckets / spread if spread > 0.0 else 0.0
        r = 0
        for b in range(buckets):
            while r < count and _bucket(sorted_x[r], sorted_x[0], scale, buckets) < b:
                r += 1
            first[b] = r
        for v in range(n_vertices):
            ahead[v] = cam[t, v, 2] > 1e-6
            image_x[v] = cam[t, v, 0] / cam[t, v, 2] if ahead[v] else 0.0
            image_y[v] = cam[t, v, 1] / cam[t, v, 2] if ahead[v] else 0.0
            if ahead[v]:
                largest = max(largest, abs(image_x[v]), abs(image_y[v]))
        slack = 1e-9 * (1.0 + largest)
        for f in range(faces.shape[0]):
            i, j, k = faces[f, 0], faces[f, 1], faces[f, 2]
            if not (ahead[i] and ahead[j] and ahead[k]):
                continue
            a0, a1, a2 = cam[t, i, 0], cam[t, i, 1], cam[t, i, 2]
            e10, e11, e12 = cam[t, j, 0] - a0, cam[t, j, 1] - a1, cam[t, j, 2] - a2
            e20, e21, e22 = cam[t, k, 0] - a0, cam[t, k, 1] - a1, cam[t, k, 2] - a2
            if not (e11 * e22 - e12 * e21) * a0 + (e12 * e20 - e10 * e22) * a1 + (e10 * e21 - e11 * e20) * a2 < 0.0:
                continue  # facing away
            x_low = min(image_x[i], image_x[j], image_x[k]) - slack
            x_high = max(image_x[i], image_x[j], image_x[k]) + slack
            y_low = min(image_y[i], image_y[j], image_y[k]) - slack
            y_high = max(image_y[i], image_y[j], image_y[k]) + slack
            if x_high < sorted_x[0] or x_low > sorted_x[count - 1] or y_high < bottom or y_low > top:
                continue
            low = first[_bucket(x_low, sorted_x[0], scale, buckets)]
            while low < count and sorted_x[low] < x_low:
                low += 1
            t0, t1, t2 = 0.0 - a0, 0.0 - a1, 0.0 - a2
            q0, q1, q2 = t1 * e12 - t2 * e11, t2 * e10 - t0 * e12, t0 * e11 - t1 * e10
            for r in range(low, count):
                if sorted_x[r] > x_high:
                    break
                m = sorted_m[r]
                if hidden[t, m] or sorted_y[r] < y_low or sorted_y[r] > y_high:
                    continue
                d0, d1, d2 = ends[t, m, 0], ends[t, m, 1], ends[t, m, 2]
                p0, p1, p2 = d1 * e22 - d2 * e21, d2 * e20 - d0 * e22, d0 * e21 - d1 * e20
                det = e10 * p0 + e11 * p1 + e12 * p2
                if not abs(det) > 1e-12:
                    continue
                inv = 1.0 / det
                u = (t0 * p0 + t1 * p1 + t2 * p2) * inv
                v = (d0 * q0 + d1 * q1 + d2 * q2) * inv
                s = (e20 * q0 + e21 * q1 + e22 * q2) * inv
                hidden[t, m] = u >= 0 and v >= 0 and u + v <= 1 and s > 0 and s < 1
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
