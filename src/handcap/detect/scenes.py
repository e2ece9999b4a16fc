"""Training and test images of patched hands: random poses, cameras and looks, rendered with exact truth.

Each scene is one image: the template hand in a random pose (angles drawn
within the joint limits, a random shape and orientation) seen by a random
camera of the synthetic cage (:func:`handcap.synth.cameras.cage_rig`) at a
random sensor scale, with a random look (:class:`handcap.synth.images.ImageStyle`).
The camera is cut down to the hand's part of its image (a shifted principal
point: the same lens, fewer pixels to render), so a scene costs a fraction of a
full frame. The truth is every visible corner and every tag whose four corners
are visible.
"""

from __future__ import annotations

import numpy as np

from handcap.core.cameras import Camera
from handcap.core.errors import HandcapError
from handcap.detect.scenefile import Scene
from handcap.patterns.glyphs import GlyphLayout, load_font
from handcap.patterns.session import session_pattern
from handcap.hand import OpenHand
from handcap.hand.anatomy import PHI_LIMITS
from handcap.layouts import load_layout
from handcap.synth.cameras import cage_rig
from handcap.synth.decals import patch_skin
from handcap.synth.filming import scaled_camera
from handcap.synth.images import ImageStyle, PatchRenderer
from handcap.synth.pages import PageLook, PagePhotographer
from handcap.synth.textures import PatchAtlas, build_atlas
from handcap.patterns.pattern import Patch, Pattern


class SceneMaker:
    """Draws random scenes (see the module docstring).

    Parameters
    ----------
    seed : int
    scale : (float, float)
        Range of the sensor size relative to the cage's 2448 x 2048 cameras.
    style : ImageStyle, optional
    font : str or Path, optional
        Font of the glyphs (default: DejaVu Sans Mono Bold).
    alphabet : str, optional
        Glyphs of the tags (default: handcap's).
    layout : GlyphLayout, optional
        Where the glyphs sit in a square (default: handcap's).
    """

    def __init__(self, seed: int = 0, *, scale=(0.5, 1.0), style: ImageStyle | None = None, font=None,
                 alphabet: str | None = None, layout: GlyphLayout | None = None):
        self.rng = np.random.default_rng(seed)
        self.scale = scale
        self.hand = OpenHand("right")
        kwargs = {} if alphabet is None else {"alphabet": alphabet}
        pattern = session_pattern(("right",), (), **kwargs)
        self.patches, self.pitch = pattern.patches, pattern.pitch  # printed: the same size on every hand
        self.alphabet = pattern.alphabet
        self.skin_layout = load_layout("dense-patches")
        self.names, self.blocks_index, self.block_text = _block_truth(self.patches)
        glyphs = load_font(font, pattern.alphabet)
        self._skins = {}
        first = self._skin(tuple([0.0] * 10))  # the sample grid is the same for every shape
        self.renderer = PatchRenderer(build_atlas(self.patches, glyphs, layout=layout), self.hand.faces,
                                      style or ImageStyle(), coords=list(zip(first.rows, first.cols)))

    def close(self) -> None:
        """Free the renderer."""
        self.renderer.close()

    def _skin(self, betas_key):
        if betas_key not in self._skins:
            self._skins[betas_key] = patch_skin(self.skin_layout, self.patches, self.hand, np.array(betas_key),
                                                pitch=self.pitch)
        return self._skins[betas_key]

    def scene(self) -> Scene:
        """Draw and render one scene.

        Returns
        -------
        Scene
        """
        rng = self.rng
        # Up to 8 subjects, each made once (attaching the patches to a new shape is the slow part).
        betas = tuple(np.round(rng.normal(0, 0.7, 10), 1).tolist()) if len(self._skins) < 9 else \
            list(self._skins)[rng.integers(len(self._skins))]
        skin = self._skin(betas)
        lo, hi = PHI_LIMITS[:, 0], PHI_LIMITS[:, 1]
        phi = (lo + rng.uniform(0.1, 0.9, len(lo)) * (hi - lo))[None]
        orient = rng.normal(size=3)
        orient *= rng.uniform(0, np.pi) / np.linalg.norm(orient)
        transl = np.array([0.0, 0.0, 1.0]) + rng.normal(0, 0.08, 3)
        out = self.hand.forward(np.array(betas), orient[None], self.hand.hand_pose_from_phi(phi), transl[None])
        vertices = out.vertices[0]
        grids = skin.grids(vertices, self.hand.faces)
        rig = cage_rig(12, target=(0.0, 0.0, 1.0), seed=int(rng.integers(1 << 30)))
        camera = _cut_to(rig[int(rng.integers(len(rig)))], vertices, rng.uniform(*self.scale), rng)
        shot = self.renderer.render(camera, vertices, grids, rng)
        seen = shot.visible
        blocks = seen[self.blocks_index].all(axis=1)
        return Scene(shot.image, shot.xy[seen], self.names[seen], shot.xy[self.blocks_index[blocks]],
                     self.block_text[blocks], self.alphabet, dict(zip(self.names, shot.xy)))


class PageMaker:
    """Draws random photographs of a printed sheet of a session's patches, as scenes.

    Parameters
    ----------
    seed : int
    look : PageLook, optional
    style : ImageStyle, optional
    font : str or Path, optional
        Font of the glyphs (default: DejaVu Sans Mono Bold).
    alphabet : str, optional
        Glyphs of the tags (default: handcap's). The sheet holds a whole session's patches, or one
        hand's where the alphabet has too few tags for a session.
    layout : GlyphLayout, optional
        Where the glyphs sit in a square (default: handcap's).
    pattern : Pattern, optional
        The patches the sheet holds instead (``alphabet`` is then its own).
    """

    def __init__(self, seed: int = 0, *, look: PageLook | None = None, style: ImageStyle | None = None,
                 font=None, alphabet: str | None = None, layout: GlyphLayout | None = None,
                 pattern: Pattern | None = None):
        self.rng = np.random.default_rng(seed)
        kwargs = {} if alphabet is None else {"alphabet": alphabet}
        if pattern is None:
            try:
                pattern = session_pattern(**kwargs)
            except HandcapError:  # too few tags for a whole session
                pattern = session_pattern(("right",), (), **kwargs)
        self.alphabet = pattern.alphabet
        self.names, self.blocks_index, self.block_text = _block_truth(pattern.patches)
        atlas = build_atlas(pattern.patches, load_font(font, pattern.alphabet), square=48, layout=layout)
        self.photographer = PagePhotographer(atlas, look, style)

    def close(self) -> None:
        """Nothing to free (the same interface as :class:`SceneMaker`)."""

    def scene(self) -> Scene:
        """Draw one photograph.

        Returns
        -------
        Scene
        """
        shot = self.photographer.photograph(self.rng)
        seen = shot.visible
        blocks = seen[self.blocks_index].all(axis=1)
        return Scene(shot.image, shot.xy[seen], self.names[seen], shot.xy[self.blocks_index[blocks]],
                     self.block_text[blocks], self.alphabet, dict(zip(self.names, shot.xy)))


class SheetMaker(PageMaker):
    """Photographs of a sheet as another generator prints it (DexterCap's does so): one checkerboard over the
    page, the tags counted along its rows, every fourth row of squares and a few columns plain (white squares
    with no glyphs, where the sheet is cut into strips), to be read without a template. Its scenes' blocks are the
    tagged squares only.

    Parameters
    ----------
    seed : int
    alphabet : str
        The tags are ``alphabet[n % L] + alphabet[n // L % L]`` for the n-th tagged square.
    font : str or Path, optional
    layout : GlyphLayout, optional
        Where the generator puts the glyphs and the underline (default: handcap's).
    look : PageLook, optional
    rows, cols : int
        Squares of the sheet.
    """

    def __init__(self, seed: int, alphabet: str, *, font=None, layout: GlyphLayout | None = None,
                 look: PageLook | None = None, rows: int = 16, cols: int = 20):
        self.rng, self.alphabet = np.random.default_rng(seed), alphabet
        n = len(alphabet)
        white = [(r, c) for r in range(rows) for c in range(cols) if (r + c) % 2]
        text = {rc: alphabet[k % n] + alphabet[k // n % n] for k, rc in enumerate(white)}
        patch = Patch("sheet", "sheet", "object:sheet",
                      tuple(tuple(text.get((r, c), "") for c in range(cols)) for r in range(rows)))
        atlas = build_atlas([patch], load_font(font, alphabet), square=48, layout=layout)
        image, (x0, y0), side = atlas.image.copy(), np.round(atlas.origins[0]).astype(int), atlas.square
        self.plain = {(r, c) for r, c in white if r % 4 == 0 or c in (0, cols // 2 - 1, cols - 2)}
        for r, c in self.plain:  # paper where the glyphs were
            image[y0 + r * side + 1:y0 + (r + 1) * side - 1, x0 + c * side + 1:x0 + (c + 1) * side - 1] = 255
        self.names, blocks, texts = _block_truth([patch])
        tagged = np.array([(r, c) not in self.plain for _, r, c in patch.blocks()])
        self.blocks_index, self.block_text = blocks[tagged], texts[tagged]
        self.photographer = PagePhotographer(PatchAtlas(image, atlas.patches, atlas.origins, side), look)
        self.pattern = Pattern((patch,), alphabet)  # to score tags read without a template
        self.rows, self.cols = rows, cols
        # PageMaker.scene and close work on these attributes; its own __init__ would build a session's sheet.

    def strips(self) -> tuple[dict, dict]:
        """The sheet cut into strips along its plain rows and columns, as that generator's template gives them.

        Returns
        -------
        grids : dict
            Strip name (``strip0``, ...) -> its rows, each a string of two-glyph cells, ``**`` for a black square
            (DexterCap's patch JSON; :func:`handcap.patterns.foreign.read_grids`).
        rename : dict
            The sheet's corner name -> ``OWNER:STRIP_rRcC`` of the same corner, for the corners the strips hold,
            where the strips belong to the owner ``sheet``.
        """
        tags = self.pattern.patches[0].tags
        plain_cols = sorted({c for r, c in self.plain if r % 4})
        row_spans = [(r0, min(r0 + 3, self.rows)) for r0 in range(1, self.rows, 4)]
        cuts = [-1] + plain_cols + [self.cols]
        col_spans = [(a + 1, b) for a, b in zip(cuts[:-1], cuts[1:]) if b > a + 1]
        grids, rename = {}, {}
        for r0, r1 in row_spans:
            for c0, c1 in col_spans:
                name = f"strip{len(grids)}"
                grids[name] = ["".join(tags[r][c] if (r, c) not in self.plain and tags[r][c] else "**"
                                       for c in range(c0, c1)) for r in range(r0, r1)]
                for r in range(r1 - r0 + 1):
                    for c in range(c1 - c0 + 1):
                        rename[f"sheet:sheet_r{r0 + r}c{c0 + c}"] = f"sheet:{name}_r{r}c{c}"
        return grids, rename


def renamed(scene: Scene, rename: dict) -> Scene:
    """``scene`` with its corners named as ``rename`` says, and without the corners it does not name.

    Parameters
    ----------
    scene : Scene
    rename : dict
        Old corner name -> new (:meth:`SheetMaker.strips`).

    Returns
    -------
    Scene
    """
    keep = np.array([str(n) in rename for n in scene.corner_names], bool)
    projected = None if scene.projected is None else {rename[n]: xy for n, xy in scene.projected.items()
                                                      if n in rename}
    return Scene(scene.image, scene.corners[keep], np.array([rename[str(n)] for n in scene.corner_names[keep]]),
                 scene.blocks, scene.block_text, scene.alphabet, projected)


def _block_truth(patches):
    """Corner names (N,), each block's four corner indices in reading order (B, 4) and its tag (B,)."""
    names = [n for p in patches for n in p.corner_names()]
    index = {n: k for k, n in enumerate(names)}
    ids, texts = [], []
    for p in patches:
        for text, r, c in p.blocks():
            ids.append([index[p.corner_name(*v)] for v in p.block_vertices(r, c)])
            texts.append(text)
    return np.array(names), np.array(ids).reshape(-1, 4), np.array(texts)


def _cut_to(camera: Camera, vertices: np.ndarray, scale: float, rng, margin: int = 48) -> Camera:
    """``camera`` at ``scale``, cut to the part of its image that shows ``vertices`` (plus a margin)."""
    full = scaled_camera(camera, scale)
    matrix, size = full.matrix, full.size
    xy, _ = full.project(vertices)
    lo = np.floor(np.clip(xy.min(axis=0) - margin - rng.uniform(0, margin, 2), 0, None)).astype(int)
    hi = np.ceil(np.minimum(xy.max(axis=0) + margin + rng.uniform(0, margin, 2), size)).astype(int)
    lo -= lo % 2
    width, height = max(64, hi[0] - lo[0]), max(64, hi[1] - lo[1])
    width += width % 2
    height += height % 2
    cut = matrix.copy()
    cut[0, 2] -= lo[0]
    cut[1, 2] -= lo[1]
    return Camera(camera.name, (int(width), int(height)), cut, camera.distortions, camera.rotation,
                  camera.translation)
