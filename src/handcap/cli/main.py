"""The ``handcap`` command. Every verb has ``--help``; user mistakes exit with code 2."""

from __future__ import annotations

import argparse
import os
import sys
import warnings

from handcap.cli.calibrate import add_calibrate
from handcap.cli.convert import add_convert
from handcap.cli.detect import add_detect, add_overlay
from handcap.cli.export import add_export
from handcap.cli.label import add_label
from handcap.cli.layout import add_layout
from handcap.cli.markerless import add_markerless
from handcap.cli.multiview import add_clean, add_multiview
from handcap.cli.objects import add_objects
from handcap.cli.occlusion import add_occlusion
from handcap.cli.pattern import add_pattern
from handcap.cli.report import add_report
from handcap.cli.session import add_session
from handcap.cli.stream import add_stream
from handcap.cli.solve import add_solve
from handcap.cli.synth import add_synth
from handcap import __version__
from handcap.core.errors import HandcapError, HandcapWarning, merge_warnings


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="handcap", description=__doc__)
    parser.add_argument("--version", action="version", version=_version())
    parser.add_argument("--strict", action="store_true",
                        help="exit with code 2 when the result carries a warning (implausible figures, guessed "
                             "units); the output is still written")
    verbs = parser.add_subparsers(dest="verb", metavar="VERB")
    verbs.required = True

    add_convert(verbs)
    add_synth(verbs)
    add_solve(verbs)
    add_objects(verbs)
    add_label(verbs)
    add_occlusion(verbs)
    add_multiview(verbs)
    add_clean(verbs)
    add_calibrate(verbs)
    add_layout(verbs)
    add_pattern(verbs)
    add_detect(verbs)
    add_overlay(verbs)
    add_markerless(verbs)
    add_export(verbs)
    add_report(verbs)
    add_session(verbs)
    add_stream(verbs)
    return parser


def verb_parsers() -> dict:
    """Every verb's parser, by name, in the order ``handcap --help`` lists them (for the docs pages)."""
    parser = build_parser()
    action = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    return dict(action.choices)


def _version() -> str:
    return f"handcap {__version__}"


def main(argv=None) -> int:
    """Run one verb. Exit codes: 0 done, 2 user error (or a warning with ``--strict``), 130 interrupted.

    A verb's ``_cmd_`` function calls a step of :mod:`handcap.steps` and returns its
    :class:`~handcap.steps.step.Step`: the summary is printed on stdout, the warnings of the result it wrote
    (one-line strings) on stderr as ``handcap VERB: warning: ...``, once each.
    """
    parser = build_parser()
    args = parser.parse_args(argv)
    # FFmpeg, under OpenCV's video reader, prints its own errors ("moov atom not found") beside the one line that
    # says which file could not be read; quiet unless the user set a level (read when the first video opens).
    os.environ.setdefault("OPENCV_FFMPEG_LOGLEVEL", "-8")
    try:
        # Every HandcapWarning the library issues is caught here and printed once, with those the verb returns
        # (the ones stored in its output); Python's own display of them would repeat each line.
        with warnings.catch_warnings(record=True) as issued:
            warnings.simplefilter("always", HandcapWarning)
            done = args.run(args)
            if done.lines:
                print(done.summary())
        issued_lines = [str(w.message) for w in issued if issubclass(w.category, HandcapWarning)]
        # a line the verb returns with its context ("take1 solve: ...") is not said again bare
        told = [" ".join(str(w).split()) for w in done.warnings]
        issued_lines = [line for line in issued_lines
                        if not any(w.endswith(": " + " ".join(line.split())) for w in told)]
        found = merge_warnings(done.warnings, issued_lines)
        for w in issued:
            if not issubclass(w.category, HandcapWarning):
                warnings.showwarning(w.message, w.category, w.filename, w.lineno)
        for line in found:
            print(f"handcap {args.verb}: warning: {line}", file=sys.stderr)
        sys.stdout.flush()
    except HandcapError as err:
        # One line, whatever the message quotes (an array's repr spans several).
        print(f"handcap {args.verb}: error: {' '.join(str(err).split())}", file=sys.stderr)
        return 2
    except BrokenPipeError:
        # The reader of our output went away (``handcap ... | head``): not an error of ours. Point stdout at
        # devnull so the interpreter's final flush does not raise again.
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 0
    except KeyboardInterrupt:
        print("handcap: interrupted", file=sys.stderr)
        return 130
    if found and args.strict:
        print(f"handcap {args.verb}: error: {len(found)} warning(s) and --strict given", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
