"""What a result folder holds, gathered for a report: the hand motion, the markers it was solved from, the
truth of a synthetic take, object motions, metrics and settings (``handcap report``, issue 19).

Files are recognised by what they contain, not by their names: every ``.npz`` is tried as a hand motion, then
as an object motion, then as markers; ``.c3d``/``.trc`` are markers; ``scene.toml`` and other ``.toml`` files
are settings; ``.json`` files are metrics. A synthetic take's ``truth.npz`` is a hand motion too: it is the
truth when another hand motion is present.
"""

from __future__ import annotations

import json
import tomllib
from dataclasses import dataclass, field
from pathlib import Path

from handcap.core.errors import HandcapError
from handcap.io import read_hand_motion, read_markers, read_object_motion


@dataclass
class TakeFiles:
    """A result folder's contents.

    Attributes
    ----------
    folder : Path
    motion, truth : HandMotion or None
        The solved hand, and the synthetic truth (``truth.npz``) when there is a solved hand besides.
    markers : MarkerSequence or None
        The labelled markers (``markers.c3d`` first, else the first marker file).
    objects : dict of str to ObjectMotion
    metrics : dict
        From the ``.json`` files, merged.
    settings : dict of str to str
        Each settings file's text.
    paths : dict of str to str
        What was read from which file.
    """

    folder: Path
    motion: object = None
    truth: object = None
    markers: object = None
    objects: dict = field(default_factory=dict)
    metrics: dict = field(default_factory=dict)
    settings: dict = field(default_factory=dict)
    paths: dict = field(default_factory=dict)


def read_take(folder) -> TakeFiles:
    """Gather a result folder (see the module docstring).

    Parameters
    ----------
    folder : str or Path

    Returns
    -------
    TakeFiles

    Raises
    ------
    HandcapError
        Not a folder, or no hand motion in it.
    """
    folder = Path(folder)
    if not folder.is_dir():
        raise HandcapError(f"{folder}: not a folder of results")
    take = TakeFiles(folder)
    hands, marker_files = {}, {}
    for path in sorted(folder.iterdir()):
        suffix = path.suffix.lower()
        if suffix == ".npz":
            for reader, kind in ((read_hand_motion, "hand"), (read_object_motion, "object"), (read_markers, "markers")):
                try:
                    value = reader(path)
                except HandcapError:
                    continue
                if kind == "hand":
                    hands[path.name] = value
                elif kind == "object":
                    take.objects[path.stem] = value
                    take.paths[f"object {path.stem}"] = path.name
                else:
                    marker_files[path.name] = value
                break
        elif suffix in (".c3d", ".trc"):
            try:
                marker_files[path.name] = read_markers(path)
            except HandcapError:
                continue
        elif suffix == ".toml":
            text = path.read_text(errors="replace")
            try:
                tomllib.loads(text)
            except tomllib.TOMLDecodeError:
                continue
            take.settings[path.name] = text
        elif suffix == ".json" and not path.name.endswith(".manifest.json"):
            try:
                values = json.loads(path.read_text())
            except (json.JSONDecodeError, UnicodeDecodeError):
                continue
            if isinstance(values, dict):
                take.metrics.update(values)
                take.paths["metrics"] = path.name
    if not hands:
        raise HandcapError(f"{folder}: holds no hand motion (.npz written by handcap solve)")
    solved = [name for name in hands if name != "truth.npz"]
    name = solved[0] if solved else "truth.npz"
    take.motion, take.paths["hand motion"] = hands[name], name
    if solved and "truth.npz" in hands:
        take.truth, take.paths["truth"] = hands["truth.npz"], "truth.npz"
    if marker_files:
        pick = "markers.c3d" if "markers.c3d" in marker_files else next(iter(marker_files))
        take.markers, take.paths["markers"] = marker_files[pick], pick
    return take
