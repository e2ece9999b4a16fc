"""The ``handcap`` command. Every verb has ``--help``; user mistakes exit with code 2."""

from __future__ import annotations

import argparse
import sys

from handcap.core.errors import HandcapError


def _cmd_convert(args) -> tuple[str, ...]:
    from handcap.io import check_output, read_markers, write_markers
    from handcap.quality import plausibility as q
    check_output(args.output, args.input)
    markers = read_markers(args.input, partial=args.partial, units=args.units)
    markers = q.attach(markers, q.marker_warnings(markers))  # stored in the output (.npz, .c3d) as well
    write_markers(markers, args.output)
    print(q.summary(f"{args.output}: {markers.n_frames} frames, {markers.n_markers} markers at {markers.rate:g} Hz",
                    q.marker_figures(markers), markers.warnings))
    return markers.warnings


def _add_units(parser, what: str = "the input's coordinates") -> None:
    """``--units mm|cm|m``: the unit of a file that says the wrong one (see handcap.io._units)."""
    from handcap.io import UNITS
    parser.add_argument("--units", choices=UNITS, default=None,
                        help=f"unit of {what}, overriding what the file says (default: the file's; an implausible "
                             f"one is replaced by the only unit that fits, with a warning)")


def _cmd_synth(args) -> tuple[str, ...]:
    from handcap.synth.scene import SynthConfig, config_from_scene, synthesize, write_capture
    if args.scene:
        config = config_from_scene(args.scene)
    else:
        betas = None if args.betas is None else tuple(float(b) for b in args.betas.split(","))
        config = SynthConfig(layout=args.layout, motion=args.motion, frames=args.frames, rate=args.rate,
                             seed=args.seed, side=args.side, object=args.object, betas=betas, cameras=args.cameras,
                             min_views=args.min_views, noise_mm=args.noise_mm, pixel_noise=args.pixel_noise,
                             dropout=args.dropout, ghost_rate=args.ghost_rate, swap_rate=args.swap_rate,
                             outlier_rate=args.outlier_rate, max_view_angle_deg=args.max_view_angle,
                             placement_mm=args.placement_mm, subject_seed=args.subject_seed)
    from handcap.io import check_output_folder
    check_output_folder(args.out, args.scene, force=args.force)
    capture = synthesize(config)
    capture, warnings = _checked_capture(capture)
    write_capture(capture, args.out)
    m = capture.markers
    from handcap.quality import plausibility as q
    print(q.summary(f"{args.out}: {m.n_frames} frames, {len(capture.hand_motion.marker_names)} hand markers, "
                    f"{m.n_markers} trajectories, {100 * capture.truth['visible'].mean():.1f}% reconstructed",
                    {**q.marker_figures(m, hand=capture.hand_motion.marker_names),
                     **q.motion_figures(capture.hand_motion)}, warnings))
    return warnings


def _checked_capture(capture):
    """The capture with the warnings of its markers and true motion stored on both (markers and truth files)."""
    from dataclasses import replace

    from handcap.quality import plausibility as q
    warnings = q.marker_warnings(capture.markers, hand=capture.hand_motion.marker_names) + \
        q.motion_warnings(capture.hand_motion)
    capture = replace(capture, markers=q.attach(capture.markers, warnings),
                      hand_motion=capture.hand_motion.with_warnings(*warnings))
    return capture, capture.markers.warnings


def _cmd_demo(args) -> tuple[str, ...]:
    from handcap.demo import run_demo
    from handcap.io import check_output_folder
    check_output_folder(args.out, force=True)  # demo-output/ is rewritten on every run
    summary = run_demo(args.out)
    for key, value in summary.items():
        if key not in ("files", "seen_per_camera_fraction", "metrics", "warnings"):
            print(f"{key:28s} {value}")
    print("\nsolved motion against the ground truth:")
    print(summary["metrics"])
    warnings = tuple(summary["warnings"])
    from pathlib import Path
    files = [Path(f) for f in summary["files"]]
    print(f"\nwrote {len(files)} files to {args.out}/ (picture of the truth beside the solve: {args.out}/hand.png); "
          + (f"{len(warnings)} warning(s), see below" if warnings else "no warnings"))
    for path in files:
        print(f"  {path.relative_to(args.out) if path.is_relative_to(args.out) else path}")
    return warnings



def _frames_arg(text: str | None):
    """``A:B`` (frames, either end optional) -> slice."""
    if text is None:
        return None
    try:
        a, b = text.split(":")
        return slice(int(a) if a else None, int(b) if b else None)
    except ValueError:
        raise HandcapError(f"--frames must be A:B with frame numbers (either may be left out), got {text!r}") from None


def _betas_arg(text: str | None):
    """10 comma-separated numbers, or a .npz holding ``betas``."""
    import numpy as np
    if text is None:
        return None
    if text.endswith(".npz"):
        from handcap.io import load_npz
        return np.asarray(load_npz(text, ("betas",), "file with betas")["betas"], dtype=float).reshape(10)
    try:
        values = [float(v) for v in text.split(",")]
    except ValueError:
        raise HandcapError(f"--betas must be 10 comma-separated numbers or a .npz file, got {text!r}") from None
    if len(values) != 10:
        raise HandcapError(f"--betas needs 10 values, got {len(values)}")
    return np.array(values)


def _add_hand_model(p, default: str = "openhand") -> None:
    """``--hand-model`` and ``--mano-dir`` for a verb that uses the hand model."""
    p.add_argument("--hand-model", metavar="MODEL",
                   help=f"openhand (built in), mano (your MANO files: --mano-dir or HANDCAP_MANO_DIR) or mano:DIR "
                        f"(default: {default})")
    p.add_argument("--mano-dir", metavar="DIR", help="folder holding MANO_RIGHT.pkl/MANO_LEFT.pkl (implies "
                                                     "--hand-model mano; default: $HANDCAP_MANO_DIR)")


def _hand_model(args, side: str, *, recorded: str | None = None, what: str = "the input"):
    """The hand model of ``--hand-model``/``--mano-dir`` (checked against the model ``what`` was made with)."""
    from handcap.hand import hand_model_from_options
    return hand_model_from_options(args.hand_model, args.mano_dir, side=side, recorded=recorded, what=what)


def _cmd_calibrate_markers(args) -> tuple[str, ...]:
    from handcap.io import check_not_input, read_markers
    from handcap.layouts import load_layout
    from handcap.solve import calibrate_attachment
    check_not_input(args.out, args.input)
    layout = load_layout(args.layout, side=args.side)
    markers = read_markers(args.input, units=args.units, hand=[m.name for m in layout.hand_markers])
    hand = _hand_model(args, layout.side)
    result = calibrate_attachment(markers, layout, hand, betas=_betas_arg(args.betas), frames=_frames_arg(args.frames),
                                  fit_shape=args.fit_shape, estimate_offset=args.estimate_offset)
    result.attachment.save(args.out)
    shape = ("shape fitted: " + " ".join(f"{b:+.2f}" for b in result.attachment.betas)) if result.fit_shape \
        else "shape not fitted (use --fit-shape)"
    print(f"{args.out}: {len(result.attachment)} markers from {len(result.frames)} frames, {result.rounds} rounds, "
          f"calibration MRE {1000 * result.mre:.2f} mm; {shape}")
    return result.warnings


def _cmd_solve(args) -> tuple[str, ...]:
    import time

    import numpy as np

    from handcap.hand.attachment import MarkerAttachment
    from handcap.io import check_not_input, read_markers, write_hand_motion
    from handcap.solve import solve_hand
    check_not_input(args.out, args.input, args.attachment)
    attachment = MarkerAttachment.load(args.attachment)
    markers = read_markers(args.input, units=args.units, hand=attachment.marker_names)
    hand = _hand_model(args, attachment.side, recorded=attachment.model, what=args.attachment)
    start = time.perf_counter()
    motion = solve_hand(markers, attachment, hand, method=args.method, filter_cutoff=args.filter_cutoff,
                        filter_order=args.filter_order)
    seconds = time.perf_counter() - start
    motion = motion.with_warnings(*markers.warnings)  # e.g. the unit of the input guessed: kept with the result
    write_hand_motion(motion, args.out)
    residuals = motion.marker_residuals
    print(f"{args.out}: {motion.n_frames} frames in {seconds:.1f} s ({motion.n_frames / seconds:.0f} frames/s, "
          f"{args.method}), MRE {1000 * np.nanmean(residuals):.2f} ± {1000 * np.nanstd(residuals):.2f} mm"
          + (f", low-passed at {args.filter_cutoff:g} Hz" if args.filter_cutoff else ""))
    return motion.warnings


def _cmd_track_object(args) -> tuple[str, ...]:
    import numpy as np

    from handcap.io import check_not_input, load_npz, read_markers, write_object_motion
    from handcap.objects import track_rigid
    check_not_input(args.out, args.input, args.canonical)
    markers = read_markers(args.input, units=args.units)
    names = _expand_names(markers, args.markers)
    canonical = None if args.canonical is None else load_npz(args.canonical, ("canonical",), "object file")["canonical"]
    track = track_rigid(markers, names, canonical, name=args.name, threshold=args.threshold_mm / 1000)
    from handcap.quality import plausibility as q
    motion = q.attach(track.motion, [*markers.warnings, *q.object_warnings(track, threshold=args.threshold_mm / 1000)])
    write_object_motion(motion, args.out)
    unsolved = track.unsolved
    listed = ", ".join(map(str, unsolved[:10])) + (" ..." if len(unsolved) > 10 else "")
    print(f"{args.out}: {track.motion.n_frames} frames, mean residual {1000 * track.mean_residual:.2f} mm, "
          f"{int(np.sum(~track.inliers & ~np.isnan(markers.select(names).positions[..., 0])))} outlier samples, "
          f"{len(unsolved)} frames with fewer than 3 markers" + (f": {listed}" if len(unsolved) else ""))
    print("  quality: " + (f"{len(motion.warnings)} warning(s), see below" if motion.warnings else "no warnings"))
    return motion.warnings


def _expand_names(markers, text: str) -> list[str]:
    """Comma-separated marker names or shell-style patterns (``boite:*``); see ``handcap.core.markers.expand_names``."""
    from handcap.core.markers import expand_names
    return expand_names(markers, text)


def _cmd_metrics(args) -> tuple[str, ...]:
    import json

    from handcap.report import metrics_table, motion_metrics
    if args.out:
        from handcap.io import check_output
        check_output(args.out, args.motion, args.truth, args.markers, args.attachment, args.object, args.object_mesh)
    hand = None
    if args.hand_model or args.mano_dir or (args.object_mesh and args.object) or args.leave_one_out:
        from handcap.io import read_hand_motion
        motion = read_hand_motion(args.motion)  # the model is needed for the mesh: the one it was solved with
        hand = _hand_model(args, motion.side, recorded=motion.model, what=args.motion)
    metrics = motion_metrics(args.motion, truth=args.truth, markers=args.markers, obj=args.object,
                             object_mesh=args.object_mesh, attachment=args.attachment,
                             leave_one_out=args.leave_one_out, hand=hand)
    stored, warnings = _motion_file_warnings(args.motion, args.markers)
    metrics["warnings"] = list(warnings)
    print(metrics_table(metrics))
    print(f"{'quality':22s} " + (f"{len(warnings)} warning(s), {len(stored)} of them stored in {args.motion}; see below"
                                 if warnings else "no warnings"))
    if args.out:
        from handcap.io import atomic_output
        with atomic_output(args.out, "w") as fh:
            json.dump(metrics, fh, indent=2)
    return warnings


def _motion_file_warnings(motion_path, markers_path=None):
    """The warnings stored in a hand motion file, and those plus the checks of the motion (and of its fit to the
    markers it was solved from, when given), without repeats."""
    import numpy as np

    from handcap.core.errors import merge_warnings
    from handcap.io import read_hand_motion, read_markers
    from handcap.quality import plausibility as q
    motion = read_hand_motion(motion_path)
    found = q.motion_warnings(motion)
    if markers_path is not None and motion.marker_fit is not None:
        from handcap.solve.motion import observed_markers
        observed, _ = observed_markers(read_markers(markers_path), list(motion.marker_names))
        found += q.residual_warnings(np.linalg.norm(motion.marker_fit - observed, axis=-1), names=motion.marker_names,
                                     what=f"MRE against {markers_path}")
    return motion.warnings, merge_warnings(motion.warnings, found)


def _cmd_shape(args) -> tuple[str, ...]:
    import numpy as np

    from handcap.io import save_npz
    from handcap.solve import MEASUREMENTS, betas_from_measurements, betas_from_scan, hand_measurements
    hand = _hand_model(args, args.side)
    if (args.scan is None) == (args.lengths is None):
        raise HandcapError("give either --scan or --lengths")
    from handcap.io import check_output
    check_output(args.out, args.scan)
    if args.scan:
        betas, chamfer = betas_from_scan(hand, _scan_points(args.scan))
        note = f"Chamfer distance {1000 * chamfer:.2f} mm"
    else:
        lengths = {}
        for item in args.lengths.split(","):
            key, _, value = item.partition("=")
            try:
                lengths[key.strip()] = float(value) / 1000
            except ValueError:
                raise HandcapError(f"--lengths takes name=millimetres pairs ({', '.join(MEASUREMENTS)}), "
                                   f"got {item!r}") from None
        betas = betas_from_measurements(hand, **lengths)
        note = "from " + ", ".join(lengths)
    from handcap.core.files import warnings_entry
    from handcap.quality import plausibility as q
    warnings = tuple(q.shape_warnings(betas))
    save_npz(args.out, {"betas": betas, **warnings_entry(warnings)})
    m = hand_measurements(hand, betas)
    print(f"{args.out}: betas {np.round(betas, 2).tolist()} ({note}); hand length {1000 * m['hand_length']:.1f} mm, "
          f"breadth {1000 * m['hand_breadth']:.1f} mm; " + (f"{len(warnings)} warning(s), see below" if warnings
                                                             else "no warnings"))
    return warnings


def _scan_points(path):
    import numpy as np

    from handcap.io import existing_file, load_npz
    path = existing_file(path)
    if path.suffix.lower() == ".npz":
        return load_npz(path, ("points",), "scan .npz (points)")["points"]
    import trimesh
    try:
        loaded = trimesh.load(path, force="mesh", process=False)
    except Exception as err:  # trimesh raises many types for unreadable files
        raise HandcapError(f"{path}: not a readable mesh or point cloud ({err})") from None
    vertices = np.asarray(getattr(loaded, "vertices", []), dtype=float)
    if vertices.ndim != 2 or len(vertices) == 0:
        raise HandcapError(f"{path}: holds no points")
    return vertices


def _cmd_label(args) -> tuple[str, ...]:
    from handcap.io import check_not_input, read_markers, read_points, write_markers
    from handcap.labeling import LabelingModel, label_take
    from handcap.layouts import load_layout
    check_not_input(args.out, args.input, *args.train)
    reuse = _is_model_file(args)  # --train is a saved model: it is used, and not written again
    if args.model and not reuse:
        check_not_input(args.model, args.input, *args.train, args.out)
    layouts = [load_layout(name) for name in args.layout]
    if len(layouts) > 1 and (args.model or args.method == "nearest"):
        raise HandcapError("several --layout (hands) label with the viterbi labeler and save no --model; "
                           "give one --layout for those")
    points = read_points(args.input, units=args.units)
    if reuse:
        models = [LabelingModel.load(args.train[0])]
    else:
        hand = [m.name for layout in layouts for m in layout.hand_markers]
        takes = [read_markers(path, units=args.units, hand=hand) for path in args.train]
        models = [LabelingModel.train(takes, layout.names, layout.rigid, seed=args.seed) for layout in layouts]
    options = {} if args.method == "nearest" else dict(hypotheses=args.hypotheses, lag=args.lag)
    if args.object:
        if args.method == "nearest":
            raise HandcapError("--object works with the viterbi labeler")
        options["objects"] = _label_objects(args.train[0] if not reuse else None, args.object)
    result = label_take(points, models[0] if len(models) == 1 else models, offline=args.offline,
                        method=args.method, **options)
    write_markers(result.markers, args.out)
    if args.model and not reuse:
        models[0].save(args.model)
    seen = (result.markers.positions[..., 0] == result.markers.positions[..., 0]).mean()
    lost = result.lost_frames
    print(f"{args.out}: {points.n_frames} frames, {len(result.markers.names)} labels, {100 * seen:.1f} % of "
          f"label-frames filled; hand frame not found in {len(lost)} frames"
          + (f" (first: {lost[0]})" if len(lost) else ""))
    return result.warnings


def _is_model_file(args) -> bool:
    from pathlib import Path
    return (bool(args.model) and len(args.train) == 1 and Path(args.train[0]).suffix.lower() == ".npz"
            and _is_labeling_model(args.train[0]))


def _label_objects(train_path, specs):
    """Rigid objects for the labeler: per spec (names or patterns, as ``track-object``), those markers of the
    training take, whose shape and rigidity are learned there."""
    import numpy as np

    from handcap.io import read_markers
    from handcap.labeling import RigidSet
    if train_path is None:
        raise HandcapError("--object learns the object's shape from a labeled take: give one as --train")
    train = read_markers(train_path)
    objects = []
    for spec in specs:
        names = _expand_names(train, spec)
        if len(names) < 3:
            raise HandcapError(f"--object {spec}: a rigid object needs 3 or more markers, got {len(names)}")
        positions = np.stack([train.positions[:, train.index(n)] for n in names], axis=1)
        # As rigid as the training take shows it (a soft object varies more than the 1.5 mm default).
        objects.append(RigidSet.from_training(names, positions, min_tolerance=0.0015))
    return objects


def _is_labeling_model(path) -> bool:
    from handcap.io import load_npz
    return str(load_npz(path).get("kind", "")) == "labeling_model"


def _cmd_score_labels(args) -> None:
    import json

    from handcap.io import read_markers
    from handcap.labeling import score_labels
    if args.json:
        from handcap.io import check_output
        check_output(args.json, args.labeled, args.truth)
    score = score_labels(read_markers(args.labeled, units=args.units), read_markers(args.truth, units=args.units))
    print(score.table(f"{args.labeled} against {args.truth}"))
    if args.json:
        from handcap.io import atomic_output
        with atomic_output(args.json, "w") as fh:
            json.dump(score.to_dict(), fh, indent=2)


def _cmd_corrupt(args) -> None:
    from pathlib import Path

    from handcap.io import check_not_input, read_markers, write_markers
    from handcap.labeling import corrupt
    out = Path(args.out)
    truth_path = out.with_name(out.stem + ".truth" + out.suffix)
    check_not_input(args.out, args.input)
    check_not_input(truth_path, args.input)
    markers = read_markers(args.input, units=args.units)
    names = None
    if args.layout:
        from handcap.layouts import load_layout
        names = load_layout(args.layout).names
    unlabeled, truth = corrupt(markers, ghost_rate=args.ghost_rate, dropout=args.dropout, seed=args.seed,
                               names=names)
    write_markers(unlabeled, out)
    write_markers(truth, truth_path)
    extra = int((unlabeled.positions[..., 0] == unlabeled.positions[..., 0]).sum()
                - (truth.positions[..., 0] == truth.positions[..., 0]).sum())
    print(f"{out}: {unlabeled.n_frames} frames of unlabeled points ({extra} ghost samples); truth in {truth_path}")


def _cmd_train_occlusion(args) -> tuple[str, ...]:
    import time

    from handcap.io import check_not_input
    from handcap.occlusion import read_take, train_occlusion_model
    check_not_input(args.out, *args.takes, *(args.poses or []))
    if args.poses and len(args.poses) != len(args.takes):
        raise HandcapError(f"--poses needs one hand motion per take: {len(args.takes)} takes, {len(args.poses)} poses")
    from dataclasses import replace

    from handcap.occlusion.augment import NO_AUGMENTATION, SUBJECT_AUGMENTATION
    from handcap.occlusion.data import synthetic_hand_takes
    if args.synthetic < 0 or args.speed_copies < 0:
        raise HandcapError("--synthetic and --speed-copies take a number >= 0")
    if not args.takes and not args.synthetic:
        raise HandcapError("give takes to train on, or --synthetic SUBJECTS, or both")
    augmentation = replace(SUBJECT_AUGMENTATION if args.augment else NO_AUGMENTATION, copies=args.speed_copies)
    poses = args.poses or [None] * len(args.takes)
    takes = [read_take(path, poses=pose) for path, pose in zip(args.takes, poses)]
    start = time.perf_counter()
    if args.synthetic:
        from handcap.layouts import load_layout
        takes += synthetic_hand_takes(args.layout, subjects=args.synthetic, seed=args.seed,
                                      side=load_layout(args.layout).side)

    def progress(stage, epoch, loss):
        if epoch % 10 == 9 or epoch == 0:
            print(f"  {stage}: epoch {epoch + 1}, loss {loss:.4f}", file=sys.stderr, flush=True)

    model = train_occlusion_model(takes, args.layout, seed=args.seed, epochs=args.epochs,
                                  regressor_epochs=args.epochs, progress=progress, augmentation=augmentation,
                                  pair_seconds=args.pair_seconds)
    model.save(args.out)
    info = model.info
    posed = int(info["posed_frames"])
    print(f"{args.out}: {model!r}, {time.perf_counter() - start:.0f} s\n"
          f"  saw {info['takes']} take(s) ({info['recorded_takes']} recorded, {info['synthetic_takes']} synthetic) "
          f"of {info['subjects']} subject(s), {info['frames']} frames; {info['augmented_copies']} augmented "
          f"copies ({info['augmented_frames']} frames); {info['samples']} training samples\n"
          f"  augmentation: {info['augmentation']}; gaps up to {args.pair_seconds:g} s\n"
          + (f"  joint regressor on {posed} posed frames" if posed else "  no poses: markers only"))
    return model.warnings


def _cmd_fill(args) -> tuple[str, ...]:
    import time

    from handcap.io import check_not_input, read_markers, write_markers
    from handcap.occlusion import fill_gaps
    check_not_input(args.out, args.input, *([args.model] if args.model else []))
    markers = read_markers(args.input, units=args.units)
    start = time.perf_counter()
    filled, report = fill_gaps(markers, args.method, max_gap_s=args.max_gap, model=args.model)
    seconds = time.perf_counter() - start
    write_markers(filled, args.out)
    print(f"{args.out}: {report.filled_samples} samples in {report.filled_gaps} gaps filled ({args.method}, "
          f"gaps up to {report.max_gap_frames} frames = {args.max_gap:g} s), {report.left_gaps} gaps "
          f"({report.left_samples} samples) left missing, {seconds:.1f} s"
          + (f"; not in the model, left as they were: {', '.join(report.untouched)}" if report.untouched else ""))
    return filled.warnings


def _cmd_clean(args) -> tuple[str, ...]:
    from pathlib import Path

    from handcap.io import MARKER_WRITERS, check_not_input, read_markers, write_markers
    from handcap.layouts import load_layout
    from handcap.multiview.clean import clean_markers
    check_not_input(args.out, args.input)
    suffix = Path(args.out).suffix.lower()
    if suffix not in MARKER_WRITERS:
        raise HandcapError(f"{args.out}: cannot write '{suffix or 'no extension'}' marker files; "
                           f"use one of {', '.join(sorted(MARKER_WRITERS))}")
    for name in ("max_linear", "max_rigid", "max_spline"):
        if getattr(args, name) < 0:
            raise HandcapError(f"--{name.replace('_', '-')} must be 0 or more frames, got {getattr(args, name)}")
    layout = None if args.layout is None else load_layout(args.layout)
    markers = read_markers(args.input, units=args.units,
                           hand=None if layout is None else [m.name for m in layout.hand_markers])
    cleaned, report = clean_markers(
        markers, layout, radius=None if args.radius_mm is None else args.radius_mm / 1000, window=args.window,
        z=args.z, floor=args.floor_mm / 1000, max_linear_frames=args.max_linear, max_rigid_frames=args.max_rigid,
        max_spline_frames=args.max_spline, rigid_tolerance=args.rigid_tolerance_mm / 1000)
    from handcap.quality import plausibility as q
    cleaned = q.attach(cleaned, [*markers.warnings, *q.clean_warnings(report, markers.missing),
                                 *q.marker_warnings(cleaned, hand=None if layout is None else layout.names)])
    write_markers(cleaned, args.out)
    n = report.summary()
    print(q.summary(f"{args.out}: removed {n['cluster_removed']} samples away from their patch and "
                    f"{n['outlier_removed']} spikes; filled {n['rigid_filled']} rigid, {n['linear_filled']} linear, "
                    f"{n['spline_filled']} spline; {n['missing']} of {report.missing.size} samples missing",
                    q.marker_figures(cleaned, hand=None if layout is None else layout.names), cleaned.warnings))
    return cleaned.warnings


def _add_label(verbs) -> None:
    from handcap.layouts import SHIPPED
    p = verbs.add_parser("label", help="label unlabeled finger markers online (GMM + N-best + Kalman + Viterbi)",
                         description="Every point of IN is treated as unlabeled, whatever its name or slot. The "
                                     "labels and the spatial model come from ROM, a labeled range-of-motion take "
                                     "(any marker format) with the layout's markers; the layout's rigid markers give "
                                     "the hand frame. The spatial model is re-aligned to the take as it is labelled "
                                     "(another day's glove, a re-stuck marker, another subject); a hand frame lost "
                                     "in many frames or few points labelled are warnings.")
    p.add_argument("input", help="unlabeled points: any marker file, or a points .npz")
    p.add_argument("--train", required=True, action="append", metavar="ROM",
                   help="labeled range-of-motion take (or a model .npz with --model); repeat for several takes "
                        "(other days, other subjects), each holding every --layout's markers")
    p.add_argument("--layout", required=True, action="append",
                   help=f"marker layout: {', '.join(SHIPPED)} or a .toml file; repeat once per hand in the stream "
                        "(each with its own marker names and rigid markers, which may include wrist markers)")
    p.add_argument("--hypotheses", type=int, default=5, help="N best assignments per frame (default %(default)s)")
    p.add_argument("--lag", type=int, default=0, help="look-ahead frames before deciding (default 0: online)")
    p.add_argument("--offline", action="store_true",
                   help="decide on the whole take, in two passes: the spatial model re-aligned to the take's labels "
                        "between them")
    p.add_argument("--method", choices=("viterbi", "nearest"), default="viterbi",
                   help="the labeler, or the nearest-neighbour baseline")
    p.add_argument("--model", help="also save the trained model here (.npz); if --train is such a model, use it")
    p.add_argument("--seed", type=int, default=0, help="seed of the mixture fits")
    p.add_argument("--object", action="append", metavar="NAMES",
                   help="a rigid object in the stream: comma-separated names of its markers in ROM, or a pattern "
                        "such as 'pillow_*' (its shape is learned there); it is found by that shape, labelled, and "
                        "kept from the fingers (repeat for several)")
    p.add_argument("--out", required=True, help="labeled markers (.c3d .trc .npz)")
    _add_units(p, "the input's and --train's coordinates")
    p.set_defaults(run=_cmd_label)

    p = verbs.add_parser("score-labels", help="score a labeling against the truth (Table 1 categories)",
                         description="Correct labels (gaps included), erroneous labels, false markers, false "
                                     "occlusions per marker and overall; gaps, mean gap and segment length.")
    p.add_argument("labeled", help="labeled markers written by handcap label")
    p.add_argument("--truth", required=True, help="the true labels (e.g. the .truth file of handcap corrupt)")
    p.add_argument("--json", help="also write the scores as JSON")
    _add_units(p, "both files' coordinates")
    p.set_defaults(run=_cmd_score_labels)

    p = verbs.add_parser("corrupt", help="make a labeling test: strip labels, shuffle, add ghosts and dropouts",
                         description="Writes the unlabeled points to --out and the truth (the labeled take with the "
                                     "same dropouts) beside it as NAME.truth.EXT.")
    p.add_argument("input", help="a labeled take")
    p.add_argument("--out", required=True, help="unlabeled points (.c3d .trc .npz)")
    p.add_argument("--ghost-rate", type=float, default=2.0, help="ghost markers per second (default %(default)s)")
    p.add_argument("--dropout", type=float, default=0.05,
                   help="extra fraction of samples dropped (default %(default)s)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--layout", help="keep only this layout's markers")
    _add_units(p)
    p.set_defaults(run=_cmd_corrupt)


def _add_solve(verbs) -> None:
    from handcap.layouts import SHIPPED
    from handcap.solve import MEASUREMENTS, METHODS
    p = verbs.add_parser("calibrate-markers", help="find where the markers sit on the hand from a calibration take",
                         description="Calibrate the marker attachment (triangle, barycentric coordinates, offset of "
                                     "every marker on its segment) from a take of an open hand slowly turned.")
    p.add_argument("input", help="labeled markers (.c3d .tsv .csv .trc .npz)")
    p.add_argument("--layout", required=True, help=f"marker layout: {', '.join(SHIPPED)} or a .toml file")
    p.add_argument("--side", choices=("right", "left"), default=None, help="hand side (default: the layout's)")
    p.add_argument("--frames", help="frames to use, A:B (default all)")
    p.add_argument("--betas", help="known shape: 10 comma-separated values or a .npz with betas")
    p.add_argument("--fit-shape", action=argparse.BooleanOptionalAction, default=None,
                   help="estimate the 10 shape values too (default: when the layout has 3 or more palm markers and "
                        "markers on two or more segments of 3 or more digits, and no --betas)")
    p.add_argument("--estimate-offset", action=argparse.BooleanOptionalAction, default=None,
                   help="estimate each marker's height off the skin (default: for sphere markers the layout places "
                        "on a segment with 3 or more markers)")
    p.add_argument("--out", required=True, help="attachment .npz")
    _add_units(p)
    _add_hand_model(p)
    p.set_defaults(run=_cmd_calibrate_markers)

    p = verbs.add_parser("solve", help="solve hand motion from labeled markers",
                         description="Per-frame hand pose from labeled markers with a calibrated attachment.")
    p.add_argument("input", help="labeled markers (.c3d .tsv .csv .trc .npz)")
    p.add_argument("--attachment", required=True, help="attachment .npz from calibrate-markers")
    p.add_argument("--method", choices=METHODS, default="lm", help="lm (default) or adam (the paper's, slow)")
    p.add_argument("--filter-cutoff", type=float, default=None, help="low-pass the motion at this frequency, Hz")
    p.add_argument("--filter-order", type=int, default=2, help="Butterworth order (default %(default)s)")
    p.add_argument("--out", required=True, help="hand motion .npz")
    _add_units(p)
    _add_hand_model(p, "the attachment's")
    p.set_defaults(run=_cmd_solve)

    p = verbs.add_parser("track-object", help="6-DoF motion of a rigid object from its markers",
                         description="Kabsch with RANSAC per frame; the object's marker geometry is estimated from "
                                     "the take unless --canonical gives it. Frames with fewer than 3 markers are "
                                     "reported and left empty (NaN), not guessed.")
    p.add_argument("input", help="labeled markers")
    p.add_argument("--markers", required=True,
                   help="comma-separated names of the object's markers (3 or more); patterns such as 'boite:*' work")
    p.add_argument("--canonical", help="object .npz with canonical (M, 3) marker positions")
    p.add_argument("--name", default="object")
    p.add_argument("--threshold-mm", type=float, default=5.0, help="RANSAC inlier distance (default %(default)s)")
    p.add_argument("--out", required=True, help="object motion .npz")
    _add_units(p)
    p.set_defaults(run=_cmd_track_object)

    p = verbs.add_parser("metrics", help="quality metrics of a solved motion",
                         description="MRE, joint error against ground truth, leave-one-marker-out error, MSNR, jerk, "
                                     "penetration, diversity and coherence (definitions in handcap.quality.metrics).")
    p.add_argument("motion", help="hand motion .npz")
    p.add_argument("--truth", help="ground truth (truth.npz of handcap synth, or a hand motion .npz)")
    p.add_argument("--markers", help="the labeled markers the motion was solved from (for MRE)")
    p.add_argument("--attachment", help="attachment .npz (for --leave-one-out)")
    p.add_argument("--leave-one-out", action="store_true", help="solve again without each marker (slow)")
    p.add_argument("--object", help="object motion .npz (for penetration)")
    p.add_argument("--object-mesh", help="the object's mesh (any format trimesh reads), metres, object frame")
    p.add_argument("--out", help="also write the metrics as JSON")
    _add_hand_model(p, "the motion's")
    p.set_defaults(run=_cmd_metrics)

    p = verbs.add_parser("shape", help="estimate the 10 shape values from a scan or measured lengths",
                         description=f"From a 3D scan of an open hand (mesh or .npz points, metres) or measured "
                                     f"lengths in millimetres ({', '.join(MEASUREMENTS)}).")
    p.add_argument("--scan", help="scan mesh (.ply .obj .stl ...) or .npz with points")
    p.add_argument("--lengths", help="e.g. hand_length=190,hand_breadth=87 (millimetres)")
    p.add_argument("--side", choices=("right", "left"), default="right")
    p.add_argument("--out", required=True, help=".npz with betas")
    _add_hand_model(p)
    p.set_defaults(run=_cmd_shape)


def _add_synth(verbs) -> None:
    from handcap.layouts import SHIPPED
    from handcap.synth.motions import MOTIONS
    from handcap.synth.objects import OBJECTS
    from handcap.synth.scene import SynthConfig
    d = SynthConfig()
    p = verbs.add_parser("synth", help="make a synthetic capture with ground truth",
                         description="Move the open hand (and an object) through a motion, film its markers with a "
                                     "rig of cameras, decide visibility by ray casting and add capture faults. "
                                     "Writes markers.c3d/.npz, points.npz, detections.npz, cameras.toml, truth.npz "
                                     "and scene.toml into OUT; the same settings give the same bytes.")
    p.add_argument("--layout", default=d.layout, help=f"marker layout: {', '.join(SHIPPED)} or a .toml file")
    p.add_argument("--motion", default=d.motion, choices=MOTIONS)
    p.add_argument("--frames", type=int, default=d.frames)
    p.add_argument("--rate", type=float, default=d.rate, help="frames per second (default %(default)s)")
    p.add_argument("--seed", type=int, default=d.seed)
    p.add_argument("--side", default=d.side, choices=("right", "left"))
    p.add_argument("--object", default=d.object, choices=OBJECTS + ("auto", "none"),
                   help="object to manipulate (auto: the motion's usual one)")
    p.add_argument("--betas", help="10 comma-separated shape values (default: drawn from the seed)")
    p.add_argument("--cameras", type=int, default=d.cameras)
    p.add_argument("--min-views", type=int, default=d.min_views, help="cameras needed to reconstruct a marker")
    p.add_argument("--noise-mm", type=float, default=d.noise_mm, help="3D jitter, mm (default %(default)s)")
    p.add_argument("--pixel-noise", type=float, default=d.pixel_noise, help="2D noise, px (default %(default)s)")
    p.add_argument("--dropout", type=float, default=d.dropout, help="extra fraction lost in bursts")
    p.add_argument("--ghost-rate", type=float, default=d.ghost_rate, help="ghost markers per second")
    p.add_argument("--swap-rate", type=float, default=d.swap_rate, help="label swaps per second")
    p.add_argument("--outlier-rate", type=float, default=d.outlier_rate,
                   help="fraction of 2D detections with a wrong id")
    p.add_argument("--max-view-angle", type=float, default=None,
                   help="degrees; default 75 for patches, none for spheres")
    p.add_argument("--placement-mm", type=float, default=d.placement_mm,
                   help="how far markers sit from their nominal layout spots, mm (default %(default)s)")
    p.add_argument("--subject-seed", type=int, default=None,
                   help="seed of the subject (hand shape, marker placement); share it between the takes of a session")
    p.add_argument("--scene", help="take every setting from a scene.toml written by an earlier run")
    p.add_argument("--out", required=True, help="output folder (new or empty, unless --force)")
    p.add_argument("--force", action="store_true", help="write into --out even if it holds files (those of the "
                                                        "same names are replaced)")
    p.set_defaults(run=_cmd_synth)

    p = verbs.add_parser("demo", help="run the main job on built-in data into demo-output/",
                         description="Synthetic DexterCap-style session -> marker calibration -> solve -> "
                                     "5 Hz smoothing -> metrics against the truth, written to demo-output/.")
    p.add_argument("--out", default="demo-output")
    p.set_defaults(run=_cmd_demo)


def _add_occlusion(verbs) -> None:
    from handcap.layouts import SHIPPED
    from handcap.occlusion import FILL_METHODS, SHIPPED_MODELS
    from handcap.occlusion.train import PAIR_SECONDS
    p = verbs.add_parser("train-occlusion", help="train the occluded-marker predictor (and joint regressor) on takes",
                         description="Trains the autoencoder that predicts occluded markers on labeled takes (any "
                                     "marker format, or handcap synth folders); with poses (synth truth, or --poses "
                                     "hand motions from handcap solve) also the joint regressor. Deterministic for a "
                                     "seed. The model is a small .npz used by handcap fill and OcclusionFiller.")
    p.add_argument("takes", nargs="*", metavar="TAKE", help="labeled takes holding the layout's markers "
                                                             "(none: --synthetic only)")
    p.add_argument("--layout", required=True, help=f"marker layout: {', '.join(SHIPPED)} or a .toml file")
    p.add_argument("--poses", nargs="+", metavar="MOTION", help="one hand motion .npz per take (phi, global_orient, "
                                                                 "transl) to train the joint regressor")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--epochs", type=int, default=60, help="training epochs of each network (default %(default)s)")
    p.add_argument("--synthetic", type=int, default=0, metavar="SUBJECTS",
                   help="also train on synthetic takes: SUBJECTS x every synthetic motion, each take a new subject "
                        "(default %(default)s)")
    p.add_argument("--augment", action="store_true",
                   help="augment every sample as another subject (scale, back-of-hand, finger and marker "
                        "placement) for a model that must serve new subjects; it costs on the training subject itself")
    p.add_argument("--speed-copies", type=int, default=0, metavar="N",
                   help="also train on N time-warped copies of every take (0.6-1.6x speed; default %(default)s)")
    p.add_argument("--pair-seconds", type=float, default=PAIR_SECONDS, metavar="SECONDS",
                   help="score the marker predictor as the filler uses it over gaps up to this long (default "
                        "%(default)s); 0 trains on single frames as the paper does")
    p.add_argument("--out", required=True, help="model .npz")
    p.set_defaults(run=_cmd_train_occlusion)

    p = verbs.add_parser("fill", help="fill marker gaps of a recorded take (interpolation or occlusion prediction)",
                         description="linear/spline interpolate interior gaps; lk, ma, ac and nn are the real-time "
                                     "paper's predictors, run forwards and backwards and blended so the fill meets "
                                     "both ends of a gap. Gaps longer than --max-gap stay missing.")
    p.add_argument("input", help="labeled markers (.c3d .tsv .csv .trc .npz)")
    p.add_argument("--method", choices=FILL_METHODS, default="nn", help="default %(default)s")
    p.add_argument("--model", help=f"occlusion model .npz, or a shipped one: {', '.join(SHIPPED_MODELS)} (nn)")
    p.add_argument("--max-gap", type=float, default=0.5, metavar="SECONDS",
                   help="longest gap to fill, seconds (default %(default)s)")
    p.add_argument("--out", required=True, help="filled markers (.c3d .trc .npz)")
    _add_units(p)
    p.set_defaults(run=_cmd_fill)


def _cmd_triangulate(args) -> tuple[str, ...]:
    import time

    from handcap.io import check_not_input, write_markers
    from handcap.io.camera_formats import read_rig
    from handcap.multiview import merge_detections, read_detections, triangulate_detections, write_quality

    from handcap.multiview import quality_path
    check_not_input(args.out, args.cameras, *args.detections)
    check_not_input(quality_path(args.out), args.cameras, *args.detections)
    detections = merge_detections([read_detections(path) for path in args.detections])
    rig = read_rig(args.cameras, units=args.units)
    start = time.perf_counter()
    result = triangulate_detections(detections, rig, min_views=args.min_views, threshold_px=args.threshold_px,
                                    chunk_frames=args.chunk_frames, scheduler=args.scheduler, workers=args.workers)
    seconds = time.perf_counter() - start
    from handcap.quality import plausibility as q
    markers = result.to_markers()
    markers = q.attach(markers, [*rig.warnings, *q.triangulation_warnings(
        result.error_px, result.views, threshold_px=args.threshold_px, used=result.used), *q.marker_warnings(markers)])
    write_markers(markers, args.out)
    quality = write_quality(result, args.out)
    s = result.summary()
    print(q.summary(f"{args.out}: {s['frames']} frames, {s['markers']} markers, {s['points']} points from "
                    f"{s['detections']} detections ({s['rejected']} rejected), mean reprojection error "
                    f"{s['mean_error_px']:.2f} px over {s['mean_views']:.1f} views, "
                    f"{s['frames'] * s['markers'] / max(seconds, 1e-9):,.0f} marker-frames/s; per-marker errors and "
                    f"view counts in {quality}", q.marker_figures(markers), markers.warnings))
    return markers.warnings


def _add_multiview(verbs) -> None:
    p = verbs.add_parser("triangulate", help="3D markers from 2D detections of calibrated cameras (robust)",
                         description="Undistorts the detections, triangulates every marker in every frame from the "
                                     "best inlier set of views (RANSAC over pairs of views, then a non-linear "
                                     "refinement) and writes the markers with their metric residuals. Per marker "
                                     "and frame, the reprojection error (px) and inlier view count go to "
                                     "OUT_STEM.triangulation.npz, with a used/rejected flag per detection. Blocks of "
                                     "frames run on local processes, or on a Dask cluster with --scheduler.")
    p.add_argument("detections", nargs="+", metavar="DETECTIONS",
                   help="2D detections .npz (handcap synth's detections.npz; several files, say one per camera, "
                        "are merged)")
    p.add_argument("--cameras", required=True, help="calibrated rig (.toml anipose or caliscope, .yml/.xml OpenCV, "
                                                    ".qca.txt Qualisys)")
    p.add_argument("--min-views", type=int, default=3, help="inlier views a marker needs (default %(default)s)")
    p.add_argument("--threshold-px", type=float, default=5.0,
                   help="reprojection error of an inlier view, pixels (default %(default)s)")
    p.add_argument("--scheduler", metavar="ADDR", help="Dask scheduler, e.g. tcp://HOST:8786 (default: local "
                                                        "processes)")
    p.add_argument("--workers", type=int, help="local processes (default: chosen by the size of the take: a small "
                                               "one stays in this process)")
    p.add_argument("--chunk-frames", type=int, help="frames per block of work (default: split evenly)")
    p.add_argument("--out", required=True, help="markers (.c3d .trc .npz)")
    _add_units(p, "the camera file's positions (translations)")
    p.set_defaults(run=_cmd_triangulate)


def _add_clean(verbs) -> None:
    from handcap.layouts import SHIPPED
    from handcap.multiview import clean
    p = verbs.add_parser("clean", help="remove mislabelled points and spikes from 3D markers, fill short gaps",
                         description="DexterCap section 3.3: in every frame keep the largest cluster of each "
                                     "patch (or segment) of --layout, remove samples far from a local fit in a "
                                     "sliding window, then fill interior gaps by the rigid motion of the patch, "
                                     "linear and spline interpolation, each up to its own gap length. Nothing is "
                                     "extrapolated past the ends of a marker's data; longer gaps stay missing.")
    p.add_argument("input", help="labeled markers (.c3d .tsv .csv .trc .npz)")
    p.add_argument("--layout", help=f"marker layout for clustering and the rigid fill: {', '.join(SHIPPED)} or a "
                                    ".toml file (default: none, those steps are skipped)")
    p.add_argument("--radius-mm", type=float, help="cluster radius for every patch, millimetres (default: from "
                                                   "the layout's template)")
    p.add_argument("--window", type=int, default=clean.WINDOW, help="frames in the outlier window, odd "
                                                                    "(default %(default)s)")
    p.add_argument("--z", type=float, default=clean.Z, help="outlier threshold, robust standard deviations "
                                                            "(default %(default)s)")
    p.add_argument("--floor-mm", type=float, default=1000 * clean.FLOOR,
                   help="smaller deviations are never outliers, millimetres (default %(default)s)")
    p.add_argument("--max-rigid", type=int, default=clean.MAX_RIGID, metavar="FRAMES",
                   help="longest gap filled by the rigid motion of the patch (default %(default)s; 0: off)")
    p.add_argument("--max-linear", type=int, default=clean.MAX_LINEAR, metavar="FRAMES",
                   help="longest gap filled by linear interpolation (default %(default)s; 0: off)")
    p.add_argument("--max-spline", type=int, default=clean.MAX_SPLINE, metavar="FRAMES",
                   help="longest gap filled by a cubic spline (default %(default)s; 0: off)")
    p.add_argument("--rigid-tolerance-mm", type=float, default=1000 * clean.RIGID_TOLERANCE,
                   help="largest RMS residual of a rigid fill's fit, millimetres (default %(default)s)")
    p.add_argument("--out", required=True, help="cleaned markers (.c3d .trc .npz)")
    _add_units(p)
    p.set_defaults(run=_cmd_clean)


def _camera_toml_out(out: str, inputs) -> None:
    """Check a camera file's name before the slow work: .toml, folder present, not an input."""
    from pathlib import Path

    from handcap.io import check_not_input
    path = Path(out)
    if path.suffix.lower() != ".toml":
        raise HandcapError(f"{out}: camera files are anipose-style .toml, got '{path.suffix or 'no extension'}'")
    if not (path.parent if str(path.parent) else Path(".")).is_dir():
        raise HandcapError(f"{out}: folder {path.parent} does not exist")
    check_not_input(out, *inputs)


def _cmd_calibrate_intrinsics(args) -> tuple[str, ...]:
    from handcap.core.cameras import CameraRig
    from handcap.multiview.boards import detect_in_files, parse_board
    from handcap.multiview.calibration import calibrate_intrinsics
    board = parse_board(args.board)
    _camera_toml_out(args.out, args.inputs)
    detections = detect_in_files(args.inputs, board, every=args.every)
    result = calibrate_intrinsics(detections, name=args.name, fix_k3=args.fix_k3,
                                  reject_outliers=not args.keep_outliers)
    from handcap.quality import plausibility as q
    rig = q.attach(CameraRig([result.camera]), q.camera_warnings(result.rms, names=[result.camera.name]))
    rig.save(args.out)  # the warnings go to the file's [metadata]
    warnings = rig.warnings
    camera = result.camera
    (fx, fy), (cx, cy) = camera.matrix[[0, 1], [0, 1]], camera.matrix[:2, 2]
    print(f"{args.out}: camera {camera.name}, {camera.size[0]}x{camera.size[1]} px, f = {fx:.2f}, {fy:.2f} px, "
          f"principal point ({cx:.1f}, {cy:.1f}) px, k1 k2 p1 p2 k3 = "
          f"{' '.join(f'{k:.4g}' for k in camera.distortions)}")
    print(f"reprojection RMS {result.rms:.3f} px over {len(result.views)} views (board seen in "
          f"{int(detections.found.sum())} of {detections.n_frames} frames), worst view "
          f"{result.labels[int(result.view_rms.argmax())]} {result.view_rms.max():.3f} px"
          + (f"; rejected as outliers: {', '.join(detections.labels[t] for t in result.rejected)}"
             if len(result.rejected) else ""))
    print("quality: " + (f"{len(warnings)} warning(s), see below" if warnings else "no warnings"))
    return warnings


def _cmd_calibrate_rig(args) -> tuple[str, ...]:
    from handcap.io.camera_formats import read_rig
    from handcap.multiview.boards import detect_in_files, parse_board
    from handcap.multiview.calibration import calibrate_rig
    board = parse_board(args.board)
    names = args.names
    if names is not None and len(names) == 1 and "," in names[0]:
        names = [n.strip() for n in names[0].split(",")]
    if names is not None and len(names) != len(args.recordings):
        raise HandcapError(f"{len(names)} camera names for {len(args.recordings)} cameras; give one name per camera")
    _camera_toml_out(args.out, args.recordings + ([args.intrinsics] if args.intrinsics else []))
    cameras = None if args.intrinsics is None else read_rig(args.intrinsics, positions=False)  # extrinsics unused
    detections = [detect_in_files(path, board, every=args.every) for path in args.recordings]
    result = calibrate_rig(detections, names=names, cameras=cameras, refine_intrinsics=args.refine_intrinsics,
                           fix_k3=args.fix_k3, origin=args.origin, origin_frame=args.origin_frame,
                           loss=args.loss, f_scale=args.f_scale)
    from handcap.quality import plausibility as q
    rig = q.attach(result.rig, q.camera_warnings(result.rms, names=result.names))
    rig.save(args.out)  # the warnings go to the file's [metadata]
    warnings = rig.warnings
    print(result.summary())
    print(f"{args.out}: {len(result.rig)} cameras; " + (f"{len(warnings)} warning(s), see below" if warnings
                                                        else "no warnings"))
    return warnings


def _add_calibrate(verbs) -> None:
    from handcap.multiview.calibration import LOSSES, ORIGINS
    board_help = ("checkerboard:COLSxROWS:SQUARE_M (inner corners, metres) or "
                  "charuco:COLSxROWS:SQUARE_M[:MARKER_M][:DICT][:inverted] (squares; marker 0.75 x square and "
                  "DICT_4X4_1000 by default), e.g. charuco:4x5:0.054:0.0405:DICT_4X4_1000:inverted")
    p = verbs.add_parser("calibrate", help="calibrate cameras from a checkerboard or ChArUco board",
                         description="intrinsics: one camera's matrix and distortion (OpenCV, k1 k2 p1 p2 k3) "
                                     "from images or a video of the board. rig: every camera of a rig from "
                                     "synchronised recordings of the board (frame number = time), by a bundle "
                                     "adjustment of all cameras and board poses. Both write anipose-style TOML.")
    what = p.add_subparsers(dest="what", metavar="WHAT")
    what.required = True

    q = what.add_parser("intrinsics", help="one camera's matrix and lens distortion",
                        description="Find the board in the images (or video frames), calibrate with OpenCV and "
                                    "drop views reprojecting far worse than the others (3 x the median, and "
                                    "0.5 px). Writes one camera at the origin.")
    q.add_argument("inputs", nargs="+", metavar="IMAGES_OR_VIDEO",
                   help="image files, a folder of images, or one video")
    q.add_argument("--board", required=True, help=board_help)
    q.add_argument("--name", help="camera name (default: the file or folder name)")
    q.add_argument("--every", type=int, default=1, metavar="N", help="video: use every N-th frame (default 1)")
    q.add_argument("--fix-k3", action="store_true", help="keep k3 = 0 (for few views)")
    q.add_argument("--keep-outliers", action="store_true", help="keep every view")
    q.add_argument("--out", required=True, help="camera file (.toml)")
    q.set_defaults(run=_cmd_calibrate_intrinsics)

    q = what.add_parser("rig", help="all cameras of a rig from synchronised recordings of the board",
                        description="One video or folder of images per camera, all of the same frames (frame t "
                                    "of every camera is the same instant). Each camera's intrinsics are "
                                    "calibrated first (or read from --intrinsics); the cameras are placed by "
                                    "chaining relative poses from shared views of the board, then all cameras "
                                    "and board poses are refined by a robust bundle adjustment. The world is the "
                                    "board at --origin-frame (x along the board, z out of its printed face) or "
                                    "the first camera. Cameras that never see the board or share no view with "
                                    "the others are named in the error.")
    q.add_argument("recordings", nargs="+", metavar="VIDEO_OR_FOLDER", help="one video or image folder per camera")
    q.add_argument("--board", required=True, help=board_help)
    q.add_argument("--names", nargs="+", metavar="NAME",
                   help="camera names in the order of the recordings (default: their file names)")
    q.add_argument("--every", type=int, default=1, metavar="N", help="videos: use every N-th frame (default 1)")
    q.add_argument("--intrinsics", metavar="FILE", help="known intrinsics: a camera file (anipose or caliscope "
                                                        "TOML, OpenCV YAML/XML, Qualisys QCA) with one camera per "
                                                        "recording, in the same order")
    q.add_argument("--refine-intrinsics", action=argparse.BooleanOptionalAction, default=None,
                   help="refine the intrinsics in the bundle adjustment (default: yes, unless --intrinsics)")
    q.add_argument("--fix-k3", action="store_true", help="keep k3 = 0")
    q.add_argument("--origin", choices=ORIGINS, default="board",
                   help="world frame: the board at --origin-frame, or the first camera (default %(default)s)")
    q.add_argument("--origin-frame", type=int, metavar="FRAME",
                   help="frame number of the board pose that is the world (default: the first frame in which "
                        "the first camera sees the board)")
    q.add_argument("--loss", choices=LOSSES, default="soft_l1", help="robust loss (default %(default)s)")
    q.add_argument("--f-scale", type=float, default=1.0, metavar="PX",
                   help="pixel error where the robust loss starts to discount (default %(default)s)")
    q.add_argument("--out", required=True, help="rig file (.toml)")
    q.set_defaults(run=_cmd_calibrate_rig)


def _cmd_layout_new(args) -> None:
    from pathlib import Path

    from handcap.io import atomic_output, check_not_input
    from handcap.layouts import SHIPPED, layout_template, load_layout
    out = Path(args.out)
    if out.is_dir():
        raise HandcapError(f"{out}: is a folder; give a file name such as {out / 'my-layout.toml'}")
    if out.suffix.lower() != ".toml":
        raise HandcapError(f"{out}: layouts are TOML files; name it NAME.toml")
    if args.like not in SHIPPED:
        check_not_input(out, args.like)
    if out.exists() and not args.force:
        raise HandcapError(f"{out}: exists; choose another name or add --force to replace it")
    layout = load_layout(args.like, side=args.side)
    with atomic_output(out, "w") as fh:
        fh.write(layout_template(layout, like=args.like, positions=not args.no_positions))
    given = 0 if args.no_positions else sum(m.position is not None for m in layout.markers)
    print(f"{out}: {len(layout)} markers like {args.like} ({layout.side} hand, {given} with positions), every field "
          f"explained in its comments; next: handcap layout check {out} YOUR_TAKE")


def _cmd_layout_check(args):
    from handcap.io import read_markers
    from handcap.layouts import check_layout, load_layout
    layout = load_layout(args.layout, side=args.side)
    markers = None if args.take is None else read_markers(args.take, units=args.units,
                                                          hand=[m.name for m in layout.hand_markers])
    result = check_layout(layout, markers, take=args.take)
    print(result.summary())
    return result.warnings


def _add_layout(verbs) -> None:
    from handcap.layouts import SHIPPED
    p = verbs.add_parser("layout", help="write a layout for your own marker set, and check it against a take",
                         description="new: a commented copy of a shipped layout to edit (names, segments, rigid "
                                     "set, positions). check: the layout's names in a take (a Subject: prefix is "
                                     "ignored), its segments, its positions on the template hand, its rigid set, "
                                     "and which positions calibrate-markers will estimate. An unusable layout "
                                     "exits with code 2; other problems are warnings.")
    what = p.add_subparsers(dest="what", metavar="WHAT")
    what.required = True
    q = what.add_parser("new", help="write a commented layout file to edit",
                        description="Copy a layout with every field explained in comments.")
    q.add_argument("--like", default="glove-13", help=f"layout to start from: {', '.join(SHIPPED)} or a .toml file "
                                                      "(default %(default)s)")
    q.add_argument("--side", choices=("right", "left"), default=None, help="write it for this hand (default: as "
                                                                            "--like)")
    q.add_argument("--no-positions", action="store_true",
                   help="leave the hand markers' positions out: calibrate-markers estimates them from a take (for "
                        "markers placed otherwise than in --like)")
    q.add_argument("--force", action="store_true", help="replace --out if it exists")
    q.add_argument("--out", required=True, help="layout file to write (.toml)")
    q.set_defaults(run=_cmd_layout_new)
    q = what.add_parser("check", help="check a layout, against a labeled take if given",
                        description="Names matched / missing / only in the take, segments, positions against the "
                                    "template hand (within 2 cm of their segment), the rigid set (3 or more markers "
                                    "of one segment, not in a line, as far apart in the take as in the layout) and "
                                    "what will be estimated.")
    q.add_argument("layout", help=f"layout: {', '.join(SHIPPED)} or a .toml file")
    q.add_argument("take", nargs="?", help="a labeled take of this marker set (.c3d .tsv .csv .trc .npz)")
    q.add_argument("--side", choices=("right", "left"), default=None, help="hand side (default: the layout's)")
    _add_units(q, "the take's coordinates")
    q.set_defaults(run=_cmd_layout_check)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="handcap", description=__doc__)
    parser.add_argument("--version", action="version", version=_version())
    parser.add_argument("--strict", action="store_true",
                        help="exit with code 2 when the result carries a warning (implausible figures, guessed "
                             "units); the output is still written")
    verbs = parser.add_subparsers(dest="verb", metavar="VERB")
    verbs.required = True

    p = verbs.add_parser("convert", help="convert a marker file (.c3d .tsv .csv .trc .npz) to another format",
                         description="Convert a marker file; the formats come from the extensions. "
                                     "Reads C3D, Qualisys TSV, OptiTrack Motive CSV, TRC and .npz; "
                                     "writes C3D, TRC and .npz. Units become metres (.npz) or millimetres (C3D, TRC).")
    p.add_argument("input")
    p.add_argument("output")
    p.add_argument("--partial", action="store_true",
                   help="C3D: keep the complete frames of a file shorter than its header promises")
    _add_units(p)
    p.set_defaults(run=_cmd_convert)

    _add_synth(verbs)
    _add_solve(verbs)
    _add_label(verbs)
    _add_occlusion(verbs)
    _add_multiview(verbs)
    _add_clean(verbs)
    _add_calibrate(verbs)
    _add_layout(verbs)
    return parser


def _version() -> str:
    from handcap import __version__
    return f"handcap {__version__}"


def main(argv=None) -> int:
    """Run one verb. Exit codes: 0 done, 2 user error (or a warning with ``--strict``), 130 interrupted.

    A verb's ``_cmd_`` function may return the warnings of the result it wrote (one-line strings): they are
    printed on stderr as ``handcap VERB: warning: ...``, once each.
    """
    import warnings

    from handcap.core.errors import HandcapWarning, merge_warnings
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        # Every HandcapWarning the library issues is caught here and printed once, with those the verb returns
        # (the ones stored in its output); Python's own display of them would repeat each line.
        with warnings.catch_warnings(record=True) as issued:
            warnings.simplefilter("always", HandcapWarning)
            returned = args.run(args)
        found = merge_warnings(returned, [str(w.message) for w in issued if issubclass(w.category, HandcapWarning)])
        for w in issued:
            if not issubclass(w.category, HandcapWarning):
                warnings.showwarning(w.message, w.category, w.filename, w.lineno)
        for line in found:
            print(f"handcap {args.verb}: warning: {line}", file=sys.stderr)
        sys.stdout.flush()
    except HandcapError as err:
        # One line, whatever the message quotes (an array's repr spans several).
        print(f"handcap {args.verb}: error: {' '.join(str(err).split())}", file=sys.stderr)
        return 2
    except BrokenPipeError:
        # The reader of our output went away (``handcap ... | head``): not an error of ours. Point stdout at
        # devnull so the interpreter's final flush does not raise again.
        import os
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 0
    except KeyboardInterrupt:
        print("handcap: interrupted", file=sys.stderr)
        return 130
    if found and args.strict:
        print(f"handcap {args.verb}: error: {len(found)} warning(s) and --strict given", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
