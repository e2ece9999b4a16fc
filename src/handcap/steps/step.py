"""What one step of work did: the files it wrote, its summary and the warnings of its result."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any


@dataclass(frozen=True)
class Step:
    """The outcome of a step such as :func:`handcap.steps.solve.solve`.

    Attributes
    ----------
    lines : tuple of str
        The human summary, one line each (the command line prints them on stdout).
    warnings : tuple of str
        One-line warnings of the result, as stored in the files written (the command line prints them on stderr).
    outputs : tuple of str
        Paths of the files written, in the order written.
    result : object
        The library result the step made (a :class:`~handcap.core.motion.HandMotion`, a
        :class:`~handcap.labeling.take.LabelResult`, ...), for callers that go on with it; None when it made none.
    """

    lines: tuple[str, ...]
    warnings: tuple[str, ...] = ()
    outputs: tuple[str, ...] = ()
    result: Any = None

    def summary(self) -> str:
        """The summary lines joined by newlines."""
        return "\n".join(self.lines)


def quality_line(warnings, prefix: str = "quality: ") -> str:
    """``quality: N warning(s), see below`` or ``quality: no warnings``.

    Parameters
    ----------
    warnings : sized collection of str
        Only its length is used.
    prefix : str
        Put before the text.

    Returns
    -------
    str
    """
    return prefix + (f"{len(warnings)} warning(s), see below" if warnings else "no warnings")
