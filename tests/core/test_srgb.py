"""The sRGB transfer function against the standard's figures, and its decoding as its inverse."""

from __future__ import annotations

import numpy as np

from handcap.core.srgb import srgb_decoded, srgb_encoded


def test_srgb_follows_iec_61966_2_1():
    # The standard's breakpoint (0.0031308 of white: level 0.04045, where both pieces meet), its middle grey and
    # white; 0.18 (photography's middle grey) encodes to 0.4614.
    np.testing.assert_allclose(srgb_encoded([0.0, 0.0031308, 0.18, 0.21404, 1.0]),
                               [0.0, 0.04045, 0.46135, 0.5, 1.0], atol=2e-5)
    light = np.linspace(0.0, 1.0, 10001)
    np.testing.assert_allclose(srgb_decoded(srgb_encoded(light)), light, atol=1e-12)
    assert (np.diff(srgb_encoded(light)) > 0).all()
