"""The one exception type a user of handcap needs to catch, and the warning for implausible results.

handcap never gives a silent wrong answer: a result that runs to the end but looks implausible (large
residuals, a lost hand frame, shape values at their bounds, a hand two kilometres wide) carries one-line
warnings. Library code calls :func:`warn`, which issues a :class:`HandcapWarning` through Python's
:mod:`warnings` machinery, and stores the same line on the result it returns (the containers'
``with_warnings``); the ``.npz`` files keep them under ``warnings``; the command line prints them and, with
``handcap --strict``, exits with code 2.
"""

from __future__ import annotations

import warnings as _warnings


class HandcapError(ValueError):
    """A user mistake or unusable input: bad file, wrong units, unknown name.

    The message is one line that says what is wrong and, where possible, how to
    mend it. The command line prints it and exits with code 2. A
    :class:`ValueError`, so that a library user may catch the built-in type.
    """


class HandcapWarning(UserWarning):
    """A result that was computed but looks implausible; the message is one line."""


def warn(message: str, *, stacklevel: int = 2) -> str:
    """Issue ``message`` as a :class:`HandcapWarning` and return it, to be stored with the result.

    Parameters
    ----------
    message : str
        One line naming the figure, its value and the plausible range.
    stacklevel : int
        As for :func:`warnings.warn`; 2 points at the caller of ``warn``.

    Returns
    -------
    str
        ``message``, unchanged.
    """
    message = " ".join(str(message).split())
    _warnings.warn(message, HandcapWarning, stacklevel=stacklevel + 1)
    return message


def merge_warnings(*groups) -> tuple[str, ...]:
    """Concatenate groups of warning lines in order, dropping repeats and empty lines."""
    out: list[str] = []
    for group in groups:
        if group is None:
            continue
        if isinstance(group, str):
            group = (group,)
        for line in group:
            line = " ".join(str(line).split())
            if line and line not in out:
                out.append(line)
    return tuple(out)
