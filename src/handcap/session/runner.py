"""``handcap process``: every stage of every take of a session, resumable (issue 19).

Each take's results go to ``RESULTS/<take>/`` (:data:`OUTPUTS`): for an images take ``detections.npz``
(detect), ``triangulated.c3d`` (triangulate), ``cleaned.c3d`` (clean); then ``attachment.npz`` (calibrate),
``motion.npz`` (solve, or fit for a keypoints take), ``object.npz`` (object: the held object's motion, when the
take's settings name its markers), ``metrics.json`` (metrics), ``report.html`` (report).
Beside each stage's output a manifest (``<stage>.manifest.json``) records the stage's settings, the SHA-256 of
every input, handcap's version, the outputs, figures, warnings and seconds. A stage whose manifest matches (same
settings, inputs and version, its outputs present) is skipped, so a killed run resumes where it stopped, and an
edited setting reruns its stage and those whose inputs then change (a stage that writes the same bytes again stops
the cascade). Every output is written atomically and the manifest last. Takes run in parallel
(:func:`handcap.parallel.map_chunks`: local processes, or a Dask cluster with ``scheduler``): the takes that
calibrate others first, then the rest.
"""

from __future__ import annotations

import hashlib
import json
import time
from dataclasses import dataclass
from pathlib import Path

from handcap import __version__
from handcap.core.errors import HandcapError
from handcap.core.files import atomic_output
from handcap.parallel import map_chunks
from handcap.layouts.file import SHIPPED
from handcap.objects.articulated import SHIPPED as ARTICULATED
from handcap.session.spec import KIND_STAGES, Session, Take
from handcap.steps import detect as detect_step
from handcap.steps import markerless as markerless_step
from handcap.steps import metrics as metrics_step
from handcap.steps import multiview as multiview_step
from handcap.steps import objects as objects_step
from handcap.steps import report as report_step
from handcap.steps import solve as solve_step

#: Kinds of take whose markers the runner triangulates and cleans itself.
CAMERA_KINDS = ("images", "detections")
#: Each stage's output file in the take's folder.
OUTPUTS = {"detect": "detections.npz", "triangulate": "triangulated.c3d", "clean": "cleaned.c3d",
           "calibrate": "attachment.npz", "solve": "motion.npz", "object": "object.npz", "fit": "motion.npz",
           "metrics": "metrics.json", "report": "report.html"}


@dataclass(frozen=True)
class StageRun:
    """One stage of one take as it ran (or was skipped): ``status`` is ``done``, ``skipped`` or ``planned``."""

    take: str
    stage: str
    status: str
    seconds: float
    warnings: tuple
    output: str


def file_hash(path) -> str:
    """SHA-256 of a file's bytes, or of a folder's files (their relative paths and bytes, in sorted order; hex).

    Parameters
    ----------
    path : str or Path
    """
    path = Path(path)
    digest = hashlib.sha256()
    files = sorted(p for p in path.rglob("*") if p.is_file()) if path.is_dir() else [path]
    for file in files:
        if path.is_dir():
            digest.update(str(file.relative_to(path)).encode() + b"\0")
        with open(file, "rb") as fh:
            for block in iter(lambda: fh.read(1 << 20), b""):
                digest.update(block)
    return digest.hexdigest()


def _markers_of(session: Session, take: Take):
    """The labelled markers a take's solve reads: its cleaned corners (images) or its markers file."""
    if take.kind in CAMERA_KINDS:
        return session.results / take.name / OUTPUTS["clean"]
    return take.inputs.get("markers")


def _calibration_of(session: Session, take: Take):
    """The markers that calibrate ``take``: its ``calibration`` file, else its calibration take's markers, else its
    own when another take names it as theirs (None: it has an attachment)."""
    if "calibration" in take.inputs:
        return take.inputs["calibration"]
    source = take.calibration_take
    if source is None and any(t.calibration_take == take.name for t in session.takes):
        source = take.name
    if source is None or "attachment" in take.inputs:
        return None
    return _markers_of(session, next(t for t in session.takes if t.name == source))


def _calibrated_by(session: Session, take: Take) -> str:
    """The take whose calibrate stage makes ``take``'s attachment: another take named as its calibration take
    (calibrated once, on its own markers), else ``take`` itself."""
    source = take.calibration_take
    if source is None or source == take.name or {"calibration", "attachment"} & set(take.inputs):
        return take.name
    return source


def _inputs(session: Session, take: Take, stage: str, folder: Path) -> dict:
    """The files a stage reads, by role."""
    owner = next(t for t in session.takes if t.name == _calibrated_by(session, take))
    attachment = owner.inputs.get("attachment", session.results / owner.name / OUTPUTS["calibrate"])
    markers = _markers_of(session, take)
    # A layout file (not a shipped name) is an input of the stages that read it: editing it reruns them.
    layout = take.layout or stage_settings(session, take, "calibrate").get("layout")
    layout_file = None if layout is None or layout in SHIPPED else layout
    held = stage_settings(session, take, "object")
    description = held.get("articulated")
    tracked = folder / OUTPUTS["object"] if "object" in _stages(session, take) else None
    return {"detect": {"images": take.inputs.get("images"), "cameras": take.inputs.get("cameras"),
                       "pattern": take.inputs.get("pattern")},
            "triangulate": {"detections": take.inputs.get("detections", folder / OUTPUTS["detect"]),
                            "cameras": take.inputs.get("cameras")},
            "clean": {"markers": folder / OUTPUTS["triangulate"], "layout_file": layout_file},
            "calibrate": {"calibration": _calibration_of(session, take), "layout_file": layout_file},
            "solve": {"markers": markers, "attachment": attachment},
            "object": {"markers": markers,
                       "description": None if description is None or description in ARTICULATED else description,
                       "canonical": held.get("canonical")},
            "fit": {"keypoints": take.inputs.get("keypoints")},
            "metrics": {"motion": folder / OUTPUTS["solve"], "markers": markers or take.inputs.get("keypoints"),
                        "truth": take.inputs.get("truth"), "object": tracked or take.inputs.get("object"),
                        "object_mesh": take.inputs.get("object_mesh")},
            "report": {"motion": folder / OUTPUTS["solve"], "metrics": folder / OUTPUTS["metrics"]}}[stage]


def _stages(session: Session, take: Take) -> list[str]:
    """The stages that apply to ``take``: its kind's, those the session runs, calibrate only with something to
    calibrate on and not when its calibration take calibrates it, object only when its settings name the object's
    markers or description."""
    held = stage_settings(session, take, "object")
    return [s for s in KIND_STAGES[take.kind] if s in session.stages and (
        s != "calibrate" or (_calibration_of(session, take) and _calibrated_by(session, take) == take.name)) and (
        s != "object" or {"markers", "articulated"} & set(held))]


def _layout(take: Take, settings: dict, stage: str) -> str:
    layout = take.layout or settings.get("layout")
    if layout is None:
        raise HandcapError(f"take {take.name}: {stage} needs a layout (stages.calibrate.layout or the take's layout)")
    return layout


def _run_stage(stage: str, take: Take, settings: dict, inputs: dict, out: Path, session: Session):
    if stage == "detect":
        sources = sorted(p for p in inputs["images"].iterdir() if not p.name.startswith("."))
        return detect_step.detect(sources, out, rig=inputs["cameras"], pattern=inputs["pattern"], progress=False,
                                  **settings)
    if stage == "triangulate":
        return multiview_step.triangulate([inputs["detections"]], inputs["cameras"], out, workers=1, **settings)
    if stage == "clean":
        layout = _layout(take, session.settings.get("calibrate", {}), stage)
        return multiview_step.clean(inputs["markers"], out, layout=layout, **settings)
    if stage == "calibrate":
        layout = _layout(take, settings, stage)
        options = {k: v for k, v in settings.items() if k != "layout"}
        calibrated_on = next((t for t in session.takes if _markers_of(session, t) == inputs["calibration"]), take)
        # Corners of dense patches that no two cameras saw are normal: a camera take calibrates on those seen.
        options.setdefault("drop_unseen", calibrated_on.kind in CAMERA_KINDS)
        return solve_step.calibrate_markers(inputs["calibration"], out, layout=layout, **options)
    if stage == "solve":
        return solve_step.solve(inputs["markers"], inputs["attachment"], out, **settings)
    if stage == "object":
        options = {k: v for k, v in settings.items() if k != "threshold_mm"}
        return objects_step.track_object(inputs["markers"], out, threshold=settings.get("threshold_mm", 5.0) / 1000,
                                         **options)
    if stage == "fit":
        return markerless_step.fit_keypoints(inputs["keypoints"], out, **settings)
    if stage == "metrics":
        return metrics_step.metrics(inputs["motion"], truth=inputs.get("truth"), markers=inputs["markers"], out=out,
                                    obj=inputs.get("object"), object_mesh=inputs.get("object_mesh"), **settings)
    return report_step.report(out.parent, out)


def stage_settings(session: Session, take: Take, stage: str) -> dict:
    """A stage's settings for one take: the session's, then the take's own over them; a ``filter_cutoff`` of 0
    means no filter. A take's own object (its ``markers`` or ``articulated``) is another object than the session's:
    its settings replace the session's. Cameras started one by one are so for every stage: detect takes
    triangulate's ``sync`` (and ``max_offset_s``) to name unread squares from the other cameras, unless it has its
    own or no ``views``.

    Parameters
    ----------
    session : Session
    take : Take
    stage : str
    """
    own = take.settings.get(stage, {})
    settings = {**session.settings.get(stage, {}), **own}
    if stage == "object" and {"markers", "articulated"} & set(own):  # another object than the session's
        settings = dict(own)
    if settings.get("filter_cutoff") == 0:
        del settings["filter_cutoff"]
    if stage == "detect" and settings.get("views", True) and "sync" not in settings:
        timing = stage_settings(session, take, "triangulate")
        settings.update({k: timing[k] for k in ("sync", "max_offset_s") if k in timing})
    return settings


def run_take(job) -> list[StageRun]:
    """Run (or skip) every stage of one take; module-level so that workers can run it.

    Parameters
    ----------
    job : tuple (Session, Take, bool)
        The session, the take, and whether to only plan (dry run).
    """
    session, take, dry = job
    folder = session.results / take.name
    runs = []
    for stage in _stages(session, take):
        out = folder / OUTPUTS[stage]
        settings = stage_settings(session, take, stage)
        inputs = {k: Path(v) for k, v in _inputs(session, take, stage, folder).items() if v is not None}
        manifest_path = folder / f"{stage}.manifest.json"
        missing = [str(p) for p in inputs.values() if not p.exists()]
        record = None
        if not missing and manifest_path.is_file() and out.is_file():
            try:
                record = json.loads(manifest_path.read_text())
            except (json.JSONDecodeError, UnicodeDecodeError):
                record = None
        hashes = {k: file_hash(p) for k, p in inputs.items()} if not missing else None
        if (record and record.get("settings") == settings and record.get("inputs") == hashes
                and record.get("version") == __version__):
            runs.append(StageRun(take.name, stage, "skipped", 0.0, tuple(record.get("warnings", ())), str(out)))
            continue
        if dry:
            runs.append(StageRun(take.name, stage, "planned", 0.0, (), str(out)))
            continue
        if missing:
            raise HandcapError(f"take {take.name}: stage {stage} lacks {missing[0]}")
        folder.mkdir(parents=True, exist_ok=True)
        start = time.perf_counter()
        try:
            step = _run_stage(stage, take, settings, inputs, out, session)
        except HandcapError as error:  # which of many takes and stages: said first
            raise HandcapError(f"take {take.name}, stage {stage}: {error}") from None
        seconds = time.perf_counter() - start
        figures = step.result if isinstance(step.result, dict) else {}
        if hasattr(step.result, "mre"):  # a calibration
            figures = {"mre_mm": round(1000 * float(step.result.mre), 4)}
        manifest = {"stage": stage, "take": take.name, "settings": settings, "inputs": hashes,
                    "input_paths": {k: str(p) for k, p in inputs.items()}, "version": __version__,
                    "outputs": {OUTPUTS[stage]: file_hash(out)}, "seconds": round(seconds, 3),
                    "finished": time.strftime("%Y-%m-%dT%H:%M:%S"), "warnings": list(step.warnings),
                    "figures": {k: v for k, v in figures.items() if k in ("mre_mm", "joint_error_mm", "msnr_db",
                                                                             "object_error_mm", "cube_moves")},
                    "lines": list(step.lines)}
        with atomic_output(manifest_path, "w") as fh:
            json.dump(manifest, fh, indent=2)
        runs.append(StageRun(take.name, stage, "done", seconds, tuple(step.warnings), str(out)))
    return runs


def process(session: Session, *, dry_run: bool = False, scheduler=None, workers: int | None = None) -> list:
    """Run the session (see the module docstring).

    Parameters
    ----------
    session : Session
    dry_run : bool
        Only say what would run and what is up to date.
    scheduler : str or None
        A Dask scheduler's address; default local processes.
    workers : int or None
        Local processes (default: one per core, at most one per take).

    Returns
    -------
    list of StageRun
        Every stage of every take, take by take.
    """
    # Two waves: the takes that calibrate others first, then the rest (each wave's takes in parallel).
    sources = {t.calibration_take for t in session.takes}
    runs = []
    for wave in ([t for t in session.takes if t.name in sources], [t for t in session.takes if t.name not in sources]):
        if not wave:
            continue
        jobs = [(session, take, dry_run) for take in wave]
        count = workers if workers is not None else min(len(jobs), 2)
        results = map_chunks(run_take, jobs, scheduler=scheduler, workers=count, desc="takes")
        runs += [run for take_runs in results for run in take_runs]
    order = [t.name for t in session.takes]
    return sorted(runs, key=lambda r: order.index(r.take))  # stable: each take's stages stay in order


def summary(runs) -> str:
    """The table ``handcap process`` ends with: one row per take and stage."""
    lines = [f"{'take':<16} {'stage':<12} {'status':<8} {'seconds':>8}  warnings"]
    for r in runs:
        lines.append(f"{r.take:<16} {r.stage:<12} {r.status:<8} {r.seconds:>8.2f}  {len(r.warnings)}")
    return "\n".join(lines)
