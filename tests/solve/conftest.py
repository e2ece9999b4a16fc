"""Synthetic sessions shared by the solver tests (a calibration take and a capture, one subject)."""

import pytest

from handcap.synth.scene import SynthConfig, synthesize


@pytest.fixture(scope="session")
def glove_session():
    cal = synthesize(SynthConfig(layout="glove-13", motion="calibration", frames=150, seed=31, subject_seed=4))
    take = synthesize(SynthConfig(layout="glove-13", motion="grasp", frames=150, rate=50, seed=32, subject_seed=4,
                                  noise_mm=0.5))
    return cal, take


@pytest.fixture(scope="session")
def dense_session():
    cal = synthesize(SynthConfig(layout="dense-patches", motion="calibration", frames=80, rate=20, seed=41,
                                 subject_seed=6, noise_mm=0.5, min_views=3))
    take = synthesize(SynthConfig(layout="dense-patches", motion="rotate-cube", frames=60, rate=20, seed=42,
                                  subject_seed=6, noise_mm=0.5, min_views=3))
    return cal, take
