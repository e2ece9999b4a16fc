"""Camera images of a patched hand, for training the detector and testing it against exact truth.

Headless OpenGL on the CPU (moderngl on Mesa's EGL llvmpipe): the hand's skin
mesh with a procedural skin texture, the printed patches as textured meshes
through their corners (0.5 mm above the skin, like a transfer on tape), a few
occluders, then what a real camera does to the picture: lens distortion (the
undistorted render is resampled through the camera's own distortion model),
defocus and motion blur, exposure and gamma, shot and read noise, 8-bit
output. Every printed corner's truth is the projection of the mesh vertex it
is drawn at, with the camera's distortion, so corner truth is exact; a corner
is visible where the depth buffer shows its patch in front (self-occlusion and
occluders) and it faces the camera.

Coordinates: world metres; images are ``(H, W)`` uint8 with pixel ``(x, y)``
at column x, row y, pixel centres at integers (OpenCV's convention).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from handcap.core.errors import HandcapError
from handcap.core.srgb import srgb_encoded
from handcap.synth.objects import random_blobs
from handcap.synth.textures import PatchAtlas

#: The GLSL shaders (files beside this module): vertex positions through the projection; grey shading of
#: printed patches (atlas texture) and skin (procedural grain), two lights, Lambert and Blinn-Phong glints.
_SHADERS = Path(__file__).resolve().parent / "shaders"


#: A printed corner seen more obliquely than this (radians from its normal) counts as not visible, as in
#: :func:`handcap.synth.scene.synthesize` for patch layouts.
MAX_VIEW_ANGLE = np.deg2rad(75.0)


@dataclass(frozen=True)
class ImageStyle:
    """Ranges the renderer draws each image's look from (uniformly, per image).

    Attributes
    ----------
    blur_sigma : (float, float)
        Defocus, Gaussian sigma in pixels.
    motion_px : (float, float)
        Length of a straight motion-blur streak, pixels.
    gain : (float, float)
        Exposure factor.
    gamma : (float, float)
    read_noise : (float, float)
        Read-noise sigma, grey levels of 255.
    shot_noise : float
        Shot-noise factor: sigma = shot_noise * sqrt(level).
    specular : (float, float)
        Strength of glints on the skin and tape.
    occluders : (int, int)
        How many occluding blobs near the hand (both inclusive).
    background : (float, float)
        Mean background grey level, 0..1.
    response : {"linear", "srgb"}
        The grey levels written: linear in the light, as a machine-vision camera records them, or encoded as
        sRGB (IEC 61966-2-1), as phones, webcams and most video do (after the noise: a camera encodes its raw
        levels).
    """

    blur_sigma: tuple = (0.3, 1.2)
    motion_px: tuple = (0.0, 2.0)
    gain: tuple = (0.7, 1.3)
    gamma: tuple = (0.8, 1.2)
    read_noise: tuple = (0.5, 3.0)
    shot_noise: float = 0.25
    specular: tuple = (0.0, 0.35)
    occluders: tuple = (0, 2)
    background: tuple = (0.05, 0.5)
    response: str = "linear"

    @classmethod
    def clean(cls) -> "ImageStyle":
        """A plain look: no blur, noise, glints or occluders (for tests of geometry)."""
        return cls((0.0, 0.0), (0.0, 0.0), (1.0, 1.0), (1.0, 1.0), (0.0, 0.0), 0.0, (0.0, 0.0), (0, 0),
                   (0.2, 0.2))


@dataclass(frozen=True)
class RenderedImage:
    """One camera image and the truth of every printed corner.

    Attributes
    ----------
    image : ndarray (H, W) uint8
    xy : ndarray (N, 2)
        Pixels (distorted image) of the N corners, whether visible or not.
    visible : ndarray (N,) bool
        In the image, facing the camera (within :data:`MAX_VIEW_ANGLE`) and not hidden at its pixel or
        the 8 around it.
    """

    image: np.ndarray
    xy: np.ndarray
    visible: np.ndarray


def _context():
    try:
        import moderngl  # an optional extra: only the renderer needs it
    except ImportError:
        raise HandcapError("rendering images needs moderngl: pip install 'handcap[images]'") from None
    errors = []
    for backend in ("egl", None):
        try:
            return moderngl.create_standalone_context(**({"backend": backend} if backend else {}))
        except Exception as err:  # noqa: BLE001 - each backend fails in its own way
            errors.append(f"{backend or 'default'}: {err}")
    raise HandcapError("no headless OpenGL context (install Mesa's EGL: apt-get install libegl1 libgl1-mesa-dri); "
                       + "; ".join(errors))


#: Smallest patch triangle drawn, square metres: a decal's cell folded flat at a joint (its texture squeezed into
#: nothing) made llvmpipe's anisotropic filter take 100 s over one image instead of 0.1 s.
MIN_TRIANGLE_AREA = 1e-10


def _drawable(vertices, faces):
    """``faces`` (F, 3) of ``vertices`` (V, 3) but those under :data:`MIN_TRIANGLE_AREA`."""
    a, b, c = (vertices[faces[:, k]] for k in range(3))
    return faces[0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1) >= MIN_TRIANGLE_AREA]


def _vertex_normals(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    tri = vertices[faces]
    face_n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    normals = np.zeros_like(vertices)
    for k in range(3):
        np.add.at(normals, faces[:, k], face_n)
    return normals / np.maximum(np.linalg.norm(normals, axis=1, keepdims=True), 1e-12)


def _grid_mesh(grid: np.ndarray):
    """Triangles of a (R, C, 3) point grid: faces (F, 3) into the flattened grid."""
    rows, cols = grid.shape[:2]
    idx = np.arange(rows * cols).reshape(rows, cols)
    a, b, c, d = idx[:-1, :-1], idx[:-1, 1:], idx[1:, 1:], idx[1:, :-1]
    return np.concatenate([np.stack([a, b, c], -1).reshape(-1, 3), np.stack([a, c, d], -1).reshape(-1, 3)])


class PatchRenderer:
    """Renders a hand mesh with printed patches seen by calibrated cameras (see the module docstring).

    Parameters
    ----------
    atlas : PatchAtlas
        Textures of the patches that are drawn.
    faces : ndarray (F, 3)
        The hand mesh's triangles.
    style : ImageStyle
    coords : sequence of (ndarray, ndarray), optional
        Per patch, the grid coordinates of the rows and columns of the points :meth:`render` is given
        (:class:`~handcap.synth.decals.PatchSkin` ``rows`` and ``cols``); they must hold every integer from
        0 to the patch's rows (cols). Default: -0.5, 0, 1, ..., n, n + 0.5.
    """

    def __init__(self, atlas: PatchAtlas, faces, style: ImageStyle | None = None, coords=None):
        self.atlas = atlas
        self.faces = np.asarray(faces, dtype=np.int32)
        self.style = style or ImageStyle()
        self.ctx = _context()
        self.program = self.ctx.program(vertex_shader=(_SHADERS / "patch.vert").read_text(),
                                        fragment_shader=(_SHADERS / "patch.frag").read_text())
        self.depth_program = self.ctx.program(vertex_shader=(_SHADERS / "patch.vert").read_text(),
                                              fragment_shader="#version 330\nvoid main() {}\n")
        flipped = np.ascontiguousarray(atlas.image)
        self.texture = self.ctx.texture(flipped.shape[::-1], 1, flipped.tobytes())
        self.texture.build_mipmaps()
        self.texture.anisotropy = 16.0
        self.texture.repeat_x = self.texture.repeat_y = False
        self._maps = {}
        self._buffers = {}
        # One patch mesh layout per patch: its grid faces and texture coordinates (fixed).
        self._patch_faces, self._patch_uv, self._corner_nodes = [], [], []
        for k, patch in enumerate(atlas.patches):
            if coords is None:
                r = np.r_[-0.5, np.arange(patch.rows + 1), patch.rows + 0.5]
                c = np.r_[-0.5, np.arange(patch.cols + 1), patch.cols + 0.5]
            else:
                r, c = (np.asarray(v, dtype=np.float64) for v in coords[k])
            rr, cc = np.meshgrid(r, c, indexing="ij")
            self._patch_uv.append(atlas.uv(k, rr, cc).reshape(-1, 2))
            self._patch_faces.append(_grid_mesh(rr[..., None]))
            # Sample node of each corner (patch.vertices() order), and of its neighbours for the normal.
            verts = patch.vertices()
            ri = np.array([np.flatnonzero(np.isclose(r, v))[0] for v in verts[:, 0]])
            ci = np.array([np.flatnonzero(np.isclose(c, v))[0] for v in verts[:, 1]])
            self._corner_nodes.append((ri, ci))

    def close(self) -> None:
        """Free the OpenGL context."""
        for buffers in self._buffers.values():
            for obj in buffers:
                for att in obj.color_attachments + ((obj.depth_attachment,) if obj.depth_attachment else ()):
                    att.release()
                obj.release()
        self._buffers.clear()
        self.ctx.release()

    def _framebuffers(self, size) -> tuple:
        """The render's framebuffers for an image size, made once and kept (each render clears them): the
        multisampled render, its depth, and the resolved render."""
        if size not in self._buffers:
            self._buffers[size] = (
                self.ctx.framebuffer(self.ctx.renderbuffer(size, components=1, samples=4, dtype="f4"),
                                     self.ctx.depth_renderbuffer(size, samples=4)),
                self.ctx.framebuffer(depth_attachment=self.ctx.depth_texture(size)),
                self.ctx.framebuffer(self.ctx.renderbuffer(size, components=1, dtype="f4")))
        return self._buffers[size]

    # -- geometry of the undistorted render -------------------------------------------------------------------
    def _render_camera(self, camera):
        """The pinhole of the undistorted render: its matrix and size, padded to cover the distorted image."""
        key = id(camera)
        if key not in self._maps:
            w, h = camera.size
            border = np.concatenate([np.c_[np.arange(0, w, 8), np.zeros(len(range(0, w, 8)))],
                                     np.c_[np.arange(0, w, 8), np.full(len(range(0, w, 8)), h - 1)],
                                     np.c_[np.zeros(len(range(0, h, 8))), np.arange(0, h, 8)],
                                     np.c_[np.full(len(range(0, h, 8)), w - 1), np.arange(0, h, 8)],
                                     [[w - 1, h - 1]]]).astype(np.float64)
            k = camera.matrix
            flat = camera.undistort_pixels(border, normalised=True)
            px = flat[:, 0] * k[0, 0] + k[0, 2]
            py = flat[:, 1] * k[1, 1] + k[1, 2]
            pad_l, pad_t = int(np.ceil(max(0.0, -px.min()))) + 2, int(np.ceil(max(0.0, -py.min()))) + 2
            pad_r, pad_b = int(np.ceil(max(0.0, px.max() - w))) + 2, int(np.ceil(max(0.0, py.max() - h))) + 2
            size = (w + pad_l + pad_r, h + pad_t + pad_b)
            matrix = k.copy()
            matrix[0, 2] += pad_l
            matrix[1, 2] += pad_t
            # For each pixel of the distorted image, where it lies in the undistorted render.
            gx, gy = np.meshgrid(np.arange(w, dtype=np.float64), np.arange(h, dtype=np.float64))
            flat = camera.undistort_pixels(np.c_[gx.ravel(), gy.ravel()], normalised=True)
            map_x = (flat[:, 0] * matrix[0, 0] + matrix[0, 2]).reshape(h, w).astype(np.float32)
            map_y = (flat[:, 1] * matrix[1, 1] + matrix[1, 2]).reshape(h, w).astype(np.float32)
            self._maps[key] = (camera, matrix, size, map_x, map_y)
        return self._maps[key][1:]

    @staticmethod
    def _mvp(camera, matrix, size, near: float, far: float) -> np.ndarray:
        w, h = size
        fx, fy, cx, cy = matrix[0, 0], matrix[1, 1], matrix[0, 2], matrix[1, 2]
        # Pixel centres at integers: x_ndc = 2 (u + 0.5) / w - 1, y flipped so that row 0 is the top.
        proj = np.array([[2 * fx / w, 0, (2 * (cx + 0.5)) / w - 1, 0],
                         [0, -2 * fy / h, 1 - (2 * (cy + 0.5)) / h, 0],
                         [0, 0, (far + near) / (far - near), -2 * far * near / (far - near)],
                         [0, 0, 1, 0]])
        return proj @ camera.world2camera

    # -- one image --------------------------------------------------------------------------------------------
    def render(self, camera, vertices, corners, rng, *, occluders=None) -> RenderedImage:
        """One image of the hand and its patches from ``camera``.

        Parameters
        ----------
        camera : Camera
        vertices : ndarray (V, 3)
            The hand mesh, metres.
        corners : sequence of ndarray
            For each patch of the atlas, its points ``(n_rows, n_cols, 3)`` at the grid coordinates of
            ``coords``, metres (:meth:`handcap.synth.decals.PatchSkin.grids`).
        rng : numpy.random.Generator
            Draws the image's look.
        occluders : sequence of (ndarray (V, 3), ndarray (F, 3)), optional
            Meshes that hide what lies behind them, metres (shared by the cameras of a take). Default:
            the style's number of random blobs between this camera and the hand.

        Returns
        -------
        RenderedImage
            Corner truth in the order of the patches' :meth:`~handcap.patterns.pattern.Patch.vertices`.
        """
        style = self.style
        matrix, size, map_x, map_y = self._render_camera(camera)
        vertices = np.asarray(vertices, dtype=np.float64)
        eye = camera.center

        meshes = [(vertices, self.faces, None, float(rng.uniform(0.45, 0.7)))]
        points, corner_normals = [], []
        for k, grid in enumerate(corners):
            grid = np.asarray(grid, dtype=np.float64)
            meshes.append((grid.reshape(-1, 3), _drawable(grid.reshape(-1, 3), self._patch_faces[k]),
                           self._patch_uv[k], None))
            ri, ci = self._corner_nodes[k]
            points.append(grid[ri, ci])
            # Seen from outside, columns run right and rows down: the outward normal is row x column.
            dr = grid[np.minimum(ri + 1, grid.shape[0] - 1), ci] - grid[np.maximum(ri - 1, 0), ci]
            dc = grid[ri, np.minimum(ci + 1, grid.shape[1] - 1)] - grid[ri, np.maximum(ci - 1, 0)]
            corner_normals.append(np.cross(dr, dc))
        if occluders is None:
            towards = eye - vertices.mean(axis=0)
            occluders = random_blobs(vertices, rng, int(rng.integers(style.occluders[0], style.occluders[1] + 1)),
                                     towards / np.linalg.norm(towards))
        for occ_vertices, occ_faces in occluders:
            meshes.append((np.asarray(occ_vertices, np.float64), np.asarray(occ_faces, np.int32), None,
                           float(rng.uniform(0.15, 0.8))))

        every = np.concatenate([m[0] for m in meshes])
        depths = (every @ camera.rotation_matrix.T + camera.translation)[:, 2]
        near = max(0.01, 0.5 * depths.min())
        far = 2.0 * depths.max() + 1.0
        mvp = self._mvp(camera, matrix, size, near, far)
        fbo, depth_fbo, resolved = self._framebuffers(size)
        prog = self.program
        prog["mvp"].write(mvp.T.astype("f4").tobytes())
        prog["eye"].value = tuple(eye)
        lights = rng.normal(size=(2, 3))
        lights[:, :] += (eye - vertices.mean(axis=0)) / np.linalg.norm(eye - vertices.mean(axis=0)) * 1.5
        prog["light_dir"].write(lights.astype("f4").tobytes())
        prog["light_power"].write(np.array(rng.uniform(0.35, 0.75, 2), "f4").tobytes())
        prog["ambient"].value = float(rng.uniform(0.15, 0.35))
        prog["shininess"].value = float(rng.uniform(8, 60))
        prog["specular"].value = float(rng.uniform(*style.specular))
        self.texture.use(0)
        prog["atlas"].value = 0
        arrays, depth_arrays = [], []
        for verts, faces, uv, albedo in meshes:
            normals = _vertex_normals(verts, faces)
            uv = np.zeros((len(verts), 2)) if uv is None else uv
            data = np.c_[verts, normals, uv].astype("f4")
            vbo = self.ctx.buffer(data.tobytes())
            ibo = self.ctx.buffer(np.asarray(faces, "i4").tobytes())
            vao = self.ctx.vertex_array(prog, [(vbo, "3f 3f 2f", "in_pos", "in_normal", "in_uv")], ibo)
            arrays.append((vao, vbo, ibo, uv is not None and albedo is None, albedo))
            depth_arrays.append(self.ctx.vertex_array(self.depth_program, [(vbo, "3f 20x", "in_pos")], ibo))
        self.ctx.enable(self.ctx.DEPTH_TEST)
        fbo.use()
        fbo.clear(0.0, 0.0, 0.0, 1.0, depth=1.0)
        for vao, _, _, textured, albedo in arrays:
            prog["textured"].value = int(textured)
            prog["albedo"].value = 0.0 if albedo is None else albedo
            prog["grain"].value = 0.15 if textured else 0.3
            prog["grain_scale"].value = 0.0015 if textured else 0.004
            vao.render()
        # The depth of the truth's visibility test: the same vertex shader, so the same depths, but a fragment
        # shader that shades nothing.
        self.depth_program["mvp"].write(mvp.T.astype("f4").tobytes())
        depth_fbo.use()
        depth_fbo.clear(depth=1.0)
        for vao in depth_arrays:
            vao.render()
        self.ctx.copy_framebuffer(resolved, fbo)
        w, h = size
        render = np.frombuffer(resolved.read(components=1, dtype="f4"), "f4").reshape(h, w)[::-1].copy()
        depth = np.frombuffer(depth_fbo.read(components=1, attachment=-1, dtype="f4"), "f4").reshape(h, w)[::-1]
        for vao, vbo, ibo, _, _ in arrays:
            vao.release()
            vbo.release()
            ibo.release()
        for vao in depth_arrays:
            vao.release()

        # Background where nothing was drawn: a smooth random field.
        empty = depth >= 1.0
        field = cv2.resize(rng.uniform(0, 1, (6, 8)).astype("f4"), (w, h), interpolation=cv2.INTER_CUBIC)
        level = rng.uniform(*style.background)
        render[empty] = np.clip(level * (0.6 + 0.8 * field[empty]), 0, 1)

        # Truth: every corner's pixel in the distorted image, and whether it is seen.
        points = np.concatenate(points) if points else np.zeros((0, 3))
        xy, _ = camera.project(points)
        cam = points @ camera.rotation_matrix.T + camera.translation
        zc = cam[:, 2]
        u = matrix[0, 0] * cam[:, 0] / zc + matrix[0, 2]
        v = matrix[1, 1] * cam[:, 1] / zc + matrix[1, 2]
        ui, vi = np.clip(np.round(u).astype(int), 0, w - 1), np.clip(np.round(v).astype(int), 0, h - 1)
        # The nearest surface over the corner's 3 x 3 pixels: a corner at an occluding edge is not seen.
        nearest = cv2.erode(depth, np.ones((3, 3), np.uint8))
        z_ndc = 2.0 * nearest[vi, ui] - 1.0
        z_seen = 2.0 * far * near / ((far + near) - z_ndc * (far - near))
        normals = np.concatenate(corner_normals) if corner_normals else np.zeros((0, 3))
        normals /= np.maximum(np.linalg.norm(normals, axis=1, keepdims=True), 1e-12)
        cosine = np.einsum("ij,ij->i", normals, eye - points) / np.linalg.norm(eye - points, axis=1)
        facing = cosine > np.cos(MAX_VIEW_ANGLE)
        # The corner's own slanted patch spans this much depth over one pixel around it.
        slope = np.sqrt(np.clip(1 - cosine ** 2, 0, 1)) / np.maximum(cosine, 0.1)
        tolerance = 0.0015 + 1.5 * zc / matrix[0, 0] * slope
        wsz, hsz = camera.size
        inside = (xy[:, 0] >= 0) & (xy[:, 0] <= wsz - 1) & (xy[:, 1] >= 0) & (xy[:, 1] <= hsz - 1) & (zc > 0)
        visible = inside & facing & (zc <= z_seen + tolerance)

        image = cv2.remap(render, map_x, map_y, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
        image = camera_effects(image, self.style, rng)
        return RenderedImage(image, xy, visible)

    def corner_points(self, corners) -> np.ndarray:
        """The printed corners among the patch points given to :meth:`render`, in its truth order.

        Parameters
        ----------
        corners : sequence of ndarray (n_rows, n_cols, 3)

        Returns
        -------
        ndarray (N, 3)
            Metres.
        """
        out = [np.asarray(g)[ri, ci] for g, (ri, ci) in zip(corners, self._corner_nodes)]
        return np.concatenate(out) if out else np.zeros((0, 3))


def camera_effects(image: np.ndarray, style: ImageStyle, rng) -> np.ndarray:
    """What a camera does to a clean picture: defocus and motion blur, exposure, gamma, noise, its response, 8 bits.

    Parameters
    ----------
    image : ndarray (H, W) float32
        Linear grey levels 0..1.
    style : ImageStyle
        Ranges each effect's strength is drawn from.
    rng : numpy.random.Generator

    Returns
    -------
    ndarray (H, W) uint8
    """
    sigma = rng.uniform(*style.blur_sigma)
    if sigma > 0.05:
        image = cv2.GaussianBlur(image, (0, 0), sigma)
    length = rng.uniform(*style.motion_px)
    if length > 0.5:
        size = int(np.ceil(length)) | 1
        kernel = np.zeros((size, size), np.float32)
        kernel[size // 2, :] = 1.0
        turn = cv2.getRotationMatrix2D((size / 2 - 0.5, size / 2 - 0.5), rng.uniform(0, 180), 1.0)
        kernel = cv2.warpAffine(kernel, turn, (size, size))
        image = cv2.filter2D(image, -1, kernel / kernel.sum())
    image = np.clip(image * rng.uniform(*style.gain), 0, 1) ** rng.uniform(*style.gamma)
    level = image * 255.0
    noise = rng.normal(0, 1, image.shape) * np.sqrt(style.shot_noise ** 2 * level
                                                    + rng.uniform(*style.read_noise) ** 2)
    level = np.clip(level + noise, 0, 255)
    if style.response == "srgb":
        level = 255.0 * srgb_encoded(level / 255.0)
    return np.clip(np.round(level), 0, 255).astype(np.uint8)

