"""Step ``detect``: camera images of coded patches to 2D detections (named corners and read blocks)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from handcap.core.errors import HandcapError
from handcap.core.files import check_output, save_npz, warnings_entry
from handcap.patterns.alphabet import lookalike_warning
from handcap.patterns.pattern import Pattern
from handcap.detect.noise import NOISE_LEARNED
from handcap.detect.sharpness import BLUR_LEARNED
from handcap.detect.response import NEAR, ResponseChoice, linear_light
from handcap.detect.motion import name_from_frames
from handcap.detect.views import name_from_views
from handcap.detect.sources import FrameSelection, frame_notes, frame_sources, select_frames, short_videos
from handcap.io import read_rig
from handcap.multiview.detections import detections_of
from handcap.multiview.sync import MAX_OFFSET_S, check_sync, estimate_sync, offsets_from_names, parse_offsets
from handcap.steps.step import Step

DEFAULT_RATE = 20.0  # DexterCap's cameras; said in a warning when assumed
#: Tags read in a first frame flipped left-right (or inverted) that call the images mirrored (inverted) when none read
#: as given.
MIRRORED_TAGS = 3
#: Share of the readings the reader trusts alone that the vote may drop or change before the template is said not to
#: fit the patches, and the least such readings to judge by. Measured (2026-11-28): 4-6 % on rendered hands and 2 %
#: on photographed sheets with their own template; 98 % with the tags shuffled over the same patches, 72 % with a
#: template of one hand of a sheet that holds the whole session.
DISOWNED_SHARE, MIN_SURE = 0.5, 10
#: Without a template, the least share of the squares the reader saw a tag in that it reports (sure enough to read
#: alone) before it says so. Measured (2026-11-29, 10 photographs each): 0.82-0.86 on handcap's own sheets in two
#: fonts, 0.14-0.39 on another generator's sheets (22 and 18 glyphs, its layout and handcap's), 0.25 on hands.
REPORTED_SHARE = 0.5
#: Share of the sure readings whose tag was read surely at another white square of the same image too, above
#: which the patches are said to be printed twice. Measured (2026-11-30): none of 247 on a rendered 4-camera hand
#: take, none of 361 on six photographed sheets; every tag of a patch seen twice.
TWICE_SHARE = 0.05


def detect(inputs, out, *, rig=None, pattern=None, alphabet: str | None = None, rate: float | None = None,
           corner_weights=None, reader_weights=None, refiner_weights=None, refine: bool = True,
           threshold: float | None = None, progress: bool | None = None, track: bool = True, checker_weights=None,
           checker: bool = True, adapt_steps: int = 0, denoise: bool = True, response: str = "auto",
           frames: slice | None = None, every: int = 1, views: bool = True, sync=None,
           max_offset_s: float = MAX_OFFSET_S, workers: int = 1, scheduler=None) -> Step:
    """Detect coded patches in images or videos and write the 2D detections ``.npz``.

    Parameters
    ----------
    inputs : sequence of str or Path
        One per camera: a folder of images, a video or an image file (its name is the camera's); a take's
        folder of videos or of folders of images gives a camera to each.
    out : str or Path
        The detections file (.npz).
    rig : str, Path or None
        Cameras file: every input must be one of its cameras; the file lists them in the rig's order.
    pattern : str, Path or None
        The session's ``pattern.toml``: tags are voted over it and corners named from it. Without it the file
        holds the read blocks only.
    alphabet : str, optional
        Glyphs of the printed tags (default: the template's, else handcap's).
    rate : float, optional
        Frames per second (default: a video's own, else 20 with a warning).
    corner_weights, reader_weights, refiner_weights, checker_weights : str, Path or None
        Networks (and the block checker) to use instead of the shipped ones.
    refine : bool
        Refine the corners to a fraction of a pixel (and turn away false ones) with the refiner network.
    threshold : float, optional
        Least corner probability: the refiner's (default 0.5), or the corner network's without it (0.3).
    progress : bool, optional
        Progress bar (default: on a terminal).
    track : bool
        Search each camera's frame around the patches its previous frame showed, and the whole frame every
        10th frame or where that search may have missed some (:mod:`handcap.detect.capture`); without,
        every frame whole.
    checker : bool
        Check the blocks the template's vote keeps with the learned checker (:mod:`handcap.detect.checker`);
        False, or no checker shipped, uses the hand-set checks (:mod:`handcap.detect.checks`).
    adapt_steps : int
        Without a template: steps of fine-tuning a copy of the reader on the take's sure readings, which then
        vouches for more readings (:mod:`handcap.detect.adapt`; :data:`handcap.detect.adapt.STEPS` is a good
        number); 0 (the default) reads with the shipped reader only.
    denoise : bool
        Take an image's sensor noise down first where it holds more than the networks learned
        (:mod:`handcap.detect.noise`); either way a warning says how many images did.
    response : {"auto", "linear", "srgb"}
        The cameras' response to light (:mod:`handcap.detect.response`): chosen for each camera on its first
        frames that read tags (the default), linear as recorded (a machine-vision camera), or display-encoded
        (sRGB: a phone, a webcam, most video), decoded to linear light before the search. A warning names the
        cameras read as sRGB.
    frames : slice, optional
        Read only the input frames ``frames.start`` to ``frames.stop`` (0-based, stop excluded).
    every : int
        Read every ``every``-th of them. The frames read are a take of their own: its frame ``k`` is input frame
        ``start + k * every``, at ``rate / every``; the file records ``first_frame`` and ``frame_step``.
    views : bool
        With a template: name the white squares a camera could not read where its neighbouring frames
        (:mod:`handcap.detect.motion`) and, with a rig, the other cameras (:mod:`handcap.detect.views`) place a
        square of the template, and (with the refiner) look again where the other cameras or the neighbouring
        frames place squares an image found none of (:mod:`handcap.detect.seek`); the file marks them in
        ``block_from_views``.
    sync : None, 'auto', str, sequence of str or dict
        Cameras not triggered together, for the naming from the other cameras (:mod:`handcap.multiview.sync`):
        ``'auto'`` finds each camera's offset from the corners the cameras named; ``CAM=FRAMES`` items (or a dict)
        give them (camera c's frame f shows the first camera's frame f + offset; cameras not named 0). None: the
        cameras are taken as synchronised. Needs ``rig`` and ``pattern``. The offsets used are stored in the file
        (``sync_cameras``, ``sync_offsets`` in frames, ``sync_drift``, ``sync_reference``), and ``triangulate``
        takes them.
    max_offset_s : float
        How far ``'auto'`` searches, seconds either way.
    workers : int
        Cameras detected at once, each in a local process of its own (:func:`handcap.detect.capture.detect_capture`;
        the same detections). 1 (the default): one camera after another, as fast on two cores (README).
    scheduler : None, str or distributed.Client
        A Dask scheduler to detect the cameras on instead (``tcp://HOST:PORT``); its workers need handcap and the
        inputs at the same paths.
    """
    out = Path(out)
    if isinstance(workers, bool) or not isinstance(workers, int) or workers < 1:
        raise HandcapError(f"--workers {workers}: give how many cameras to detect at once, 1 or more")
    if out.suffix.lower() != ".npz":
        raise HandcapError(f"{out}: detections are written as .npz; name it NAME.npz")
    sources = frame_sources(inputs)
    check_output(out, *[f for s in sources for f in (s.files or (s.path,))], rig, pattern)
    template = Pattern.load(pattern) if pattern is not None else None
    names = [s.camera for s in sources]
    if rig is not None:
        cameras = read_rig(rig)
        missing = [n for n in names if n not in cameras.names]
        if missing:
            raise HandcapError(f"{rig}: has no camera {missing[0]!r} (it has {', '.join(cameras.names)}); name each "
                               "input folder or video after its camera")
        names = [n for n in cameras.names if n in names]
        sources = sorted(sources, key=lambda s: names.index(s.camera))
    given = _given_sync(sync, names, rig, template, views, max_offset_s)
    pick = FrameSelection(0 if frames is None or frames.start is None else frames.start,
                          None if frames is None else frames.stop, every)
    if pick != FrameSelection():
        sources = select_frames(sources, pick)
    # The networks load torch (a second and a half): only when detecting, not with the command line.
    from handcap.detect.networks import (load_checker, load_corner_net, load_reader, load_refiner,
                                         shipped_notes)  # loads torch
    from handcap.detect.pipeline import Detector  # loads torch

    ResponseChoice(response)  # an unknown response is refused before the networks load
    if adapt_steps < 0:
        raise HandcapError(f"--adapt-steps {adapt_steps}: give 0 (the shipped reader only) or more steps")
    if adapt_steps and template is not None:
        raise HandcapError("--adapt-steps adapts the reader to a take read without --pattern; with the template the "
                           "vote over its patches corrects the readings")
    if threshold is not None and not 0.0 < threshold < 1.0:
        raise HandcapError(f"--threshold {threshold}: give a probability between 0 and 1")
    # The corner network's and the refiner's 8-bit twins where their weights carry activation ranges: the same
    # corners, faster.
    detector = Detector(load_corner_net(corner_weights, int8=True), load_reader(reader_weights), template, alphabet,
                        threshold, load_refiner(refiner_weights, int8=True) if refine else None,
                        checker=load_checker(checker_weights) if checker else None, denoise=denoise)
    warnings = frame_notes(sources) + lookalike_warning(detector.alphabet)
    if corner_weights is None or reader_weights is None or (refine and refiner_weights is None):
        # Issue 16: the shipped networks are short of the targets; say how good they measured, every time.
        warnings.append("the shipped detector networks are short of handcap's targets (corner recall >= 97 %, "
                        "median error <= 0.15 px); as measured on held-out rendered images: "
                        + "; ".join(shipped_notes()) + "; check the corner ids before relying on them")
    if template is None:
        warnings.append("no template (--pattern): blocks and their pixels only, no corner ids; triangulate needs ids")
    if rate is None:
        rates = [r for r in (s.fps() for s in sources) if r is not None]
        rate = rates[0] if rates else DEFAULT_RATE
        if not rates:
            warnings.append(f"frame rate not given (--rate): {DEFAULT_RATE:g} Hz assumed")
    elif not 0 < rate < 100000:
        raise HandcapError(f"--rate {rate}: give frames per second, more than 0")
    rate = rate / pick.every
    from handcap.detect.capture import detect_capture  # loads torch

    marker_names = template.corner_names() if template is not None else []
    sizes = None if rig is None else [cameras[s.camera].size for s in sources]
    parallel = {"workers": workers, "scheduler": scheduler}
    run = detect_capture(detector, sources, marker_names, rate, progress=progress, track=track, sizes=sizes,
                         response=response, **parallel)
    images, corrected = run.images, run.corrected
    decoded = [s.camera for s, r in zip(sources, run.responses) if r == "srgb"]
    if decoded:
        tags = np.sum([n for n, r in zip(run.looked, run.responses) if r == "srgb"], axis=0)
        near = abs(int(tags[1]) - int(tags[0])) <= NEAR * max(tags)
        chosen = (f"chosen on their first frames, which read {tags[1]} tags decoded against {tags[0]} as recorded"
                  + ("; about as many, so the printed ink's grey level against the paper's decided" if near else "")
                  if response == "auto" else "--response")
        warnings.append(f"{_listed(decoded)} read as display-encoded (sRGB, as phones, webcams and most video record "
                        f"light; {chosen}): decoded to linear light, as the detector's networks learned, before the "
                        "search" + ("; --response linear reads them as recorded" if response == "auto" else ""))
    warnings += short_videos(sources, run.frames)
    if run.noisy:
        warnings.append(f"{run.noisy} of {images} images hold more sensor noise than the detector's networks learned "
                        f"(up to {run.noise:.1f} grey levels, against {NOISE_LEARNED:g}): "
                        + ("they were denoised first (non-local means); " if denoise else "not denoised "
                           "(--no-denoise); ") + "fewer corners are found in them. More light, or less gain, helps")
    if sum(run.blurred):
        blurred = [s.camera for s, n in zip(sources, run.blurred) if n]  # not `cameras`: that is the rig
        warnings.append(f"{sum(run.blurred)} of {images} images ({_listed(blurred)}) show the printed edges blurred by "
                        f"up to {run.blur:.2f} px (sigma), more than the detector's networks learned (about "
                        f"{BLUR_LEARNED:g} px): fewer corners and tags are read in them. Focus the camera (or stop "
                        "the lens down), or shorten the exposure if it is motion blur")
    if run.twice >= MIN_SURE and run.twice > TWICE_SHARE * run.sure:
        warnings.append(f"{run.twice} of the {run.sure} tags the reader was sure of were read at another white square "
                        f"of the same image too ({run.twice_images} images): patches printed twice (two copies of a "
                        "page, or patches of two handcap pattern runs, whose tags collide: pattern --extend adds "
                        "patches with tags of their own)" + ("; the vote drops such tags" if template is not None
                                                             else "; both are reported"))
    if run.empty:
        warnings.append(f"no corner found in {run.empty} of {images} images (no patches in view, or not in focus)")
    if template is not None and run.sure >= MIN_SURE and run.disowned > DISOWNED_SHARE * run.sure:
        warnings.append(f"{run.disowned} of the {run.sure} tags the reader was sure of do not fit the template's "
                        f"patches where they were read: is {pattern} the pattern.toml these patches were printed "
                        "from? (tags of patches it lacks are dropped too; patches printed by two handcap pattern "
                        "runs share tags, which pattern --extend avoids)")
    elif images and not len(run.arrays["block_text"]):
        warnings.append(_nothing_read(detector, sources[0]))
    kept = len(run.arrays["block_text"])
    adapted = ""
    if adapt_steps and images and kept:
        from handcap.detect.adapt import MIN_READINGS, adapt_reader, take_views  # loads torch

        views = take_views(detector, _spread(sources, run.responses), progress=progress)
        if len(views.blocks) < MIN_READINGS:
            warnings.append(f"the reader was not adapted to this take: {len(views.blocks)} sure readings in "
                            f"{len(views.images)} images, and it needs {MIN_READINGS}")
        else:
            detector.adapted = adapt_reader(detector.reader, views, steps=adapt_steps, progress=progress)
            detector.confused = views.confused
            run = detect_capture(detector, sources, marker_names, rate, progress=progress, track=track, sizes=sizes,
                                 response=run.responses, **parallel)
            adapted = (f"; the reader adapted to this take ({len(views.blocks)} sure readings in {len(views.images)} "
                       f"images, {adapt_steps} steps) vouched for {len(run.arrays['block_text']) - kept} more"
                       + (f" (none with {views.confused}, glyphs it confuses here)" if views.confused else ""))
            warnings.append("tags vouched for by a reader adapted to this take (--adapt-steps) are a little more "
                            "often wrong than those the shipped reader reports alone (README: another generator's "
                            "sheets): check them")
            kept = len(run.arrays["block_text"])
    if template is None and run.read >= MIN_SURE and 0 < kept < REPORTED_SHARE * run.read:  # none read: said above
        warnings.append(f"the reader saw tags in {run.read} white squares and reports {kept} "
                        f"({100 * kept / run.read:.0f} %), those it is sure of without a template: patches in a font "
                        "or glyph layout unlike handcap's, small or blurred squares, or a wrong --alphabet; with the "
                        "patches' template (--pattern; another generator's, such as DexterCap's JSON, through "
                        "handcap pattern --import) the vote over them reads more"
                        + ("" if adapt_steps else "; so may a reader adapted to this take (--adapt-steps 200)"))
    found, by_views, clocks = run.arrays, "", {}  # clocks: the offsets found or given, for triangulate
    if views and template is not None and len(found["frame"]):
        naming = name_from_frames(found, run.unread, template, progress=progress)
        found, left, by_views, offsets = naming.arrays, naming.left, f"; {naming.summary()}", None
        if rig is not None:
            offsets, said = (None, []) if sync is None else _offsets(found, cameras, given, max_offset_s)
            if offsets is not None:
                by_views += f"; {offsets.summary()}"
                clocks = clock_arrays(offsets)
            naming = name_from_views(found, left, cameras, template, progress=progress, sync=offsets)
            found, warnings = naming.arrays, warnings + said + list(naming.warnings)
            by_views += f"; {naming.summary()}"
        if detector.refiner is not None:
            from handcap.detect.seek import searched_frames, second_look  # loads torch

            naming = second_look(found, template, detector.refiner, searched_frames(detector, sources, run.responses),
                                 rig=cameras if rig is not None else None, sync=offsets, progress=progress)
            found, by_views = naming.arrays, by_views + f"; {naming.summary()}"
    pitch = {} if template is None else {"pitch": np.array(float(template.pitch))}  # a ruler for triangulate
    picked = {} if pick == FrameSelection() else {"first_frame": np.array(pick.start),
                                                  "frame_step": np.array(pick.every)}
    arrays = {**found, **pitch, **picked, **clocks, **warnings_entry(warnings)}
    save_npz(out, arrays)
    line = (f"{out}: {images} images from {len(names)} camera(s): {len(arrays['frame'])} named corners, "
            f"{len(arrays['block_text'])} read tags" + (f" ({corrected} corrected by the vote)" if template else "")
            + (f"; {run.regions} images searched around the previous frame's patches only" if run.regions else "")
            + adapted + by_views)
    lines = (line,) if not picked else (line, f"input frames {pick.start}:{'' if pick.stop is None else pick.stop}"
                                              + (f" every {pick.every}" if pick.every > 1 else "") + f": frame k of "
                                              f"{out.name} is input frame {pick.start} + {pick.every} k, at "
                                              f"{rate:g} Hz")
    return Step(lines, tuple(warnings), (str(out),), arrays)


def clock_arrays(sync) -> dict:
    """The entries of a detections file that keep the cameras' offsets, for ``triangulate``.

    Parameters
    ----------
    sync : Sync
        :func:`~handcap.multiview.sync.estimate_sync`'s or :func:`~handcap.multiview.sync.check_sync`'s.

    Returns
    -------
    dict
        ``sync_cameras`` (C,) str, ``sync_offsets`` (C,) frames (NaN: none found), ``sync_drift`` (C,) frames per
        frame, ``sync_reference`` (the camera they count from).
    """
    offsets = np.asarray(sync.offsets, dtype=np.float64)
    drift = np.zeros(len(offsets)) if sync.drift is None else np.asarray(sync.drift, dtype=np.float64)
    return {"sync_cameras": np.array(sync.camera_names), "sync_offsets": offsets, "sync_drift": drift,
            "sync_reference": np.array(sync.reference)}


def _given_sync(sync, names: list, rig, template, views: bool, max_offset_s: float) -> dict | None:
    """The offsets ``sync`` gives by camera (None for 'auto' or none), checked before the detection."""
    if sync is None:
        return None
    if rig is None or template is None or not views:
        raise HandcapError("--sync times the other cameras' views for naming the squares a camera could not read: it "
                           "needs --rig and --pattern, and not --no-views (triangulate --sync synchronises the corners "
                           "named)")
    if sync == "auto":
        if not (np.isfinite(max_offset_s) and max_offset_s > 0):
            raise HandcapError(f"--max-offset {max_offset_s:g}: give how far --sync auto searches, seconds (more "
                               "than 0)")
        return None
    given = dict(sync) if isinstance(sync, dict) else parse_offsets(sync)
    unknown = [n for n in given if n not in names]
    if unknown:
        raise HandcapError(f"--sync: an offset for camera {unknown[0]!r}, which the inputs lack (they are "
                           f"{', '.join(names)})")
    return given


def _offsets(arrays: dict, rig, given: dict | None, max_offset_s: float):
    """Each camera's offset (a :class:`~handcap.multiview.sync.Sync`) from the named corners ('auto', ``given``
    None) or as given, and its warnings; None where the search placed no second camera."""
    detections = detections_of(arrays)
    if len(detections.camera_names) < 2:
        return None, []
    if given is None:
        found = estimate_sync(detections, rig, max_offset_s=max_offset_s)
        if np.isfinite(found.offsets).sum() < 2:
            return None, [f"--sync auto placed no camera beside {found.reference}, so no unread square was named "
                          "from the other cameras: " + "; ".join(found.warnings)]
    else:
        found = check_sync(detections, rig, offsets_from_names(detections, given))
    return found, list(found.warnings)


def _nothing_read(detector, source) -> str:
    """The warning where no tag was read in any image, and why, as the first frame of ``source`` tells.

    A front camera's selfie is mirrored, and patches printed white on black (or a negative) are inverted: no tag
    reads (checked: none read wrong), but flipped or inverted back they do.
    """
    _, first = next(source.frames())
    flipped = len(detector.image(np.ascontiguousarray(first[:, ::-1])).block_text)
    if flipped >= MIRRORED_TAGS:
        return (f"no tag was read in any image: the images look mirrored ({flipped} tags read in {source.camera}'s "
                "first frame flipped left-right: a front camera's selfie?); flip them before detecting")
    inverted = len(detector.image(255 - first).block_text)
    if inverted >= MIRRORED_TAGS:
        return (f"no tag was read in any image: the images look inverted ({inverted} tags read in {source.camera}'s "
                "first frame with black and white swapped: patches printed white on black, or a negative?); invert "
                "them before detecting")
    return ("no tag was read in any image: wrong --alphabet, patches too small in the images or printed in a font or "
            "glyph layout unlike handcap's, or not coded patches")


def _spread(sources, responses) -> list:
    """At most :data:`handcap.detect.adapt.MAX_IMAGES` of the sources' frames, evenly spread over them, each
    decoded to linear light where its camera's response is sRGB (``responses``, one per source)."""
    from handcap.detect.adapt import MAX_IMAGES  # loads torch

    every = max(1, -(-sum(s.count() for s in sources) // MAX_IMAGES))
    images, k = [], 0
    for source, response in zip(sources, responses):
        for _, image in source.frames():
            if k % every == 0 and len(images) < MAX_IMAGES:
                images.append(linear_light(image) if response == "srgb" else image)
            k += 1
    return images


def _listed(cameras) -> str:
    """Cameras named for a warning: all of up to three, else the first three and how many more."""
    head = ", ".join(cameras[:3]) + (f" and {len(cameras) - 3} more" if len(cameras) > 3 else "")
    return ("camera " if len(cameras) == 1 else "cameras ") + head
