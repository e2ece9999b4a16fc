"""The sRGB transfer function (IEC 61966-2-1): how a display-referred camera (a phone, a webcam, most video)
encodes light, and its decoding back to light.

Both map 0..1 to 0..1: white stays 1, and the middle sRGB level 0.5 is 0.2140 of white (0.5 of white is 0.7354).
"""

from __future__ import annotations

import numpy as np


def srgb_encoded(light) -> np.ndarray:
    """Light encoded as sRGB.

    Parameters
    ----------
    light : array_like
        Linear light, 0..1 of white.

    Returns
    -------
    ndarray
        sRGB levels, 0..1.
    """
    light = np.asarray(light, dtype=np.float64)
    return np.where(light <= 0.0031308, 12.92 * light, 1.055 * np.maximum(light, 0.0031308) ** (1 / 2.4) - 0.055)


def srgb_decoded(level) -> np.ndarray:
    """sRGB levels decoded to light (the inverse of :func:`srgb_encoded`).

    Parameters
    ----------
    level : array_like
        sRGB levels, 0..1.

    Returns
    -------
    ndarray
        Linear light, 0..1 of white.
    """
    level = np.asarray(level, dtype=np.float64)
    return np.where(level <= 0.04045, level / 12.92, ((np.maximum(level, 0.04045) + 0.055) / 1.055) ** 2.4)
