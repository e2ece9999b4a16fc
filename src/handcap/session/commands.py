"""``process`` (run a session) and ``session new`` (write an example session) as steps for the command line.

They live here, not in :mod:`handcap.steps`: the session runner chains the steps, so it sits above them."""

from __future__ import annotations

from handcap.session.example import new_session
from handcap.session.runner import process, summary
from handcap.session.spec import load_session
from handcap.steps.step import Step


def run_session(path, *, dry_run: bool = False, scheduler=None, workers: int | None = None) -> Step:
    """Run a session file (see :func:`handcap.session.runner.process`).

    Parameters
    ----------
    path : str or Path
        ``session.toml``.
    dry_run : bool
        Only print the plan.
    scheduler, workers
        Dask scheduler address; local processes.
    """
    session = load_session(path)
    runs = process(session, dry_run=dry_run, scheduler=scheduler, workers=workers)
    said: dict = {}  # a warning that a take's later stages carry on (the calibration's in solve and metrics): once
    for r in runs:
        for w in r.warnings:
            said.setdefault((r.take, w), f"{r.take} {r.stage}: {w}")
    warnings = tuple(said.values())
    done = sum(r.status == "done" for r in runs)
    head = (f"{session.path}: plan of {len(session.takes)} takes" if dry_run else
            f"{session.path}: {done} stages run, {sum(r.status == 'skipped' for r in runs)} up to date, "
            f"results in {session.results}")
    return Step((head, summary(runs)), warnings, tuple(r.output for r in runs if r.status == "done"), runs)


def session_new(folder, *, images: bool = True) -> Step:
    """Write an example session with synthetic takes into ``folder`` (see :func:`new_session`).

    Parameters
    ----------
    folder : str or Path
    images : bool
        Film the takes of coded patches too.
    """
    written = new_session(folder, images=images)
    return Step((f"{written[-1]}: a session of synthetic takes; run handcap process {written[-1]}",), (),
                tuple(written), None)
