"""Self-contained HTML reports (``handcap report``, issue 19): one page per take, and one per session.

A take's page holds an interactive 3D view of the solved skeleton, the markers and the objects over time (a
slider and a play button), the per-marker residuals and the gaps over time, the joint angles, the quality
figures, every warning and the settings. The figures are plotly's; the page carries plotly.js itself (from
the plotly package, once per page), so it opens offline, with no server and no network. A session's page
lists its takes with their key figures and links to each take's page, written beside it.
"""

from __future__ import annotations

import html
import math
from pathlib import Path

import numpy as np

from handcap.core.errors import HandcapError
from handcap.core.files import atomic_output
from handcap.hand.anatomy import JOINT_NAMES, PARENTS, PHI_NAMES, TIP_NAMES, TIP_PARENTS
from handcap.report.metrics import PAPER_COLUMNS, PAPER_NOTE, metrics_table, motion_metrics, paper_rows
from handcap.report.take import TakeFiles, read_take

#: Most frames the 3D view animates (longer takes are subsampled evenly).
VIEW_FRAMES = 150
_BONES = [(int(p), j) for j, p in enumerate(PARENTS) if p >= 0] + [(int(p), 16 + k) for k, p in enumerate(TIP_PARENTS)]
_STYLE = ("body{font-family:system-ui,sans-serif;margin:24px;max-width:1200px;color:#222}"
          "table{border-collapse:collapse}td,th{border:1px solid #ccc;padding:3px 8px;text-align:left}"
          "pre{background:#f5f5f5;padding:8px;overflow:auto}.warn{color:#a40}")


def _plotly():
    """plotly's graph objects and its io module."""
    try:
        import plotly.graph_objects as go  # noqa: PLC0415 (optional extra 'report', loaded only when used)
        import plotly.io as pio  # noqa: PLC0415
    except ImportError:
        raise HandcapError("handcap report needs plotly: pip install 'handcap[report]'") from None
    return go, pio


def _bones(joints) -> np.ndarray:
    """Line segments of the skeleton, (3 * bones, 3) with NaN breaks, for one frame's joints (21, 3)."""
    out = np.full((3 * len(_BONES), 3), np.nan)
    for k, (a, b) in enumerate(_BONES):
        out[3 * k], out[3 * k + 1] = joints[a], joints[b]
    return out


def view_figure(take: TakeFiles) -> dict:
    """The take's 3D view: the skeleton, markers and objects over time, with a slider and a play button.

    The layout and the first frame are built (and checked) by plotly; the animation's frames are plain dicts,
    since checking :data:`VIEW_FRAMES` frames of traces took ten times as long as everything else on the page.

    Parameters
    ----------
    take : TakeFiles
        From :func:`handcap.report.take.read_take`; its hand motion needs joints.

    Returns
    -------
    dict
        A plotly figure (``data``, ``layout``, ``frames``); positions in millimetres, rounded to 0.01.
    """
    go, _ = _plotly()
    motion = take.motion
    joints = motion.joints
    step = max(1, math.ceil(motion.n_frames / VIEW_FRAMES))
    frames = list(range(0, motion.n_frames, step))
    clouds = []
    if take.markers is not None and take.markers.n_frames == motion.n_frames:
        clouds.append(("markers", take.markers.positions, "#1f77b4"))
    for name, om in take.objects.items():
        if om.n_frames == motion.n_frames:
            clouds.append((name, om.transform_points(om.canonical), "#2ca02c"))

    def traces(t):
        bones = np.round(_bones(joints[t]) * 1000, 2)
        out = [{"type": "scatter3d", "x": bones[:, 0], "y": bones[:, 1], "z": bones[:, 2], "mode": "lines+markers",
                "name": "skeleton", "line": {"color": "#d62728", "width": 5}, "marker": {"size": 2}}]
        for name, points, colour in clouds:
            p = np.round(points[t] * 1000, 2)
            out.append({"type": "scatter3d", "x": p[:, 0], "y": p[:, 1], "z": p[:, 2], "mode": "markers", "name": name,
                        "marker": {"size": 3, "color": colour}})
        return out

    every = np.concatenate([joints.reshape(-1, 3)] + [c[1].reshape(-1, 3) for c in clouds]) * 1000
    every = every[np.isfinite(every).all(axis=1)]
    lo, hi = every.min(axis=0), every.max(axis=0)
    axes = {a: {"range": [float(lo[i]) - 10, float(hi[i]) + 10], "title": f"{a} (mm)"} for i, a in
            enumerate("xyz")}
    fig = go.Figure(data=traces(frames[0]))
    fig.update_layout(
        title="3D view (millimetres)", height=650,
        scene={"xaxis": axes["x"], "yaxis": axes["y"], "zaxis": axes["z"], "aspectmode": "data"},
        updatemenus=[{"type": "buttons", "showactive": False, "buttons": [
            {"label": "play", "method": "animate",
             "args": [None, {"frame": {"duration": 1000 * step / motion.rate, "redraw": True}, "fromcurrent": True}]},
            {"label": "pause", "method": "animate", "args": [[None], {"mode": "immediate"}]}]}],
        sliders=[{"currentvalue": {"prefix": "frame "}, "steps": [
            {"label": str(t), "method": "animate", "args": [[str(t)], {"mode": "immediate"}]} for t in frames]}])
    return {**fig.to_dict(), "frames": [{"data": traces(t), "name": str(t)} for t in frames]}


def _time_plots(go, take: TakeFiles) -> list:
    motion = take.motion
    time = np.arange(motion.n_frames) / motion.rate
    figs = []
    if motion.marker_residuals is not None and len(motion.marker_names):
        fig = go.Figure(go.Heatmap(z=motion.marker_residuals.T * 1000, x=time, y=list(motion.marker_names),
                                   colorscale="Viridis", colorbar={"title": "mm"}))
        fig.update_layout(title="Marker residuals over time (model to marker, mm)", xaxis_title="time (s)",
                          height=max(300, 14 * len(motion.marker_names) + 120))
        figs.append(fig)
    if take.markers is not None:
        seen = np.isfinite(take.markers.positions).all(axis=2).astype(float)
        fig = go.Figure(go.Heatmap(z=seen.T, x=np.arange(take.markers.n_frames) / take.markers.rate,
                                   y=list(take.markers.names), colorscale=[[0, "#e45756"], [1, "#eeeeee"]],
                                   showscale=False))
        fig.update_layout(title=f"Gaps: where each marker of {take.paths['markers']} is missing (red)",
                          xaxis_title="time (s)", height=max(300, 14 * len(take.markers.names) + 120))
        figs.append(fig)
    if motion.phi is not None:
        fig = go.Figure([go.Scatter(x=time, y=np.rad2deg(motion.phi[:, k]), name=name, mode="lines",
                                    visible=True if "bend" in name else "legendonly")
                         for k, name in enumerate(PHI_NAMES)])
        fig.update_layout(title="Joint angles (degrees; click the legend for the others)", xaxis_title="time (s)",
                          height=450)
        figs.append(fig)
    return figs


def _table(rows) -> str:
    return "<table>" + "".join(f"<tr><th>{html.escape(str(k))}</th><td>{html.escape(str(v))}</td></tr>"
                               for k, v in rows) + "</table>"


def _figures_of(take: TakeFiles) -> dict:
    if take.metrics:
        return take.metrics
    folder = take.folder
    try:
        return motion_metrics(folder / take.paths["hand motion"],
                              truth=folder / take.paths["truth"] if take.truth is not None else None,
                              markers=folder / take.paths["markers"] if take.markers is not None else None)
    except HandcapError as err:
        return {"metrics": f"not computed: {err}"}


def take_page(take: TakeFiles, title: str | None = None, figures: dict | None = None) -> str:
    """The HTML page of one take.

    Parameters
    ----------
    take : TakeFiles
        From :func:`handcap.report.take.read_take`; its hand motion needs joints.
    title : str, optional
        Default: the folder's name.
    figures : dict, optional
        The take's quality figures, when the caller has them (default: its metrics JSON, else computed).

    Returns
    -------
    str
    """
    go, pio = _plotly()
    motion = take.motion
    if motion.joints is None:
        raise HandcapError(f"{take.folder / take.paths['hand motion']}: has no joints; solve it with handcap solve")
    title = title or take.folder.name
    figures = _figures_of(take) if figures is None else figures
    warnings = list(dict.fromkeys([*motion.warnings, *(take.markers.warnings if take.markers is not None else ()),
                                   *(w for om in take.objects.values() for w in om.warnings),
                                   *figures.get("warnings", ())]))
    parts = [f"<!doctype html><html><head><meta charset='utf-8'><title>{html.escape(title)}</title>"
             f"<style>{_STYLE}</style></head><body><h1>{html.escape(title)}</h1>",
             _table([("frames", motion.n_frames), ("rate (Hz)", f"{motion.rate:g}"), ("side", motion.side),
                     ("hand model", motion.model), ("joints", ", ".join(JOINT_NAMES + TIP_NAMES))]
                    + [(k, v) for k, v in take.paths.items()])]
    plots = [view_figure(take), *_time_plots(go, take)]
    for k, fig in enumerate(plots):  # the view's frames are unchecked dicts (view_figure)
        parts.append(pio.to_html(fig, full_html=False, include_plotlyjs=(k == 0), auto_play=False, validate=False))
    table = metrics_table(figures) if any(k in figures for k in ("msnr_db", "mre_mm")) else ""
    parts.append("<h2>Quality</h2>" + (f"<pre>{html.escape(table)}</pre>" if table else
                                        _table((k, v) for k, v in figures.items() if k != "warnings")))
    rows = paper_rows(figures)
    if rows:
        head = "".join(f"<th>{html.escape(c)}</th>" for c in ("", "this take", *PAPER_COLUMNS))
        body = "".join("<tr>" + "".join(f"<td>{html.escape(c)}</td>" for c in row) + "</tr>" for row in rows)
        parts.append(f"<h3>Against the published figures</h3><table class='paper'><tr>{head}</tr>{body}</table>"
                     f"<p>{html.escape(PAPER_NOTE)}</p>")
    parts.append("<h2>Warnings</h2>" + ("<ul>" + "".join(f"<li class='warn'>{html.escape(w)}</li>" for w in warnings)
                                        + "</ul>" if warnings else "<p>none</p>"))
    parts.append("<h2>Settings</h2>" + ("".join(f"<h3>{html.escape(n)}</h3><pre>{html.escape(t)}</pre>"
                                                for n, t in take.settings.items()) or "<p>none stored</p>"))
    parts.append("</body></html>")
    return "\n".join(parts)


def write_report(folder, out) -> list[str]:
    """Write the report of a take folder, or of a session folder (subfolders that are takes), to ``out``.

    Parameters
    ----------
    folder : str or Path
        A take's results, or a folder of takes' results.
    out : str or Path
        The page to write (``.html``); a session's take pages go beside it as ``<out stem>-<take>.html``.

    Returns
    -------
    list of str
        The pages written.

    Raises
    ------
    HandcapError
        A folder with no hand motion in it or in any subfolder.
    """
    folder, out = Path(folder), Path(out)
    try:
        take = read_take(folder)
    except HandcapError:
        take = None
    if take is not None:
        with atomic_output(out) as fh:
            fh.write(take_page(take).encode())
        return [str(out)]
    takes = []
    for sub in sorted(p for p in folder.iterdir() if p.is_dir()) if folder.is_dir() else []:
        try:
            takes.append(read_take(sub))
        except HandcapError:
            continue
    if not takes:
        raise HandcapError(f"{folder}: no hand motion in it or in its subfolders (solve the takes first)")
    written, rows = [], []
    for take in takes:
        page = out.with_name(f"{out.stem}-{take.folder.name}.html")
        figures = _figures_of(take)  # once: the page and the session's row both show them
        with atomic_output(page) as fh:
            fh.write(take_page(take, figures=figures).encode())
        written.append(str(page))
        mre = figures.get("mre_mm", ["", ""])[0]
        rows.append(f"<tr><td><a href='{html.escape(page.name)}'>{html.escape(take.folder.name)}</a></td>"
                    f"<td>{take.motion.n_frames}</td><td>{mre if mre == '' else f'{mre:.2f}'}</td>"
                    f"<td>{len(take.motion.warnings) + len(figures.get('warnings', ()))}</td></tr>")
    index = (f"<!doctype html><html><head><meta charset='utf-8'><title>{html.escape(folder.name)}</title>"
             f"<style>{_STYLE}</style></head><body><h1>Session {html.escape(folder.name)}</h1><table><tr><th>take"
             f"</th><th>frames</th><th>MRE (mm)</th><th>warnings</th></tr>{''.join(rows)}</table></body></html>")
    with atomic_output(out) as fh:
        fh.write(index.encode())
    return [str(out), *written]
