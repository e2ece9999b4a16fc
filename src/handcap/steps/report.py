"""Step ``report``: the self-contained HTML page of a take's results, or of a session's takes."""

from __future__ import annotations

from handcap.report.html import write_report
from handcap.steps.step import Step


def report(folder, out) -> Step:
    """Write the report of a result folder (see :func:`handcap.report.html.write_report`).

    Parameters
    ----------
    folder : str or Path
        A take's results (hand motion, markers, truth, objects, metrics, settings), or a folder of takes.
    out : str or Path
        The ``.html`` page to write.

    Returns
    -------
    Step
    """
    written = write_report(folder, out)
    line = f"{written[0]}: report of {folder}" + (f" and its {len(written) - 1} takes" if len(written) > 1 else "")
    return Step((line,), (), tuple(written), None)
