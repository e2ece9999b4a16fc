"""Sessions (issue 19): a session file names the takes and the stages' settings (:mod:`~handcap.session.spec`);
:func:`~handcap.session.runner.process` runs every stage of every take, resumable through manifests;
:mod:`~handcap.session.example` writes a session with synthetic takes to start from."""

from handcap.session.runner import StageRun, process, summary
from handcap.session.spec import STAGES, Session, load_session

__all__ = ["STAGES", "Session", "StageRun", "load_session", "process", "summary"]
