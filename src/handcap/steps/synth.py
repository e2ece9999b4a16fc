"""Steps ``synth`` (a synthetic capture with its truth) and the image and markerless demos (the plain demo is a
session: :func:`handcap.demo.demo`)."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

from handcap.core.errors import HandcapError
from handcap.steps.markerless_demo import run_markerless_demo
from handcap.io import check_output_folder
from handcap.quality import plausibility as q
from handcap.steps.step import Step
from handcap.synth.filming import check_filmable, film_capture
from handcap.synth.images import ImageStyle
from handcap.synth.scene import SynthConfig, config_from_scene, synthesize, write_capture


def synth(out, config: SynthConfig | None = None, *, scene=None, force: bool = False, images: bool = False,
          image_scale: float = 1.0, image_style: str = "default", image_response: str = "linear") -> Step:
    """Make a synthetic capture and write it into the folder ``out`` (see :func:`handcap.synth.scene.synthesize`).

    Parameters
    ----------
    out : str or Path
        Output folder: new or empty, unless ``force``.
    config : SynthConfig or None
        The settings (default: those of ``scene``, else the defaults).
    scene : str, Path or None
        A scene.toml written by an earlier run: every setting is taken from it.
    force : bool
        Write into ``out`` even if it holds files (those of the same names are replaced).
    images : bool
        Also film the patched hand from every camera (:func:`handcap.synth.filming.film_capture`).
    image_scale : float
        Image size relative to the rig's cameras.
    image_style : {'default', 'clean'}
        The look: blur, noise, glints and occluders drawn per image, or none of them.
    image_response : {'linear', 'srgb'}
        The cameras' response: grey levels linear in the light (a machine-vision camera), or encoded as sRGB (a
        phone, a webcam, most video; :attr:`handcap.synth.images.ImageStyle.response`).
    """
    config = config_from_scene(scene) if scene else config or SynthConfig()
    check_output_folder(out, scene, force=force)
    if image_style not in ("default", "clean"):
        raise HandcapError(f"--image-style {image_style!r}: choose default or clean")
    if image_response not in ("linear", "srgb"):
        raise HandcapError(f"--image-response {image_response!r}: choose linear or srgb")
    if images:
        check_filmable(config, image_scale)
    capture = synthesize(config)
    warnings = q.marker_warnings(capture.markers, hand=capture.hand_motion.marker_names) + \
        q.motion_warnings(capture.hand_motion)
    # The warnings of the markers and of the true motion are stored on both (markers and truth files).
    capture = replace(capture, markers=q.attach(capture.markers, warnings),
                      hand_motion=capture.hand_motion.with_warnings(*warnings))
    write_capture(capture, out)
    m = capture.markers
    line = q.summary(f"{out}: {capture.summary()}", {**q.marker_figures(m, hand=capture.hand_motion.marker_names),
                                                      **q.motion_figures(capture.hand_motion)}, m.warnings)
    lines = [line]
    if images:
        style = replace(ImageStyle.clean() if image_style == "clean" else ImageStyle(), response=image_response)
        filmed = film_capture(capture, out, scale=image_scale, style=style)
        rig = ("rig image_cameras.toml (cameras.toml scaled to the images)" if "image_cameras.toml" in filmed["paths"]
               else "rig cameras.toml")
        lines.append(f"images: {filmed['images']} frames in {Path(out) / 'images'}, {filmed['visible']} visible "
                     f"corners and {filmed['blocks']} visible tags in image_truth.npz, template pattern.toml, {rig}")
    return Step(tuple(lines), m.warnings, (str(out),), capture)


def demo_markerless(out="demo-markerless") -> Step:
    """Run :func:`handcap.steps.markerless_demo.run_markerless_demo` into ``out`` (rewritten on every run)."""
    check_output_folder(out, force=True)  # the demo's folder is rewritten on every run
    return _figures_step(run_markerless_demo(out), out)


def demo_images(out="demo-images") -> Step:
    """Run :func:`handcap.demo_images.run_image_demo` into ``out`` (rewritten on every run) and summarise it."""
    from handcap.demo_images import run_image_demo  # loads torch (the detector's networks)

    check_output_folder(out, force=True)  # the demo's folder is rewritten on every run
    return _figures_step(run_image_demo(out), out)


def _figures_step(summary: dict, out) -> Step:
    """A demo's summary (figures, ``warnings``, ``files``) as the lines the command prints."""
    warnings = tuple(summary["warnings"])
    lines = [f"{key:40s} {value}" for key, value in summary.items() if key not in ("files", "warnings")]
    lines.append(f"\nwrote {len(summary['files'])} files to {out}/ (figures in {out}/summary.txt); "
                 + (f"{len(warnings)} warning(s), see below" if warnings else "no warnings"))
    return Step(tuple(lines), warnings, tuple(summary["files"]), summary)
