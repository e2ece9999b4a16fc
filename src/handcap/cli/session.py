"""``handcap process`` and ``handcap session new``."""

from __future__ import annotations

from handcap.session import commands as session


def _cmd_process(a):
    return session.run_session(a.session, dry_run=a.dry_run, scheduler=a.scheduler, workers=a.workers)


def _cmd_session_new(a):
    return session.session_new(a.folder, images=not a.no_images)


def add_session(verbs) -> None:
    p = verbs.add_parser("process", help="run every stage of every take of a session file (resumable)",
                         description="Runs the stages of each take (images: detect, triangulate, clean; then "
                                     "calibrate, solve or fit, metrics, report) into "
                                     "RESULTS/<take>/, each output written atomically with a manifest of its "
                                     "settings, input hashes and version; a stage whose manifest matches is "
                                     "skipped, so a killed run resumes and an edited setting reruns only what "
                                     "depends on it. The session file's format: handcap.session.spec.")
    p.add_argument("session", help="session.toml")
    p.add_argument("--dry-run", action="store_true", help="print the plan: what would run, what is up to date")
    p.add_argument("--scheduler", metavar="ADDRESS", help="a Dask scheduler (tcp://HOST:PORT); default local processes")
    p.add_argument("--workers", type=int, help="local processes running takes (default: 2)")
    p.set_defaults(run=_cmd_process)

    p = verbs.add_parser("session", help="write an example session (session new DIR)",
                         description="session new DIR: a commented session.toml with takes of each kind made in DIR "
                                     "(a calibration take and two grasp takes of markers, a take of 3D hand "
                                     "keypoints, two filmed takes of coded patches), so that handcap process "
                                     "DIR/session.toml runs at once.")
    p.add_argument("action", choices=("new",))
    p.add_argument("folder")
    p.add_argument("--no-images", action="store_true",
                   help="leave out the filmed takes (filming needs the extra 'images' and headless OpenGL)")
    p.set_defaults(run=_cmd_session_new)
