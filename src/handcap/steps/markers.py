"""Steps on marker files: ``convert`` to another format, ``corrupt`` (a labeling test) and ``fill`` gaps."""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from handcap.io import check_not_input, check_output, read_markers, write_markers
from handcap.labeling import corrupt as corrupt_labels
from handcap.layouts import load_layout
from handcap.occlusion import fill_gaps
from handcap.occlusion.history import HISTORY_S
from handcap.quality import plausibility as q
from handcap.steps.step import Step


def convert(path, out, *, partial: bool = False, units: str | None = None) -> Step:
    """Convert a marker file to another format (chosen by ``out``'s extension), its warnings stored with it.

    Parameters
    ----------
    path, out : str or Path
        Marker files (.c3d .tsv .csv .txt .trc .npz in; .c3d .trc .npz out); ``out`` must not be ``path``.
    partial : bool
        C3D: keep the complete frames of a file shorter than its header promises.
    units : {'mm', 'cm', 'm'} or None
        Unit of the input's coordinates, overriding what the file says.
    """
    check_output(out, path)
    markers = read_markers(path, partial=partial, units=units)
    markers = q.attach(markers, q.marker_warnings(markers))  # stored in the output (.npz, .c3d) as well
    write_markers(markers, out)
    line = q.summary(f"{out}: {markers.n_frames} frames, {markers.n_markers} markers at {markers.rate:g} Hz",
                     q.marker_figures(markers), markers.warnings)
    return Step((line,), markers.warnings, (str(out),), markers)


def corrupt(path, out, *, ghost_rate: float = 2.0, dropout: float = 0.05, seed: int = 0, layout: str | None = None,
            units: str | None = None) -> Step:
    """A labeling test from a labeled take: unlabeled points to ``out``, the truth beside it as ``NAME.truth.EXT``.

    Parameters
    ----------
    path, out : str or Path
        The labeled take, and the unlabeled points to write (.c3d .trc .npz).
    ghost_rate : float
        Ghost markers per second.
    dropout : float
        Extra fraction of samples dropped, in [0, 1).
    seed : int
        Seed of the shuffling, ghosts and dropouts.
    layout : str or None
        Keep only this layout's markers (a shipped name or a .toml file).
    units : {'mm', 'cm', 'm'} or None
        Unit of the input's coordinates, overriding what the file says.
    """
    out = Path(out)
    truth_path = out.with_name(out.stem + ".truth" + out.suffix)
    check_not_input(out, path)
    check_not_input(truth_path, path)
    markers = read_markers(path, units=units)
    names = None if layout is None else load_layout(layout).names
    unlabeled, truth = corrupt_labels(markers, ghost_rate=ghost_rate, dropout=dropout, seed=seed, names=names)
    write_markers(unlabeled, out)
    write_markers(truth, truth_path)
    extra = int(np.isfinite(unlabeled.positions[..., 0]).sum() - np.isfinite(truth.positions[..., 0]).sum())
    line = f"{out}: {unlabeled.n_frames} frames of unlabeled points ({extra} ghost samples); truth in {truth_path}"
    return Step((line,), (), (str(out), str(truth_path)), unlabeled)


def fill(path, out, *, method: str = "nn", model=None, max_gap_s: float = 0.5, units: str | None = None,
         history_s: float = HISTORY_S) -> Step:
    """Fill the gaps of a recorded take up to ``max_gap_s`` seconds (see :func:`handcap.occlusion.fill_gaps`).

    Parameters
    ----------
    path, out : str or Path
        Labeled markers in, filled markers out (.c3d .trc .npz).
    method : str
        One of :data:`handcap.occlusion.FILL_METHODS`.
    model : str, Path or None
        Occlusion model .npz, or a shipped one's name (method ``nn``).
    max_gap_s : float
        Longest gap to fill, seconds; longer ones stay missing.
    units : {'mm', 'cm', 'm'} or None
        Unit of the input's coordinates, overriding what the file says.
    history_s : float
        Seconds before a gap from which ``nn`` learns its error (:mod:`handcap.occlusion.history`).
    """
    check_not_input(out, path, *([model] if model else []))
    markers = read_markers(path, units=units)
    start = time.perf_counter()
    filled, report = fill_gaps(markers, method, max_gap_s=max_gap_s, model=model, history_s=history_s)
    seconds = time.perf_counter() - start
    write_markers(filled, out)
    line = (f"{out}: {report.filled_samples} samples in {report.filled_gaps} gaps filled ({method}, gaps up to "
            f"{report.max_gap_frames} frames = {max_gap_s:g} s), "
            f"{report.left_gaps} gaps ({report.left_samples} samples) left missing, {seconds:.1f} s"
            + (f"; not in the model, left as they were: {', '.join(report.untouched)}" if report.untouched else ""))
    return Step((line,), filled.warnings, (str(out),), filled)
