"""Photographs of printed sheets of coded patches, made in 2D with exact truth (no OpenGL needed).

A sheet is the atlas of a set of patches (:func:`handcap.synth.textures.build_atlas`)
on white paper. A photograph of it is a plane seen in perspective (any in-plane
turn, tilts up to :attr:`PageLook.tilt_deg`), bent by paper curl (a smooth
displacement of the image), lit unevenly with a shadow and sometimes a glint,
with print texture and grey ink, partly covered by occluders (fingers, a pen),
then put through the same camera effects as the 3D renders
(:func:`handcap.synth.images.camera_effects`). One resampling maps every output
pixel to the sheet, so the truth of each corner is the exact image of its sheet
point under the same map.

These pictures train the block reader on many more fonts, alphabets and sizes
than hand renders can cheaply give, and measure how well a flat printed page is
read. Pixel convention: OpenCV's (pixel centres at integers).
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
from scipy import ndimage

from handcap.synth.images import ImageStyle, camera_effects
from handcap.synth.textures import PatchAtlas


@dataclass(frozen=True)
class PageLook:
    """Ranges each photograph's geometry and light are drawn from (uniformly).

    Attributes
    ----------
    square_px : (float, float)
        Side of a checker square in the image where the sheet faces the camera, pixels.
    tilt_deg : (float, float)
        Angle between the sheet's normal and the line of sight, degrees.
    focal_px : (float, float)
        Focal length of the camera, pixels (short ones give strong perspective).
    curl : (float, float)
        Largest displacement of paper curl, in squares.
    size : (int, int)
        Largest image width and height; each photo takes 50-100 % of each.
    ink : (float, float)
        Grey level of the ink relative to the paper.
    shade : (float, float)
        Darkest share of the light across the image.
    occluders : (int, int)
        How many occluders (both inclusive).
    glint : float
        Chance of a specular glint.
    """

    square_px: tuple = (9.0, 40.0)
    tilt_deg: tuple = (0.0, 60.0)
    focal_px: tuple = (500.0, 3000.0)
    curl: tuple = (0.0, 1.5)
    size: tuple = (640, 512)
    ink: tuple = (0.02, 0.2)
    shade: tuple = (0.45, 1.0)
    occluders: tuple = (0, 2)
    glint: float = 0.2


@dataclass(frozen=True)
class PagePhoto:
    """One photograph of a sheet and the truth of every printed corner.

    Attributes
    ----------
    image : ndarray (H, W) uint8
    xy : ndarray (N, 2)
        Pixels of every corner of the atlas's patches (in patch order, each patch's
        :meth:`~handcap.patterns.pattern.Patch.vertices` order), visible or not.
    visible : ndarray (N,) bool
        In the image (3 pixels from its border) and not under an occluder.
    """

    image: np.ndarray
    xy: np.ndarray
    visible: np.ndarray


class PagePhotographer:
    """Takes random photographs of one sheet (see the module docstring).

    Parameters
    ----------
    atlas : PatchAtlas
        The printed patches, drawn at 16 or more pixels per square.
    look : PageLook, optional
    style : ImageStyle, optional
        Camera effects (occluders and glints are the look's).
    """

    def __init__(self, atlas: PatchAtlas, look: PageLook | None = None, style: ImageStyle | None = None):
        self.look, self.style = look or PageLook(), style or ImageStyle()
        sheet = atlas.image.astype(np.float32) / 255.0
        printed = np.zeros(sheet.shape, bool)
        for patch, origin in zip(atlas.patches, atlas.origins):
            x0, y0 = np.floor(origin - 0.5 * atlas.square).astype(int)
            x1, y1 = np.ceil(origin + (np.array([patch.cols, patch.rows]) + 0.5) * atlas.square).astype(int)
            printed[max(y0, 0):y1, max(x0, 0):x1] = True
        sheet[~printed] = 1.0  # paper between the patches
        self.levels = [sheet]  # halved with area averaging while a square keeps 8 pixels
        square = atlas.square
        while square >= 16:
            self.levels.append(cv2.resize(self.levels[-1], None, fx=0.5, fy=0.5, interpolation=cv2.INTER_AREA))
            square /= 2
        self.square = atlas.square
        # Corner positions on the sheet (texel edges are at integers there, so centres sit at +0.5).
        self.corners = np.concatenate([origin + patch.vertices()[:, ::-1] * atlas.square
                                       for patch, origin in zip(atlas.patches, atlas.origins)]) - 0.5

    def photograph(self, rng) -> PagePhoto:
        """One random photograph.

        Parameters
        ----------
        rng : numpy.random.Generator

        Returns
        -------
        PagePhoto
        """
        look = self.look
        w = int(look.size[0] * rng.uniform(0.5, 1.0)) // 2 * 2
        h = int(look.size[1] * rng.uniform(0.5, 1.0)) // 2 * 2
        side = rng.uniform(*look.square_px)
        level = int(np.clip(np.floor(np.log2(self.square / (1.5 * side))), 0, len(self.levels) - 1))
        sheet, k = self.levels[level], 0.5 ** level
        homography = self._homography(side, k, (w, h), rng)
        curl = _curl_field((w, h), rng.uniform(*look.curl) * side, rng)
        gx, gy = np.meshgrid(np.arange(w, dtype=np.float32), np.arange(h, dtype=np.float32))
        bent = np.stack([gx + curl[0], gy + curl[1], np.ones_like(gx)], axis=-1) @ np.linalg.inv(homography).T
        ahead = bent[..., 2] > 1e-9
        z = np.where(ahead, bent[..., 2], 1.0)
        mapx = np.where(ahead, bent[..., 0] / z, -1e6).astype(np.float32)
        mapy = np.where(ahead, bent[..., 1] / z, -1e6).astype(np.float32)
        ink = rng.uniform(*look.ink)
        grain = cv2.GaussianBlur(rng.normal(0, 1, sheet.shape[:2]).astype(np.float32), (0, 0), 1.0)
        printed = np.clip(sheet * (1 + rng.uniform(0.0, 0.06) * grain), 0, 1)
        picture = cv2.remap(ink + (1 - ink) * printed, mapx, mapy, cv2.INTER_LINEAR,
                            borderMode=cv2.BORDER_CONSTANT, borderValue=float(rng.uniform(0.05, 0.6)))
        picture *= _light((w, h), rng.uniform(*look.shade), rng)
        covered = np.zeros((h, w), np.float32)
        for _ in range(int(rng.integers(look.occluders[0], look.occluders[1] + 1))):
            covered = np.maximum(covered, _occluder((w, h), side, rng))
        picture = picture * (1 - covered) + covered * rng.uniform(0.05, 0.9)
        if rng.random() < look.glint:
            picture += _glint((w, h), side, rng)
        image = camera_effects(picture.astype(np.float32), self.style, rng)
        # Truth: sheet corner -> homography -> undo the curl (the pixel q with q + curl(q) = p).
        pts = np.c_[(self.corners + 0.5) * k - 0.5, np.ones(len(self.corners))] @ homography.T
        front = pts[:, 2] > 1e-9
        p = pts[:, :2] / np.where(front, pts[:, 2], 1.0)[:, None]
        q, unbent = unbent_points(curl, p)
        inside = front & unbent & (q >= 3).all(axis=1) & (q[:, 0] <= w - 4) & (q[:, 1] <= h - 4)
        hidden = ndimage.maximum_filter(covered, size=3) > 0.5
        visible = inside.copy()
        at = np.round(q[inside]).astype(int)
        visible[inside] = ~hidden[at[:, 1], at[:, 0]]
        return PagePhoto(image, q, visible)

    def _homography(self, side: float, k: float, size, rng) -> np.ndarray:
        """Sheet level coordinates -> image pixels: a turned, tilted plane through a pinhole."""
        look = self.look
        centre = (self.corners[rng.integers(len(self.corners))] + 0.5) * k - 0.5
        scale = side / (self.square * k)
        turn = rng.uniform(0, 2 * np.pi)
        c, s = np.cos(turn), np.sin(turn)
        plane = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]]) @ np.array([[scale, 0, -scale * centre[0]],
                                                                         [0, scale, -scale * centre[1]],
                                                                         [0, 0, 1]])
        axis = rng.uniform(0, 2 * np.pi)
        tilt = np.deg2rad(rng.uniform(*look.tilt_deg))
        rot, _ = cv2.Rodrigues(np.array([np.cos(axis), np.sin(axis), 0.0]) * tilt)
        focal = rng.uniform(*look.focal_px)
        lens = np.array([[focal, 0, size[0] * rng.uniform(0.3, 0.7)], [0, focal, size[1] * rng.uniform(0.3, 0.7)],
                         [0, 0, 1]])
        return lens @ np.c_[rot[:, :2], [0.0, 0.0, focal]] @ plane


def _curl_field(size, amplitude: float, rng) -> np.ndarray:
    """A smooth displacement field (2, H, W): a coarse random grid interpolated by cubics."""
    w, h = size
    coarse = rng.normal(0, amplitude / 2, (2, 3, 3)).astype(np.float32)
    coarse -= coarse.mean(axis=(1, 2), keepdims=True)
    return np.stack([cv2.resize(c, (w, h), interpolation=cv2.INTER_CUBIC) for c in coarse])


def unbent_points(curl: np.ndarray, p: np.ndarray, *, steps: int = 20, tol: float = 1e-3,
                  least_det: float = 0.2) -> tuple[np.ndarray, np.ndarray]:
    """The pixels ``q`` that a curl field brings to ``p``: ``q + curl(q) = p``, by Newton's method.

    The photograph at pixel ``q`` shows the sheet where ``q + curl(q)`` lies, so a sheet point that projects to ``p``
    is seen at ``q``. (Plain fixed-point steps ``q = p - curl(q)`` converge only where the field bends by less than a
    pixel per pixel; in one photograph of ten of the default look it bends more somewhere, and 0.2 % of the visible
    corners were placed up to 4 px off, on small images with large squares up to 60 px.)

    Parameters
    ----------
    curl : ndarray (2, H, W)
        Displacement (x, y) of each pixel, pixels (sampled bilinearly, clamped at the border).
    p : ndarray (N, 2)
        Points, pixels.
    steps : int
        Newton steps.
    tol : float
        Largest residual ``|q + curl(q) - p|`` of a solution, pixels.
    least_det : float
        Least determinant of the map's Jacobian at a solution: where the field folds the paper over (0 or below) the
        point may show twice, or not at all.

    Returns
    -------
    q : ndarray (N, 2)
        Pixels.
    ok : ndarray (N,) bool
        Solved to ``tol`` where the map is one to one (``least_det``).
    """
    grads = [np.gradient(component) for component in curl]  # each (d/dy, d/dx)
    slopes = np.stack([grads[0][1], grads[0][0], grads[1][1], grads[1][0]])  # dcx/dx, dcx/dy, dcy/dx, dcy/dy
    q = p - _sample(curl, p)
    for _ in range(steps):
        r = q + _sample(curl, q) - p
        a, b, c, d = (1.0 + _sample(slopes[:1], q)[:, 0], _sample(slopes[1:2], q)[:, 0],
                      _sample(slopes[2:3], q)[:, 0], 1.0 + _sample(slopes[3:], q)[:, 0])
        det = a * d - b * c
        safe = np.abs(det) > 1e-6
        det = np.where(safe, det, 1.0)
        step = np.stack([d * r[:, 0] - b * r[:, 1], a * r[:, 1] - c * r[:, 0]], axis=1) / det[:, None]
        q = q - np.where(safe[:, None], step, r)
    r = np.linalg.norm(q + _sample(curl, q) - p, axis=1)
    a, b, c, d = (1.0 + _sample(slopes[:1], q)[:, 0], _sample(slopes[1:2], q)[:, 0], _sample(slopes[2:3], q)[:, 0],
                  1.0 + _sample(slopes[3:], q)[:, 0])
    return q, (r <= tol) & (a * d - b * c >= least_det)


def _sample(field: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Bilinear values of a (2, H, W) field at points (N, 2) (x, y), clamped to its border."""
    coords = [points[:, 1], points[:, 0]]
    return np.stack([ndimage.map_coordinates(f, coords, order=1, mode="nearest") for f in field], axis=1)


def _light(size, darkest: float, rng) -> np.ndarray:
    """Uneven light: a linear ramp from ``darkest`` to 1 and sometimes a soft-edged shadow."""
    w, h = size
    gx, gy = np.meshgrid(np.linspace(-1, 1, w, dtype=np.float32), np.linspace(-1, 1, h, dtype=np.float32))
    way = rng.uniform(0, 2 * np.pi)
    ramp = (np.cos(way) * gx + np.sin(way) * gy + 1.5) / 3.0
    light = darkest + (1 - darkest) * np.clip(ramp, 0, 1)
    if rng.random() < 0.3:
        way = rng.uniform(0, 2 * np.pi)
        edge = np.cos(way) * gx + np.sin(way) * gy - rng.uniform(-0.5, 0.8)
        light *= 1 - rng.uniform(0.2, 0.5) / (1 + np.exp(-edge / rng.uniform(0.02, 0.2)))
    return light


def _occluder(size, side: float, rng) -> np.ndarray:
    """A soft-edged ellipse 2-8 squares long (a finger, a pen): coverage 0..1 (H, W)."""
    w, h = size
    mask = np.zeros((h, w), np.uint8)
    centre = (int(rng.uniform(0, w)), int(rng.uniform(0, h)))
    axes = (int(rng.uniform(1, 4) * side), int(rng.uniform(0.5, 1.5) * side))
    cv2.ellipse(mask, centre, axes, rng.uniform(0, 180), 0, 360, 255, -1, lineType=cv2.LINE_AA)
    return cv2.GaussianBlur(mask.astype(np.float32) / 255.0, (0, 0), max(0.5, 0.1 * side))


def _glint(size, side: float, rng) -> np.ndarray:
    """A specular glint on glossy tape: a bright Gaussian spot 1-5 squares across."""
    w, h = size
    gx, gy = np.meshgrid(np.arange(w, dtype=np.float32), np.arange(h, dtype=np.float32))
    x, y, r = rng.uniform(0, w), rng.uniform(0, h), rng.uniform(0.5, 2.5) * side
    return rng.uniform(0.3, 1.2) * np.exp(-((gx - x) ** 2 + (gy - y) ** 2) / (2 * r * r))
