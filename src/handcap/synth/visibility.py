"""Which camera sees which marker: image bounds, facing, and occlusion by ray casting.

A marker is seen by a camera when it projects inside the image, lies in front
of the camera, faces it (printed patch corners only: within
``max_view_angle`` of the surface normal) and nothing lies on the straight
line between the camera centre and the marker: no triangle of the hand (its
own skin included) or of the object. The ray test is exact (Moller-Trumbore,
in camera coordinates); the triangles tried for each marker are found in the
image first: those facing the camera whose bounding box holds its projection.
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
    """The occluding triangles of one frame, shared by every camera: vertices (V, 3), the corners of each
    face as three index columns (F,) and the face normals (F, 3) with their offsets ``n . a`` (F,), metres."""

    def __init__(self, vertices, faces):
        self.vertices = np.asarray(vertices, dtype=np.float64)
        self.faces = np.asarray(faces)
        self.corner = tuple(np.ascontiguousarray(self.faces[:, k]) for k in range(3))
        a, b, c = (self.vertices[i] for i in self.corner)
        self.normal = np.cross(b - a, c - a)
        self.offset = np.einsum("fi,fi->f", self.normal, a)


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
    return _occluded(_Surface(vertices, faces), camera, points, end_gap)


def _occluded(surface: _Surface, camera, points, end_gap: float = 1e-4) -> np.ndarray:
    points = np.asarray(points, dtype=np.float64)
    hidden = np.zeros(len(points), bool)
    if len(points) == 0 or len(surface.faces) == 0:
        return hidden
    rot, trans = camera.rotation_matrix, camera.translation
    cam = surface.vertices @ rot.T + trans  # (V, 3) camera coordinates
    depth = cam[:, 2]
    ahead = depth > 1e-6
    i, j, k = surface.corner
    # In front of the camera, and facing it: the normal points against the line of sight (n . (a - centre) < 0).
    keep = np.flatnonzero(ahead[i] & ahead[j] & ahead[k] & (surface.offset < surface.normal @ camera.center))
    if len(keep) == 0:
        return hidden
    px = cam[:, :2] / np.where(ahead, depth, 1.0)[:, None]  # normalised image coordinates
    x, y = np.ascontiguousarray(px[:, 0]), np.ascontiguousarray(px[:, 1])
    xs, ys = (x[i[keep]], x[j[keep]], x[k[keep]]), (y[i[keep]], y[j[keep]], y[k[keep]])
    # The boxes in single precision, widened by far more than its rounding: the box test only picks the
    # triangles the exact test (double precision) tries, and half the bytes make it about twice as fast.
    x_low, x_high = np.minimum(np.minimum(*xs[:2]), xs[2]), np.maximum(np.maximum(*xs[:2]), xs[2])
    y_low, y_high = np.minimum(np.minimum(*ys[:2]), ys[2]), np.maximum(np.maximum(*ys[:2]), ys[2])
    widen = BOX_SLACK * (1.0 + max(np.abs(x_low).max(), np.abs(x_high).max(), np.abs(y_low).max(),
                                   np.abs(y_high).max()))
    x_low, y_low = (x_low - widen).astype(np.float32), (y_low - widen).astype(np.float32)
    x_high, y_high = (x_high + widen).astype(np.float32), (y_high + widen).astype(np.float32)
    pt_cam = points @ rot.T + trans
    pt_x = (pt_cam[:, 0] / pt_cam[:, 2]).astype(np.float32)[:, None]
    pt_y = (pt_cam[:, 1] / pt_cam[:, 2]).astype(np.float32)[:, None]
    which, cand = [], []
    step = max(1, PAIRS_AT_ONCE // len(keep))
    for start in range(0, len(points), step):
        s = slice(start, start + step)
        # A point can only be behind a triangle it projects into: inside its bounding box in the image.
        inside = (pt_x[s] >= x_low) & (pt_x[s] <= x_high) & (pt_y[s] >= y_low) & (pt_y[s] <= y_high)
        flat = np.flatnonzero(inside)
        which.append(flat // len(keep) + start)
        cand.append(flat % len(keep))
    which, cand = np.concatenate(which), keep[np.concatenate(cand)]
    if len(which) == 0:
        return hidden
    ends = pt_cam[which] * (1.0 - end_gap / np.linalg.norm(pt_cam[which], axis=1, keepdims=True))
    hit = segments_cross_triangles(np.zeros_like(ends), ends, cam[surface.faces[cand]])
    hidden[np.unique(which[hit])] = True
    return hidden


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
    points = np.asarray(points, dtype=np.float64)
    valid = ~np.isnan(points).any(axis=1)
    out = np.zeros((len(rig), len(points)), bool)
    surface = _Surface(vertices, faces)
    for c, camera in enumerate(rig):
        pixels, depth = camera.project(np.where(valid[:, None], points, 0.0))
        ok = valid & (depth > 0) & camera.in_image(pixels)
        if normals is not None and max_view_angle is not None:
            to_camera = camera.center - points
            to_camera /= np.linalg.norm(to_camera, axis=1, keepdims=True)
            ok &= np.einsum("mi,mi->m", normals, to_camera) > np.cos(max_view_angle)
        idx = np.flatnonzero(ok)
        ok[idx[_occluded(surface, camera, points[idx])]] = False
        out[c] = ok
    return out
