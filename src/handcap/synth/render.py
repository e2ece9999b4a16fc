"""Small software renderer for pictures of hands, objects and markers (OpenCV).

Painter's algorithm with Lambert shading: good enough for a report or a demo
picture, exact enough to show which markers are where. Not a visibility oracle
(that is :mod:`handcap.synth.visibility`).
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from handcap.core.files import atomic_output


@dataclass(frozen=True)
class View:
    """A pinhole view for pictures: ``x_cam = rotation @ x_world + translation``.

    Attributes
    ----------
    rotation : ndarray (3, 3)
    translation : ndarray (3,)
        Metres.
    focal : float
        Pixels.
    size : tuple (width, height)
        Pixels.
    """

    rotation: np.ndarray
    translation: np.ndarray
    focal: float
    size: tuple[int, int]

    @classmethod
    def looking_at(cls, target, eye, up=(0.0, 0.0, 1.0), *, size=(800, 600), fov_deg: float = 40.0) -> "View":
        """A view from ``eye`` towards ``target`` (metres) with image up along ``up``.

        Parameters
        ----------
        target : array_like (3,)
            Point at the image centre, metres.
        eye : array_like (3,)
            Camera centre, metres.
        up : array_like (3,)
            World direction that appears upwards in the image (no unit; x is used when it is
            parallel to the line of sight).
        size : (int, int)
            Image width and height, pixels.
        fov_deg : float
            Horizontal field of view, degrees.

        Returns
        -------
        View
            Focal length in pixels, translation in metres.
        """
        target, eye, up = (np.asarray(v, dtype=np.float64) for v in (target, eye, up))
        forward = target - eye
        forward /= np.linalg.norm(forward)
        right = np.cross(forward, up)
        if np.linalg.norm(right) < 1e-9:
            right = np.cross(forward, [1.0, 0.0, 0.0])
        right /= np.linalg.norm(right)
        down = np.cross(forward, right)
        rotation = np.stack([right, down, forward])
        focal = 0.5 * size[0] / np.tan(np.deg2rad(fov_deg) / 2)
        return cls(rotation, -rotation @ eye, float(focal), (int(size[0]), int(size[1])))

    def project(self, points) -> tuple[np.ndarray, np.ndarray]:
        """Pixels (..., 2) and depths (...) of world points (..., 3)."""
        cam = np.asarray(points, dtype=np.float64) @ self.rotation.T + self.translation
        depth = cam[..., 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            px = self.focal * cam[..., :2] / depth[..., None] + 0.5 * np.array(self.size)
        return px, depth


def _shade(normals, color, light) -> np.ndarray:
    lambert = np.clip(np.abs(normals @ light), 0.0, 1.0)
    return np.clip(np.asarray(color, dtype=np.float64)[None] * (0.35 + 0.65 * lambert[:, None]), 0, 255)


def render(view: View, meshes=(), points=(), *, background=(255, 255, 255), supersample: int = 2) -> np.ndarray:
    """Draw meshes and marker points into an RGB image.

    Parameters
    ----------
    view : View
    meshes : sequence of (vertices (V, 3), faces (F, 3), rgb)
    points : sequence of (positions (N, 3), rgb, radius_px); NaN rows skipped.
        Points are drawn in depth order together with the triangles, so a
        marker behind the hand is hidden.

    Returns
    -------
    image : ndarray of uint8, shape (height, width, 3), RGB
    """
    s = supersample
    width, height = view.size
    image = np.empty((height * s, width * s, 3), np.uint8)
    image[:] = background
    light = -view.rotation[2] + 0.5 * view.rotation[1]
    light /= np.linalg.norm(light)
    items = []  # (depth, kind, payload)
    for vertices, faces, color in meshes:
        px, depth = view.project(vertices)
        tri = vertices[faces]
        normals = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        normals /= np.maximum(np.linalg.norm(normals, axis=1, keepdims=True), 1e-15)
        colors = _shade(normals, color, light)
        tri_depth = depth[faces].mean(axis=1)
        ok = (depth[faces] > 1e-3).all(axis=1)
        for f in np.flatnonzero(ok):
            items.append((tri_depth[f], 0, (px[faces[f]], colors[f])))
    for positions, color, radius in points:
        positions = np.asarray(positions, dtype=np.float64).reshape(-1, 3)
        positions = positions[~np.isnan(positions).any(axis=1)]
        px, depth = view.project(positions)
        for p, d in zip(px, depth):
            if d > 1e-3:
                # Slightly in front so a marker on the skin is drawn over its own triangle.
                items.append((d - 0.004, 1, (p, color, radius)))
    items.sort(key=lambda item: -item[0])
    for _, kind, payload in items:
        if kind == 0:
            poly, color = payload
            cv2.fillConvexPoly(image, np.round(poly * s).astype(np.int32), tuple(int(c) for c in color),
                               lineType=cv2.LINE_AA)
        else:
            p, color, radius = payload
            centre = tuple(int(v) for v in np.round(p * s))
            cv2.circle(image, centre, int(radius * s), tuple(int(c) for c in color), -1, lineType=cv2.LINE_AA)
            cv2.circle(image, centre, int(radius * s), (40, 40, 40), max(1, s // 2), lineType=cv2.LINE_AA)
    if s > 1:
        image = cv2.resize(image, (width, height), interpolation=cv2.INTER_AREA)
    return image


def save_png(path, image) -> None:
    """Write an RGB image as PNG (atomically).

    Parameters
    ----------
    path : str or Path
    image : ndarray of uint8, shape (height, width, 3)
        RGB, as :func:`render` returns it.

    Raises
    ------
    RuntimeError
        OpenCV could not encode the image.
    HandcapError
        The file could not be written.
    """
    ok, data = cv2.imencode(".png", cv2.cvtColor(image, cv2.COLOR_RGB2BGR))
    if not ok:
        raise RuntimeError("OpenCV could not encode the PNG")
    with atomic_output(path) as fh:
        fh.write(data.tobytes())
