"""``handcap report``: a self-contained HTML page of a take's (or a session's) results."""

from __future__ import annotations

from handcap.core.errors import HandcapError
from handcap.steps import report


def _cmd_report(a):
    if not str(a.out).lower().endswith((".html", ".htm")):
        raise HandcapError(f"{a.out}: the report is an .html file")
    return report.report(a.folder, a.out)


def add_report(verbs) -> None:
    p = verbs.add_parser("report", help="an HTML page of a take's results (3D view, residuals, gaps, figures)",
                         description="One self-contained HTML file that opens offline: an interactive 3D view of "
                                     "the skeleton, markers and objects over time, the per-marker residuals and the "
                                     "gaps over time, the joint angles, the quality figures, the warnings and the "
                                     "settings. A folder of take folders gives a session page that links a page per "
                                     "take, written beside it. Needs the extra 'report' (plotly).")
    p.add_argument("folder", help="a take's result folder (hand motion .npz, markers, truth.npz, ...), or a session's")
    p.add_argument("--out", required=True, help="the .html page to write")
    p.set_defaults(run=_cmd_report)
