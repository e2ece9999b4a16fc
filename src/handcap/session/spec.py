"""The session file (``session.toml``) of ``handcap process``: what it may say, checked with one clear line per
mistake naming the key and the file (issue 19).

::

    [session]
    name = "lab-2026-11"
    results = "results"                 # relative to this file (default: results)
    stages = ["calibrate", "solve", "fit", "metrics", "report"]   # default: all of STAGES that apply

    [stages.calibrate]
    layout = "glove-13"                 # every take's layout unless the take names one (or a .toml file,
                                        # relative to this file: handcap layout new writes one)
    [stages.solve]
    method = "lm"
    filter_cutoff = 8.0                 # Hz; omit (or 0) for none

    [[takes]]
    name = "grasp-01"
    kind = "markers"                    # labelled markers
    markers = "raw/grasp-01.c3d"
    calibration = "raw/calib.c3d"       # a calibration take ... or attachment = "attachment.npz"
    truth = "raw/grasp-01-truth.npz"    # optional: a synthetic take's truth, for the metrics

    [[takes]]
    name = "video-02"
    kind = "keypoints"                  # 3D hand keypoints (triangulated or lifted from video)
    keypoints = "raw/video-02-keypoints.c3d"

    [[takes]]
    name = "patches-03"
    kind = "images"                     # camera images of coded patches: detect, triangulate, clean, ...
    images = "raw/patches-03"           # one sub-folder of images (or one video) per camera
    cameras = "raw/cameras.toml"
    pattern = "raw/pattern.toml"
    layout = "dense-patches"
    calibration_take = "patches-calib"  # another take of the session, run first; its markers calibrate this one
    [takes.settings.solve]              # this take's own settings over the session's
    filter_cutoff = 0                   # 0: no filter
    [takes.settings.triangulate]
    sync = "auto"                       # cameras started one by one: find each one's offset (or "cam_2=+12.5, ...");
                                        # detect names unread squares with it too, unless it has a sync of its own
    [takes.settings.object]             # the object the hand holds, tracked from its markers (or patch corners)
    markers = "mug:*"                   # or articulated = "cube2x2-patches" (a 2x2x2 cube: its moves too)
    name = "mug"                        # canonical = "mug.npz": its markers in its mesh's frame (object_mesh)

Paths are relative to the session file.
"""

from __future__ import annotations

import re
import tomllib
from dataclasses import dataclass, field
from pathlib import Path

from handcap.core.errors import HandcapError
from handcap.detect.response import RESPONSES
from handcap.layouts.file import SHIPPED
from handcap.multiview.sync import parse_offsets
from handcap.objects.articulated import SHIPPED as ARTICULATED

#: The stages, in the order they run; each one's settings and their types.
STAGES = {
    "detect": {"rate": float, "refine": bool, "threshold": float, "alphabet": str, "track": bool,
               "views": bool, "sync": str, "max_offset_s": float, "response": str},
    "triangulate": {"min_views": int, "threshold_px": float, "units": str, "sync": str, "sync_reference": str,
                    "max_offset_s": float},
    "clean": {"window": int, "z": float, "max_linear_frames": int, "max_rigid_frames": int,
              "max_spline_frames": int},
    "calibrate": {"layout": str, "side": str, "fit_shape": bool, "estimate_offset": bool, "units": str,
                  "drop_unseen": bool, "drop_misfit_mm": float},
    "solve": {"method": str, "filter_cutoff": float, "filter_order": int, "units": str, "keep_swaps": bool},
    "object": {"markers": str, "articulated": str, "name": str, "threshold_mm": float, "units": str,
               "canonical": str},
    "fit": {"fit_shape": bool, "robust_scale": float, "filter_cutoff": float, "side": str, "label": str,
            "units": str},
    "metrics": {"leave_one_out": bool},
    "report": {},
}
#: Kinds of take the runner knows, the inputs each takes (required, optional) and the stages it goes through:
#: camera images of coded patches (detect, triangulate, clean, calibrate, solve), 2D detections of named
#: markers (triangulate, clean, ...), labelled markers (calibrate, solve) and 3D hand keypoints (fit the hand
#: model to them). ``layout`` and ``calibration_take`` are names, not files; ``images`` is a folder with one
#: sub-folder of images (or one video) per camera of ``cameras``; ``object`` and ``object_mesh`` (an object's
#: motion and surface) add the hand's penetration of it to the metrics. A take whose ``object`` settings name an
#: object's ``markers`` (or an ``articulated`` description) has the object tracked from its own markers, and that
#: motion goes to the metrics instead of ``object``.
_CALIBRATION = ("calibration", "attachment", "calibration_take", "truth", "layout", "object", "object_mesh")
KINDS = {"images": (("images", "cameras", "pattern"), _CALIBRATION),
         "detections": (("detections", "cameras"), _CALIBRATION),
         "markers": (("markers",), _CALIBRATION),
         "keypoints": (("keypoints",), ("truth",))}
KIND_STAGES = {"images": ("detect", "triangulate", "clean", "calibrate", "solve", "object", "metrics", "report"),
               "detections": ("triangulate", "clean", "calibrate", "solve", "object", "metrics", "report"),
               "markers": ("calibrate", "solve", "object", "metrics", "report"),
               "keypoints": ("fit", "metrics", "report")}
#: Inputs that name something other than a file.
NAMES = ("layout", "calibration_take")
#: Inputs that are folders.
FOLDERS = ("images",)
_NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9._-]*$")


@dataclass(frozen=True)
class Take:
    """One take of a session: its name (a folder name under the results), kind, input paths, layout, the
    take whose markers calibrate it (``calibration_take``; the take itself when another take names it so and it
    has no calibration of its own) and its own stage settings over the session's (``[takes.settings.STAGE]``)."""

    name: str
    kind: str
    inputs: dict = field(default_factory=dict)
    layout: str | None = None
    calibration_take: str | None = None
    settings: dict = field(default_factory=dict)


@dataclass(frozen=True)
class Session:
    """A parsed session file.

    Attributes
    ----------
    path : Path
    name : str
    results : Path
    stages : tuple of str
    settings : dict of str to dict
        Per stage.
    takes : tuple of Take
    """

    path: Path
    name: str
    results: Path
    stages: tuple
    settings: dict
    takes: tuple


_KIND_NAMES = {str: "a string", float: "a number", int: "an integer", bool: "true or false"}


def _typed(value, kind, where):
    if kind is float and isinstance(value, int) and not isinstance(value, bool):
        return float(value)
    if not isinstance(value, kind) or (kind is int and isinstance(value, bool)):
        raise HandcapError(f"{where} must be {_KIND_NAMES[kind]}, got {value!r}")
    return value


def _settings(raw, where: str) -> dict:
    """Stage settings ``{stage: {key: value}}`` checked against :data:`STAGES` (numbers made floats where wanted)."""
    if not isinstance(raw, dict):
        raise HandcapError(f"{where} must be tables of settings ([stages.solve] ...)")
    settings = {}
    for stage, values in raw.items():
        if stage not in STAGES:
            raise HandcapError(f"{where}.{stage}: unknown stage (choose from {', '.join(STAGES)})")
        if not isinstance(values, dict):
            raise HandcapError(f"{where}.{stage} must be a table of settings")
        settings[stage] = {}
        for key, value in values.items():
            if key not in STAGES[stage]:
                known = ", ".join(STAGES[stage]) or "none"
                raise HandcapError(f"{where}.{stage}.{key} is not a setting of {stage} ({known})")
            settings[stage][key] = _typed(value, STAGES[stage][key], f"{where}.{stage}.{key}")
            if key == "sync" and value != "auto":
                try:
                    parse_offsets(value)
                except HandcapError as error:
                    raise HandcapError(f"{where}.{stage}.sync is \"auto\" or offsets; {error}") from None
            if key == "response" and value not in RESPONSES:
                raise HandcapError(f"{where}.{stage}.response is one of {', '.join(RESPONSES)}, got {value!r}")
    return settings


def _shipped_or_file(name: str, path: Path, where: str, key: str = "layout") -> str:
    """A shipped layout's (or articulated object's, ``key``) name as it is; any other a file, relative to the
    session file, that must exist."""
    shipped, what = (SHIPPED, "layout") if key == "layout" else (ARTICULATED, "articulated object")
    if name in shipped:
        return name
    file = path.parent / name
    if not file.is_file():
        raise HandcapError(f"{where}.{key} {name!r}: neither a shipped {what} ({', '.join(shipped)}) nor a "
                           f"{what} file (no such file {file})")
    return str(file)


def _files_in(settings: dict, path: Path, where: str) -> dict:
    """``settings`` with their layout and articulated object resolved (:func:`_shipped_or_file`)."""
    for stage, key in (("calibrate", "layout"), ("object", "articulated")):
        if key in settings.get(stage, {}):
            settings[stage][key] = _shipped_or_file(settings[stage][key], path, f"{where}.{stage}", key)
    if "canonical" in settings.get("object", {}):  # the object's markers in its mesh's frame: a file
        file = path.parent / settings["object"]["canonical"]
        if not file.is_file():
            raise HandcapError(f"{where}.object.canonical: no such file {file}")
        settings["object"]["canonical"] = str(file)
    return settings


def load_session(path) -> Session:
    """Read and check a session file.

    Parameters
    ----------
    path : str or Path

    Returns
    -------
    Session

    Raises
    ------
    HandcapError
        One line naming the file and the key: a missing file, bad TOML, an unknown table, stage, kind or
        setting, a value of the wrong type, a missing input file, a take without calibration or attachment,
        or two takes of one name.
    """
    path = Path(path)
    if not path.is_file():
        raise HandcapError(f"{path}: no such session file (handcap session new DIR writes an example)")
    try:
        table = tomllib.loads(path.read_text(encoding="utf-8"))
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as err:
        raise HandcapError(f"{path}: not TOML ({' '.join(str(err).split())[:100]})") from None
    unknown = set(table) - {"session", "stages", "takes"}
    if unknown:
        raise HandcapError(f"{path}: unknown table {sorted(unknown)[0]!r} (session, stages and takes are known)")
    head = table.get("session", {})
    if not isinstance(head, dict):
        raise HandcapError(f"{path}: session must be a table ([session])")
    for key in set(head) - {"name", "results", "stages"}:
        raise HandcapError(f"{path}: session.{key} is not a setting (name, results, stages)")
    name = _typed(head.get("name", path.parent.name), str, f"{path}: session.name")
    results = path.parent / _typed(head.get("results", "results"), str, f"{path}: session.results")
    stages = head.get("stages", list(STAGES))
    if not isinstance(stages, list) or not stages:
        raise HandcapError(f"{path}: session.stages must be a list of stages ({', '.join(STAGES)})")
    for stage in stages:
        if stage not in STAGES:
            raise HandcapError(f"{path}: session.stages: unknown stage {stage!r} (choose from {', '.join(STAGES)})")
    raw = table.get("stages", {})
    settings = _files_in(_settings(raw, f"{path}: stages"), path, f"{path}: stages")
    takes, seen = [], set()
    raw_takes = table.get("takes", [])
    if not isinstance(raw_takes, list) or not raw_takes:
        raise HandcapError(f"{path}: no [[takes]]")
    for k, raw_take in enumerate(raw_takes):
        where = f"{path}: takes[{k}]"
        if not isinstance(raw_take, dict):
            raise HandcapError(f"{where} must be a table")
        label = _typed(raw_take.get("name", ""), str, f"{where}.name")
        if not _NAME.match(label) or label in seen:
            raise HandcapError(f"{where}.name {label!r}: give each take a unique name of letters, digits, . _ -")
        seen.add(label)
        kind = raw_take.get("kind", "markers")
        if kind not in KINDS:
            raise HandcapError(f"{where}.kind {kind!r}: the runner knows {', '.join(KINDS)} takes so far")
        required, optional = KINDS[kind]
        for key in set(raw_take) - {"name", "kind", "settings", *required, *optional}:
            raise HandcapError(f"{where}.{key} is not an input of a {kind} take ({', '.join(required + optional)})")
        inputs = {}
        for key in required + tuple(k for k in optional if k in raw_take and k not in NAMES):
            if key not in raw_take:
                raise HandcapError(f"{where}.{key} is missing: a {kind} take needs it")
            file = path.parent / _typed(raw_take[key], str, f"{where}.{key}")
            if key in FOLDERS and not file.is_dir():
                raise HandcapError(f"{where}.{key}: no such folder {file} (one sub-folder or video per camera)")
            if key not in FOLDERS and not file.is_file():
                raise HandcapError(f"{where}.{key}: no such file {file}")
            inputs[key] = file
        named = {k: _typed(raw_take[k], str, f"{where}.{k}") for k in NAMES if k in raw_take}
        if "layout" in named:
            named["layout"] = _shipped_or_file(named["layout"], path, where)
        own = _files_in(_settings(raw_take.get("settings", {}), f"{where}.settings"), path, f"{where}.settings")
        for table, table_name in ((settings.get("object", {}), f"{path}: stages.object"),
                                  (own.get("object", {}), f"{where}.settings.object")):
            if {"markers", "articulated"} <= set(table):
                raise HandcapError(f"{table_name} has both markers and articulated; give one (a rigid object's "
                                   f"markers, or an articulated object's description)")
        if own.get("object") and kind == "keypoints":
            raise HandcapError(f"{where}.settings.object: a keypoints take has no object markers to track")
        takes.append(Take(label, kind, inputs, named.get("layout"), named.get("calibration_take"), own))
    sources = {t.calibration_take for t in takes} - {None}
    by_name = {t.name: t for t in takes}
    for k, take in enumerate(takes):
        where = f"{path}: takes[{k}]"
        other = by_name.get(take.calibration_take)
        if take.calibration_take is not None and (other is None or other.kind == "keypoints"):
            raise HandcapError(f"{where}.calibration_take {take.calibration_take!r}: name another markers or images "
                               f"take of this session")
        if other is not None and other.calibration_take not in (None, other.name):
            raise HandcapError(f"{where}.calibration_take {take.calibration_take!r}: that take is calibrated by "
                               f"{other.calibration_take!r}; name the calibration take itself")
    for k, take in enumerate(takes):
        where = f"{path}: takes[{k}]"
        if (take.kind != "keypoints" and "solve" in stages and take.name not in sources
                and not ({"calibration", "attachment"} & set(take.inputs)) and take.calibration_take is None):
            raise HandcapError(f"{where}: give calibration (a calibration take's markers), calibration_take (a take "
                               f"of this session) or attachment (an .npz) to solve")
    return Session(path, name, results, tuple(s for s in STAGES if s in stages), settings, tuple(takes))
