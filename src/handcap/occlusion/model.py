"""A trained occlusion model: marker predictor, optional joint regressor, metadata; one ``.npz``.

The file holds plain arrays (no pickles): the two networks' layers, the
template and standardisation, the marker names, the hand side it was trained
on, and how it was trained (layout, seed, frames, command). Shipped models for
the shipped layouts live in ``handcap/occlusion/weights/`` and are made by
``make occlusion-weights`` (:func:`handcap.occlusion.shipped.build`, deterministic for its seed).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from importlib.resources import files
from pathlib import Path

import numpy as np

from handcap.core.errors import HandcapError
from handcap.core.motion import check_side
from handcap.core.files import load_npz, save_npz
from handcap.occlusion.predictor import MarkerPredictor
from handcap.occlusion.regressor import JointRegressor

FORMAT = "handcap-occlusion-1"
SHIPPED_MODELS = ("active-9", "glove-13", "joints-19")


@dataclass(frozen=True, eq=False)
class OcclusionModel:
    """Everything :class:`~handcap.occlusion.filler.OcclusionFiller` needs for one hand layout.

    Attributes
    ----------
    predictor : MarkerPredictor
    regressor : JointRegressor or None
        Present when the model was trained with poses.
    side : {"right", "left"}
        The hand it was trained on; the other hand is served by mirroring.
    layout : str
        Layout name it was trained for.
    info : dict of str
        How it was trained: seed, epochs, and how much data it saw (takes, recorded and
        synthetic, subjects, frames, augmented copies and frames, samples, augmentation).
    warnings : tuple of str
        One line each where its training data look too scarce.
    """

    predictor: MarkerPredictor
    regressor: JointRegressor | None = None
    side: str = "right"
    layout: str = ""
    info: dict = field(default_factory=dict)
    warnings: tuple = ()

    def __post_init__(self):
        check_side(self.side)
        if self.regressor is not None and tuple(self.regressor.names) != tuple(self.predictor.names):
            raise HandcapError("the joint regressor and the marker predictor were trained on different markers")

    @property
    def names(self) -> tuple[str, ...]:
        """Marker names (M,) the model was trained on, in its column order."""
        return self.predictor.names

    def __repr__(self) -> str:
        pose = "with joint regressor" if self.regressor is not None else "markers only"
        return f"OcclusionModel({self.layout!r}, {self.side}, {len(self.names)} markers, {pose})"

    def summary(self) -> str:
        """What it was trained on (from ``info``): takes, subjects, frames, augmentation, samples; several lines."""
        info = self.info
        if not info:
            return repr(self)
        posed = int(info.get("posed_frames", 0))
        try:
            pair = f"{float(info.get('pair_seconds', 'nan')):g}"
        except ValueError:
            pair = "?"
        return (f"{self!r}\n"
                f"  saw {info['takes']} take(s) ({info['recorded_takes']} recorded, {info['synthetic_takes']} "
                f"synthetic) of {info['subjects']} subject(s), {info['frames']} frames; {info['augmented_copies']} "
                f"augmented copies ({info['augmented_frames']} frames); {info['samples']} training samples\n"
                f"  augmentation: {info['augmentation']}; gaps up to {pair} s\n"
                + (f"  joint regressor on {posed} posed frames" if posed else "  no poses: markers only"))

    def save(self, path) -> None:
        """Write the model as ``.npz`` (atomically)."""
        arrays = {"format": np.array(FORMAT), "side": np.array(self.side), "layout": np.array(self.layout),
                  "info_keys": np.array(list(self.info), dtype=str),
                  "info_values": np.array([str(v) for v in self.info.values()], dtype=str),
                  "warnings": np.array(list(self.warnings), dtype=str),
                  **self.predictor.arrays()}
        if self.regressor is not None:
            arrays.update(self.regressor.arrays())
        save_npz(path, arrays)

    @classmethod
    def load(cls, path) -> "OcclusionModel":
        """Read a model written by :meth:`save`.

        Raises
        ------
        HandcapError
            If the file is missing or is not an occlusion model.
        """
        arrays = load_npz(path, required=("format", "ae_names"), what="occlusion model")
        if str(arrays["format"]) != FORMAT:
            raise HandcapError(f"{path}: not a handcap occlusion model (format {str(arrays['format'])!r})")
        try:
            predictor = MarkerPredictor.from_arrays(arrays)
            regressor = JointRegressor.from_arrays(arrays) if "jr_names" in arrays else None
            info = dict(zip((str(k) for k in np.atleast_1d(arrays["info_keys"])),
                            (str(v) for v in np.atleast_1d(arrays["info_values"]))))
            warnings = tuple(str(w) for w in np.atleast_1d(arrays["warnings"])) if "warnings" in arrays else ()
            return cls(predictor, regressor, str(arrays["side"]), str(arrays["layout"]), info, warnings)
        except HandcapError:
            raise  # already says what is wrong (a ValueError too, so kept apart from numpy's below)
        except KeyError as err:
            raise HandcapError(f"{path}: occlusion model is missing {err.args[0]!r}") from None
        except (ValueError, TypeError, IndexError) as err:
            # The format entry matched but an array has the wrong type or shape: a damaged file.
            raise HandcapError(f"{path}: damaged occlusion model ({' '.join(str(err).split())[:120]}); "
                               f"train it again with handcap train-occlusion") from None

    @classmethod
    def shipped(cls, layout: str) -> "OcclusionModel":
        """The model shipped for a layout (see :data:`SHIPPED_MODELS`)."""
        if layout not in SHIPPED_MODELS:
            raise HandcapError(f"no occlusion model is shipped for layout {layout!r}; shipped: "
                               f"{', '.join(SHIPPED_MODELS)} (train one with handcap train-occlusion)")
        return cls.load(files("handcap.occlusion").joinpath("weights", f"{layout}.npz"))

    @classmethod
    def resolve(cls, source) -> "OcclusionModel":
        """A model from a shipped layout name, a ``.npz`` path, or a model."""
        if isinstance(source, OcclusionModel):
            return source
        if str(source) in SHIPPED_MODELS and not Path(str(source)).exists():
            return cls.shipped(str(source))
        return cls.load(source)
