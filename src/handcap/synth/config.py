"""The settings of a synthetic capture: :class:`SynthConfig`, checked when made, and its ``scene.toml``
(every setting, to make the same capture again)."""

from __future__ import annotations

import tomllib
from dataclasses import asdict, dataclass, replace
from pathlib import Path

import numpy as np

from handcap import __version__
from handcap.core.errors import HandcapError
from handcap.core.motion import check_side
from handcap.objects.cube import parse_moves
from handcap.synth.cube import CUBE_MOTION
from handcap.synth.motions import MOTIONS
from handcap.synth.objects import OBJECTS

DEFAULT_OBJECT = {"grasp": "cylinder", "precision": "sphere", "rotate-cube": "cube2x2", CUBE_MOTION: "cube2x2"}


@dataclass(frozen=True)
class SynthConfig:
    """Every setting of a synthetic capture (written to ``scene.toml``).

    Attributes
    ----------
    layout : str
        Shipped layout name or a layout TOML path.
    motion : str
        One of :data:`handcap.synth.motions.MOTIONS`, or ``turn-cube`` (the hand turning the 2x2x2 cube's
        layers through ``moves``: :mod:`handcap.synth.cube`).
    frames : int
        Ignored by ``turn-cube``, whose take lasts as long as its moves need.
    rate : float
        Frames per second.
    seed : int
    side : {"right", "left"}
    object : str
        One of :data:`handcap.synth.objects.OBJECTS`, ``"none"``, or ``"auto"``
        (the motion's usual object: cylinder for grasp, sphere for precision,
        the 2x2x2 cube for rotate-cube, none otherwise).
    betas : tuple of 10 float or None
        Subject shape; None draws one from the seed (standard deviation 0.5).
    cameras : int
        Cameras on the cage.
    min_views : int
        Cameras that must see a marker for it to be reconstructed in 3D.
    noise_mm : float
        Standard deviation of the 3D jitter of reconstructed markers, millimetres.
    pixel_noise : float
        Standard deviation of 2D detection noise, pixels.
    dropout : float
        Extra fraction of samples lost in bursts (mean 5 frames).
    ghost_rate : float
        Ghost markers per second.
    swap_rate : float
        Label swaps per second.
    outlier_rate : float
        Fraction of 2D detections given a wrong marker id.
    max_view_angle_deg : float or None
        Patch corners seen more obliquely are not detected; None: the layout's
        kind decides (75 degrees for patches, unlimited for spheres).
    placement_mm : float
        How far from their nominal spots markers are stuck on, millimetres
        (standard deviation along the skin): each printed patch is shifted and
        turned as one piece (turn: 3 degrees per millimetre), each sphere marker
        moves on its own. The layout file keeps the nominal spots, so a
        calibration has something to find.
    subject_seed : int or None
        Seed of the subject: hand shape (when ``betas`` is None) and marker
        placement. Takes with the same subject seed share them, like the
        calibration take and the takes of one session. None: ``seed``.
    moves : str or None
        ``turn-cube`` only: the moves in standard notation (``"R U R' U'"``); None: a random 10-move scramble
        drawn from the seed.
    """

    layout: str = "glove-13"
    motion: str = "grasp"
    frames: int = 600
    rate: float = 100.0
    seed: int = 0
    side: str = "right"
    object: str = "auto"
    betas: tuple | None = None
    cameras: int = 12
    min_views: int = 2
    noise_mm: float = 0.3
    pixel_noise: float = 0.5
    dropout: float = 0.01
    ghost_rate: float = 1.0
    swap_rate: float = 0.1
    outlier_rate: float = 0.0
    max_view_angle_deg: float | None = None
    placement_mm: float = 3.0
    subject_seed: int | None = None
    moves: str | None = None

    def __post_init__(self):
        check_side(self.side)
        if self.motion not in MOTIONS + (CUBE_MOTION,):
            raise HandcapError(f"unknown motion {self.motion!r}; choose one of {', '.join(MOTIONS + (CUBE_MOTION,))}")
        if self.moves is not None:
            if self.motion != CUBE_MOTION:
                raise HandcapError(f"moves are turned by motion {CUBE_MOTION!r}, not {self.motion!r}")
            if not parse_moves(self.moves):
                raise HandcapError("moves: give at least one face turn, e.g. \"R U R' U'\"")
        if self.motion == CUBE_MOTION and self.object not in ("auto", "cube2x2"):
            raise HandcapError(f"motion {CUBE_MOTION!r} turns the 2x2x2 cube's layers: use --object cube2x2 "
                               f"(or auto), not {self.object!r}")
        if self.object not in OBJECTS + ("none", "auto"):
            raise HandcapError(f"unknown object {self.object!r}; choose one of {', '.join(OBJECTS)}, none, auto")
        if not (isinstance(self.frames, int) and 2 <= self.frames <= 1_000_000):
            raise HandcapError(f"frames must be an integer from 2 to 1000000, got {self.frames}")
        if not (np.isfinite(self.rate) and 1 <= self.rate <= 10_000):
            raise HandcapError(f"rate must be 1-10000 frames per second, got {self.rate}")
        if not 1 <= self.cameras <= 24:
            raise HandcapError(f"cameras must be 1-24, got {self.cameras}")
        if not 1 <= self.min_views <= self.cameras:
            raise HandcapError(f"min_views must be between 1 and the number of cameras ({self.cameras})")
        for name in ("noise_mm", "pixel_noise", "ghost_rate", "swap_rate", "placement_mm"):
            value = getattr(self, name)
            if not (np.isfinite(value) and value >= 0):
                raise HandcapError(f"{name} must be a non-negative number, got {value}")
        for name in ("dropout", "outlier_rate"):
            value = getattr(self, name)
            if not 0 <= value < 1:
                raise HandcapError(f"{name} must be a fraction in [0, 1), got {value}")
        if self.betas is not None and len(self.betas) != 10:
            raise HandcapError(f"betas must be 10 numbers, got {len(self.betas)}")
        if self.motion in DEFAULT_OBJECT and self.object == "none":
            raise HandcapError(f"motion {self.motion!r} needs an object; drop --object none")

    @property
    def object_kind(self) -> str | None:
        """The object in the take (one of :data:`OBJECTS`), ``auto`` resolved by the motion; None for none."""
        kind = DEFAULT_OBJECT.get(self.motion) if self.object == "auto" else self.object
        return None if kind in (None, "none") else kind


def scene_table(config: SynthConfig) -> dict:
    """``scene.toml`` contents: every setting, plus the handcap version."""
    table = {k: v for k, v in asdict(config).items() if v is not None}
    if config.betas is not None:
        table["betas"] = [float(b) for b in config.betas]
    table["handcap_version"] = __version__
    return {"synth": table}


def config_from_scene(path) -> SynthConfig:
    """The settings stored in a ``scene.toml``."""
    try:
        table = tomllib.loads(Path(path).read_text())["synth"]
    except (OSError, KeyError, tomllib.TOMLDecodeError) as err:
        raise HandcapError(f"{path}: not a handcap scene.toml ({err})") from None
    table.pop("handcap_version", None)
    if "betas" in table:
        table["betas"] = tuple(table["betas"])
    try:
        return replace(SynthConfig(), **table)
    except TypeError as err:
        raise HandcapError(f"{path}: unknown setting ({err})") from None
