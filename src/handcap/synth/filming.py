"""Film a synthetic capture: camera images of its patched hand, with the truth of every printed corner and tag.

``handcap synth --images`` calls :func:`film_capture` after writing the
capture: every camera of the rig films every frame (:mod:`handcap.synth.images`).
The hand wears the patches of the session template (``pattern.toml``, written
beside the images) at the places the layout gives; a held cuboid, cylinder or
sphere wears the template's patches of its faces (:mod:`handcap.synth.object_patches`),
the 2x2x2 cube the patches of its 24 facelets, each turning with its cubie as the
hand turns the layers. A few random blobs per frame hide parts of the hand from
every camera alike.

Files, in the capture folder:

- ``images/CAMERA/FFFFFF.png``: 8-bit grayscale frames.
- ``pattern.toml``: the template (tags and corner ids) of the patches drawn.
- ``image_cameras.toml``: where the images are smaller than the rig's cameras (``scale`` under 1), the rig
  that filmed them (``cameras.toml`` with each camera scaled, :func:`scaled_camera`): give it to
  ``handcap detect --rig`` and ``triangulate --cameras`` with these images.
- ``image_truth.npz``: the 2D detections File contract for what a perfect
  detector would report, plus the rest of the truth: ``camera_names (C,)``,
  ``marker_names (N,)`` (``right:PATCH_rRcC``, then the object's ``cylinder:FACE_rRcC``), ``frame``, ``camera``,
  ``marker``, ``xy`` (pixels, distorted image), ``score`` (ones) for every
  visible corner; ``block_text (B,)``, ``block_frame``, ``block_camera``,
  ``block_xy (B, 4, 2)`` (reading order, underline at the bottom) for every tag
  whose four corners are visible; ``positions (T, N, 3)`` metres,
  ``all_xy (T, C, N, 2)``, ``visible (T, C, N)``, ``rate``, ``image_size (C, 2)``.

Cameras not triggered together (:class:`Clocks`): camera c films the capture's frames ``starts[c] + every * k`` as
its frames k, at ``rate / every``. Each camera's ``all_xy`` and ``visible`` are then at its own moments,
``positions`` at the first camera's, and ``camera_offsets (C,)`` gives each camera's offset in frames as
:class:`handcap.multiview.sync.Sync` counts it (``(starts[c] - starts[0]) / every``).

The printed corners follow the skin of the template layout's nominal spots
(the capture's ``--placement-mm`` moves single markers; a printed patch is one
piece of tape), so ``image_truth.npz`` and not ``truth.npz`` holds their truth.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path

import cv2
import numpy as np
from scipy.spatial.transform import Rotation
from tqdm import tqdm

from handcap.core.camera_rig import CameraRig
from handcap.core.cameras import Camera
from handcap.core.errors import HandcapError
from handcap.core.transforms import homogeneous
from handcap.core.files import atomic_output, save_npz
from handcap.patterns.glyphs import load_font
from handcap.patterns.session import session_pattern
from handcap.hand import OpenHand
from handcap.io.npz import write_hand_motion
from handcap.layouts import load_layout
from handcap.synth.decals import patch_skin
from handcap.synth.images import ImageStyle, PatchRenderer
from handcap.synth.cube import cubie_boxes
from handcap.synth.object_patches import PATCHED, cube_patch_grids, object_patch_grids, patch_coords
from handcap.synth.objects import make_object, random_blobs
from handcap.synth.scene import synthesize
from handcap.synth.textures import build_atlas


def scaled_camera(camera: Camera, scale: float) -> Camera:
    """The same camera with an image ``scale`` times as wide (a binned or smaller sensor).

    Parameters
    ----------
    camera : Camera
    scale : float
        0 < scale <= 1 usually.

    Returns
    -------
    Camera
        Pixel centres stay at integers: ``c' = scale (c + 0.5) - 0.5``.
    """
    matrix = camera.matrix.copy()
    matrix[0, 0] *= scale
    matrix[1, 1] *= scale
    matrix[0, 1] *= scale
    matrix[0, 2] = scale * (matrix[0, 2] + 0.5) - 0.5
    matrix[1, 2] = scale * (matrix[1, 2] + 0.5) - 0.5
    size = (max(1, int(round(camera.size[0] * scale))), max(1, int(round(camera.size[1] * scale))))
    return Camera(camera.name, size, matrix, camera.distortions, camera.rotation, camera.translation)


def region_rig(rig, points, margin: int = 64):
    """The rig's cameras reading out only the part of their sensor that sees ``points`` (a region of interest).

    Machine-vision cameras can read out a window of their sensor; the same lens with a shifted
    principal point and fewer pixels sees the hand exactly as the full frame does, for a fraction
    of the rendering and detection time.

    Parameters
    ----------
    rig : CameraRig
    points : ndarray (N, 3)
        Metres; every camera's window holds their projections plus ``margin``.
    margin : int
        Pixels on every side.

    Returns
    -------
    CameraRig
        Same names, poses, lenses and distortions; window corners on even pixels.
    """
    cut = []
    for camera in rig:
        xy, _ = camera.project(np.asarray(points, dtype=np.float64).reshape(-1, 3))
        lo = np.clip(np.floor(np.nanmin(xy, axis=0)) - margin, 0, None).astype(int) // 2 * 2
        hi = np.minimum(np.ceil(np.nanmax(xy, axis=0)) + margin, camera.size).astype(int)
        size = np.maximum(hi - lo, 64) // 2 * 2
        matrix = camera.matrix.copy()
        matrix[:2, 2] -= lo
        cut.append(Camera(camera.name, (int(size[0]), int(size[1])), matrix, camera.distortions, camera.rotation,
                          camera.translation))
    return CameraRig(cut)


def check_filmable(config, scale: float = 1.0):
    """The capture's layout, if its hand can be filmed at ``scale``; else one clear error.

    Parameters
    ----------
    config : SynthConfig
    scale : float
        Image size relative to the rig's cameras.

    Returns
    -------
    MarkerLayout

    Raises
    ------
    HandcapError
        A layout that is not made of printed patches, or a scale out of 0.05 .. 1.
    """
    layout = load_layout(config.layout, side=config.side)
    if layout.marker_kind != "patch":
        raise HandcapError(f"--images films printed patches; layout {layout.name!r} has {layout.marker_kind} "
                           "markers: use --layout dense-patches")
    if not 0.05 <= scale <= 1.0:
        raise HandcapError(f"--image-scale {scale}: give a factor from 0.05 to 1")
    return layout


def film_capture(capture, folder, *, scale: float = 1.0, style: ImageStyle | None = None,
                 progress: bool | None = None, clocks: Clocks | None = None) -> dict:
    """Render every frame of ``capture`` from every camera into ``folder`` (see the module docstring).

    Parameters
    ----------
    capture : SynthCapture
        A capture made with a patch layout (``dense-patches`` or a layout of its kind).
    folder : str or Path
        The capture's folder.
    scale : float
        Image size relative to the rig's cameras (0.05 to 1).
    style : ImageStyle, optional
        The look of the images (default :class:`~handcap.synth.images.ImageStyle`).
    progress : bool, optional
        Show a progress bar (default: only on a terminal).
    clocks : Clocks, optional
        Cameras not triggered together (see the module docstring); default: every camera films every frame.

    Returns
    -------
    dict
        ``images`` (number written), ``visible`` (corner observations), ``blocks`` (tag observations) and
        ``paths`` (the files written, by name; ``image_cameras.toml`` among them where ``scale`` is under 1).

    Raises
    ------
    HandcapError
        A layout that is not made of printed patches, a scale out of range, or clocks that do not fit the capture.
    """
    config = capture.config
    layout = check_filmable(config, scale)
    clocks = clocks or Clocks((0,) * len(capture.rig.cameras))
    if (len(clocks.starts) != len(capture.rig.cameras) or min(clocks.starts) < 0 or clocks.every < 1
            or clocks.frames(config.frames) < 1):
        raise HandcapError(f"clocks {clocks} do not fit a capture of {len(capture.rig.cameras)} cameras and "
                           f"{config.frames} frames")
    folder = Path(folder)
    obj = None
    if capture.object_motion is not None:
        obj = make_object(capture.object_motion.name, seed=config.seed)
    # The 2x2x2 cube: each cubie's rotation in the cube's frame (T, 8, 3, 3), turning where the hand turns its
    # layers (turn-cube), else held whole (rotate-cube).
    cubies = None
    if obj is not None and obj.kind == "cube2x2":
        cubies = capture.truth.get("cube_cubie_rotation",
                                   np.tile(np.eye(3), (len(capture.object_motion.rotation), 8, 1, 1)))
    patched = obj is not None and (obj.kind in PATCHED or cubies is not None)
    pattern = session_pattern((config.side,), (obj.name,) if patched else ())
    wanted = {m.patch for m in layout.markers if m.patch}
    patches = tuple(p for p in pattern.patches if p.owner == config.side and p.name in wanted)
    if not patches:
        raise HandcapError(f"layout {layout.name!r} names none of the patches of handcap pattern")
    held = tuple(p for p in pattern.patches if obj is not None and p.owner == obj.name)
    held_coords = [patch_coords(p) for p in held]
    if cubies is not None:
        held_grids, on_cubie = cube_patch_grids(held, pattern.pitch, held_coords)
    else:
        held_grids = object_patch_grids(obj, held, pattern.pitch, held_coords) if held else []
    hand = OpenHand(config.side)
    motion = capture.hand_motion
    vertices = hand.forward(motion.betas, motion.global_orient, motion.hand_pose, motion.transl).vertices
    skin = patch_skin(layout, patches, hand, motion.betas, pitch=pattern.pitch)  # printed: the same size on any hand
    grids = skin.grids(vertices, hand.faces)  # per patch (T, rows, cols, 3)
    style = style or ImageStyle()
    renderer = PatchRenderer(build_atlas(patches + held, load_font(None, pattern.alphabet)), hand.faces, style,
                             coords=list(zip(skin.rows, skin.cols)) + held_coords)
    cameras = [scaled_camera(c, scale) for c in capture.rig]
    rng = np.random.default_rng(np.random.SeedSequence([config.seed, 16]))
    n_frames, n_cams = clocks.frames(len(vertices)), len(cameras)
    names = [name for p in patches + held for name in p.corner_names()]
    all_xy = np.zeros((n_frames, n_cams, len(names), 2))
    visible = np.zeros((n_frames, n_cams, len(names)), bool)
    positions = np.zeros((n_frames, len(names), 3))
    paths = {}
    hidden = None if progress is None else not progress
    try:
        with tqdm(total=n_frames * n_cams, desc="images", unit="image", disable=hidden, leave=False) as bar:
            for t in range(len(vertices)):
                filming = [c for c, start in enumerate(clocks.starts)
                           if (t - start) % clocks.every == 0 and 0 <= (t - start) // clocks.every < n_frames]
                if not filming:
                    continue
                frame_grids = [g[t] for g in grids]
                occluders = random_blobs(vertices[t], rng, int(rng.integers(style.occluders[0],
                                                                            style.occluders[1] + 1)))
                if obj is not None:
                    turn = Rotation.from_rotvec(capture.object_motion.rotation[t]).as_matrix()
                    where = capture.object_motion.translation[t]
                    if cubies is not None:  # the cubies turn with the cube's layers, and their patches with them
                        occluders.append(cubie_boxes(cubies[t], homogeneous(turn, where)))
                        frame_grids += [g @ (turn @ cubies[t, q]).T + where for g, q in zip(held_grids, on_cubie)]
                    else:
                        occluders.append((obj.vertices @ turn.T + where, obj.faces))
                        frame_grids += [g @ turn.T + where for g in held_grids]
                for c in filming:
                    camera, k = cameras[c], (t - clocks.starts[c]) // clocks.every
                    shot = renderer.render(camera, vertices[t], frame_grids, rng, occluders=occluders)
                    all_xy[k, c], visible[k, c] = shot.xy, shot.visible
                    path = folder / "images" / camera.name / f"{k:06d}.png"
                    path.parent.mkdir(parents=True, exist_ok=True)
                    ok, encoded = cv2.imencode(".png", shot.image)
                    with atomic_output(path) as fh:
                        fh.write(encoded.tobytes())
                    bar.update()
                if 0 in filming:
                    positions[(t - clocks.starts[0]) // clocks.every] = renderer.corner_points(frame_grids)
    finally:
        renderer.close()
    paths["pattern.toml"] = pattern.save(folder / "pattern.toml")
    if scale != 1.0:  # cameras.toml calibrates the full-size images, which these are not
        paths["image_cameras.toml"] = folder / "image_cameras.toml"
        CameraRig(cameras, capture.rig.warnings).save(paths["image_cameras.toml"])
    truth = _truth_arrays(patches + held, names, cameras, all_xy, visible, positions, config.rate / clocks.every)
    if clocks.every > 1 or any(clocks.starts):
        truth["camera_offsets"] = clocks.offsets()
    paths["image_truth.npz"] = folder / "image_truth.npz"
    save_npz(paths["image_truth.npz"], truth)
    return {"images": n_frames * n_cams, "visible": int(visible.sum()), "blocks": len(truth["block_text"]),
            "paths": paths}


@dataclass(frozen=True)
class Clocks:
    """Cameras not triggered together: camera c films the capture's frames ``starts[c] + every * k`` as its frame k.

    Attributes
    ----------
    starts : tuple of int, length C
        Each camera's first frame of the capture (0 or more).
    every : int
        Capture frames per camera frame (1 or more): the capture is synthesized at ``every`` times the cameras' rate.
    """

    starts: tuple
    every: int = 1

    def frames(self, n_frames: int) -> int:
        """Frames every camera films of a capture of ``n_frames``.

        Parameters
        ----------
        n_frames : int
            The capture's frames.
        """
        return (n_frames - 1 - max(self.starts)) // self.every + 1

    def offsets(self) -> np.ndarray:
        """Each camera's offset (C,), frames of its own: its frame k shows the first camera's ``k + offset``."""
        return (np.asarray(self.starts, float) - self.starts[0]) / self.every


def _truth_arrays(patches, names, cameras, all_xy, visible, positions, rate) -> dict:
    frame, camera, marker = np.nonzero(visible)
    index = {n: k for k, n in enumerate(names)}
    texts, corners = [], []
    for p in patches:
        for text, r, c in p.blocks():
            texts.append(text)
            corners.append([index[p.corner_name(vr, vc)] for vr, vc in p.block_vertices(r, c)])
    corners = np.array(corners, dtype=np.int64).reshape(-1, 4)
    seen = visible[:, :, corners].all(axis=-1)  # (T, C, B)
    b_frame, b_camera, b_index = np.nonzero(seen)
    return {
        "camera_names": np.array([c.name for c in cameras]), "marker_names": np.array(names),
        "frame": frame, "camera": camera, "marker": marker, "xy": all_xy[frame, camera, marker],
        "score": np.ones(len(frame)), "rate": np.array(float(rate)),
        "block_text": np.array(texts)[b_index] if len(b_index) else np.zeros(0, "<U2"),
        "block_frame": b_frame, "block_camera": b_camera,
        "block_xy": all_xy[b_frame[:, None], b_camera[:, None], corners[b_index]],
        "block_score": np.ones(len(b_index)),
        "positions": positions, "all_xy": all_xy, "visible": visible,
        "image_size": np.array([c.size for c in cameras]),
    }


def film_take(config, folder, *, progress: bool | None = None, style: ImageStyle | None = None,
              clocks: Clocks | None = None):
    """Synthesize a take of printed patches and film it into ``folder``, as a user's camera take would arrive.

    The cameras read out the window of their sensor that holds the hand (:func:`region_rig`). Writes
    ``cameras.toml`` (the rig), ``truth.npz`` (the true hand motion) and what :func:`film_capture` writes
    (``images/CAM/FRAME.png``, ``pattern.toml``, ``image_truth.npz``).

    Parameters
    ----------
    config : SynthConfig
        A patch layout (see :func:`check_filmable`).
    folder : str or Path
    progress : bool, optional
        Progress bars (default: on a terminal).
    style : ImageStyle, optional
        The look of the images (default :class:`~handcap.synth.images.ImageStyle`).
    clocks : Clocks, optional
        Cameras not triggered together (see the module docstring).

    Returns
    -------
    Capture
        The synthesized take, with the windowed rig.
    """
    check_filmable(config)
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    capture = synthesize(config, progress=progress)
    hand_points = capture.truth["positions"][:, :len(capture.hand_motion.marker_names)]
    capture = replace(capture, rig=region_rig(capture.rig, hand_points[np.isfinite(hand_points).all(axis=-1)]))
    capture.rig.save(folder / "cameras.toml")
    write_hand_motion(capture.hand_motion, folder / "truth.npz")
    film_capture(capture, folder, progress=progress, style=style, clocks=clocks)
    return capture
