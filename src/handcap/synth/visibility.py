"""Which camera sees which marker: image bounds, facing, and occlusion by ray casting.

A marker is seen by a camera when it projects inside the image, lies in front
of the camera, faces it (printed patch corners only: within
``max_view_angle`` of the surface normal) and nothing lies on the straight
line between the camera centre and the marker: no triangle of the hand (its
own skin included) or of the object. The ray test is exact (Moller-Trumbore,
in camera coordinates); the triangles tried for each marker are found in the
image first, through a k-d tree of projected triangle centres.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from handcap.core.geometry import segments_cross_triangles


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
    (about half) are tested.
    """
    points = np.asarray(points, dtype=np.float64)
    hidden = np.zeros(len(points), bool)
    if len(points) == 0 or len(faces) == 0:
        return hidden
    cam = vertices @ camera.rotation_matrix.T + camera.translation
    tri = cam[faces]
    normal = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    keep = np.flatnonzero(((normal * tri[:, 0]).sum(axis=1) < 0) & (tri[:, :, 2] > 1e-6).all(axis=1))
    if len(keep) == 0:
        return hidden
    tri_px = tri[keep, :, :2] / tri[keep, :, 2:]  # normalised image coordinates
    centre = tri_px.mean(axis=1)
    radius = np.sqrt(((tri_px - centre[:, None]) ** 2).sum(axis=2).max(axis=1))
    pt_cam = points @ camera.rotation_matrix.T + camera.translation
    pt_px = pt_cam[:, :2] / pt_cam[:, 2:]
    # Small triangles through a k-d tree of their centres; the few large ones
    # (long slivers of an object) are tried against every point.
    cut = 3.0 * np.median(radius)
    small = radius <= cut
    lists = cKDTree(centre[small]).query_ball_point(pt_px, r=cut)
    counts = np.fromiter((len(c) for c in lists), int, len(lists))
    which = np.repeat(np.arange(len(points)), counts)
    cand = np.flatnonzero(small)[np.concatenate([np.asarray(c, int) for c in lists] + [np.zeros(0, int)])]
    large = np.flatnonzero(~small)
    which = np.concatenate([which, np.repeat(np.arange(len(points)), len(large))])
    cand = np.concatenate([cand, np.tile(large, len(points))])
    # A point can only be behind a triangle it projects into: within its circumradius.
    near = ((pt_px[which] - centre[cand]) ** 2).sum(axis=1) <= radius[cand] ** 2
    which, cand = which[near], keep[cand[near]]
    if len(which) == 0:
        return hidden
    ends = pt_cam[which] * (1.0 - end_gap / np.linalg.norm(pt_cam[which], axis=1, keepdims=True))
    hit = segments_cross_triangles(np.zeros_like(ends), ends, tri[cand])
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
    for c, camera in enumerate(rig):
        pixels, depth = camera.project(np.where(valid[:, None], points, 0.0))
        ok = valid & (depth > 0) & camera.in_image(pixels)
        if normals is not None and max_view_angle is not None:
            to_camera = camera.center - points
            to_camera /= np.linalg.norm(to_camera, axis=1, keepdims=True)
            ok &= np.einsum("mi,mi->m", normals, to_camera) > np.cos(max_view_angle)
        idx = np.flatnonzero(ok)
        ok[idx[occluded(camera, points[idx], vertices, faces)]] = False
        out[c] = ok
    return out
