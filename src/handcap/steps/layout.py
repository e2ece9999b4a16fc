"""Steps on marker layouts: write a ``new`` commented layout to edit, ``check`` one against a take."""

from __future__ import annotations

from pathlib import Path

from handcap.core.errors import HandcapError
from handcap.io import atomic_output, check_not_input, read_markers
from handcap.layouts import SHIPPED, check_layout, layout_template, load_layout
from handcap.patterns.layout import pattern_layout
from handcap.patterns.pattern import Pattern
from handcap.steps.step import Step


def new(out, *, like: str = "glove-13", side: str | None = None, positions: bool = True, force: bool = False,
        pattern=None, segments=()) -> Step:
    """Write a commented copy of a layout, every field explained (see :func:`handcap.layouts.layout_template`).

    Parameters
    ----------
    out : str or Path
        Layout file to write (.toml); an existing one only with ``force``.
    like : str
        Layout to start from: a shipped name or a .toml file.
    side : {'right', 'left'} or None
        Write it for this hand (default: as ``like``, or the template's one hand).
    positions : bool
        Keep the hand markers' positions (False: calibrate-markers estimates them from a take).
    force : bool
        Replace ``out`` if it exists.
    pattern : str, Path or None
        Instead of ``like``: a ``pattern.toml`` whose hand patches' corners become the markers, on the segments
        ``segments`` give, without positions (:func:`handcap.patterns.layout.pattern_layout`).
    segments : sequence of str
        ``PATCHES=SEGMENT`` rules for ``pattern``.
    """
    out = Path(out)
    if out.is_dir():
        raise HandcapError(f"{out}: is a folder; give a file name such as {out / 'my-layout.toml'}")
    if out.suffix.lower() != ".toml":
        raise HandcapError(f"{out}: layouts are TOML files; name it NAME.toml")
    if segments and pattern is None:
        raise HandcapError("--segment places the patches of a --pattern; give --pattern too")
    check_not_input(out, *([] if like in SHIPPED else [like]), pattern)
    if out.exists() and not force:
        raise HandcapError(f"{out}: exists; choose another name or add --force to replace it")
    if pattern is not None:
        layout = pattern_layout(Pattern.load(pattern), side, segments, name=out.stem)
        counts: dict[str, int] = {}
        for m in layout.markers:
            counts[m.patch] = counts.get(m.patch, 0) + 1
        with atomic_output(out, "w") as fh:
            fh.write(layout_template(layout, positions=False, made=f"--pattern {pattern}"))
        line = (f"{out}: {len(layout)} corners of {len(counts)} patches of the {layout.side} hand of {pattern}, "
                "no positions (calibrate-markers places them from a calibration take: open hand, slowly turned); "
                f"next: handcap calibrate-markers CALIBRATION_TAKE --layout {out} --drop-unseen")
        return Step((line,), (), (str(out),), layout)
    layout = load_layout(like, side=side)
    with atomic_output(out, "w") as fh:
        fh.write(layout_template(layout, like=like, positions=positions))
    given = sum(m.position is not None for m in layout.markers) if positions else 0
    line = (f"{out}: {len(layout)} markers like {like} ({layout.side} hand, {given} with positions), every field "
            f"explained in its comments; next: handcap layout check {out} YOUR_TAKE")
    return Step((line,), (), (str(out),), layout)


def check(layout: str, take=None, *, side: str | None = None, units: str | None = None) -> Step:
    """Check a layout, against a labeled take if given (see :func:`handcap.layouts.check_layout`).

    Parameters
    ----------
    layout : str
        A shipped name or a .toml file.
    take : str, Path or None
        A labeled take of this marker set.
    side : {'right', 'left'} or None
        Hand side (default: the layout's).
    units : {'mm', 'cm', 'm'} or None
        Unit of the take's coordinates, overriding what the file says.
    """
    marker_layout = load_layout(layout, side=side)
    markers = None if take is None else read_markers(take, units=units,
                                                     hand=[m.name for m in marker_layout.hand_markers])
    result = check_layout(marker_layout, markers, take=take)
    return Step((result.summary(),), result.warnings, (), result)
