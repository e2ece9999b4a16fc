"""``handcap session new DIR``: a commented session file with synthetic takes made in DIR, ready for
``handcap process DIR/session.toml``."""

from __future__ import annotations

from pathlib import Path

from handcap.core.errors import HandcapError
from handcap.core.files import atomic_output
from handcap.synth.scene import SynthConfig, synthesize, write_capture

TEMPLATE = '''# A handcap session: `handcap process session.toml` runs every stage of every take and writes
# results/<take>/ (attachment.npz, motion.npz, metrics.json, report.html, and a manifest per stage).
# Run it again and finished stages are skipped; edit a setting and only what depends on it runs again.
# `handcap process session.toml --dry-run` prints the plan.

[session]
name = "{name}"
results = "results"
stages = ["calibrate", "solve", "metrics", "report"]

[stages.calibrate]
layout = "glove-13"          # the marker layout of every take (a take may name its own)

[stages.solve]
method = "lm"
filter_cutoff = 8.0          # Hz: a low-pass on the solved motion; remove the line for none

[stages.metrics]
leave_one_out = false

{takes}'''

TAKE = '''[[takes]]
name = "{name}"
kind = "markers"             # labelled markers (.c3d .trc .tsv .csv .npz)
markers = "{name}/markers.c3d"
calibration = "calibration/markers.c3d"   # or attachment = "attachment.npz"
truth = "{name}/truth.npz"   # synthetic takes only: the metrics compare against it

'''


def new_session(folder, *, takes: int = 2, frames: int = 300) -> list[str]:
    """Write a session into ``folder``: a calibration take, ``takes`` grasp takes (synthetic, one subject) and a
    commented ``session.toml``.

    Parameters
    ----------
    folder : str or Path
        New or empty.
    takes, frames : int
        Number of takes and frames of each (100 Hz).

    Returns
    -------
    list of str
        The files written.
    """
    folder = Path(folder)
    if folder.exists() and (not folder.is_dir() or any(folder.iterdir())):
        raise HandcapError(f"{folder}: exists and is not an empty folder; give a new one")
    written = []
    configs = {"calibration": SynthConfig(motion="calibration", frames=400, seed=100, subject_seed=7)}
    for k in range(takes):
        configs[f"take{k + 1}"] = SynthConfig(motion="grasp", frames=frames, seed=k + 1, subject_seed=7)
    for name, config in configs.items():
        written += [str(p) for p in write_capture(synthesize(config, progress=False), folder / name).values()]
    text = TEMPLATE.format(name=folder.name, takes="".join(TAKE.format(name=n) for n in configs if n != "calibration"))
    with atomic_output(folder / "session.toml", "w") as fh:
        fh.write(text)
    return [*written, str(folder / "session.toml")]
