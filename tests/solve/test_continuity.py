"""Short excursions of the solved hand into another pose, and back, mended from the frames around them: on the
real glove recording (its solve jumped for a frame or a few where its 13 markers allow two poses). A synthetic
take whose labels a labeler got partly wrong is in ``test_relabel.py`` (the hand against the truth)."""

import warnings

import numpy as np
import pytest

import handcap.solve.motion as motion_module
from handcap.core.errors import HandcapWarning
from handcap.layouts import load_layout
from handcap.quality.metrics import msnr
from handcap.quality.motion_checks import jerk_spikes
from handcap.solve import calibrate_attachment, solve_hand
from handcap.solve.continuity import excursions


@pytest.fixture
def unmended(monkeypatch):
    """Solve as before the mending (step 5 of solve_lm off)."""
    def solve(*args, **kwargs):
        with monkeypatch.context() as patch:
            patch.setattr(motion_module, "mend_excursions", lambda *a: 0)
            return solve_hand(*args, **kwargs)
    return solve


def test_the_real_glove_keeps_its_course(shared_data, unmended):
    from handcap.io import read_markers

    layout = load_layout("glove-13")
    markers = read_markers(shared_data / "markers/hand_embodiment_glove/recording.tsv").select(layout.names)
    take = markers.frames(0, 1500)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", HandcapWarning)
        attachment = calibrate_attachment(take, layout).attachment
        before, after = unmended(take, attachment), solve_hand(take, attachment)
    spikes_before, spikes_after = len(jerk_spikes(before.joints, 100.0)), len(jerk_spikes(after.joints, 100.0))
    # measured: 18 -> 2 spikes, MSNR 2.6 -> 6.3 dB, MRE 1.206 -> 1.211 mm (the whole recording: 184 -> 9 spikes,
    # 0.2 -> 7.1 dB, 1.316 -> 1.323 mm)
    assert spikes_before >= 10 and spikes_after <= spikes_before / 5, (spikes_before, spikes_after)
    assert msnr(after.joints) > msnr(before.joints) + 3.0
    assert np.nanmean(after.marker_residuals) < np.nanmean(before.marker_residuals) + 0.00002  # the fit as good


def test_excursions_are_the_stretches_between_spikes():
    # a smooth path with a one-frame jump at 50 and a step at 300: one stretch around 50; nothing where it is smooth
    t = np.arange(400) / 100.0
    path = np.stack([np.sin(t), np.cos(t), t], axis=1)[:, None] * 0.05
    path[50] += 0.01
    stretches = excursions(path, 100.0)
    assert len(stretches) == 1 and stretches[0][0] <= 50 <= stretches[0][-1] and len(stretches[0]) <= 8
    assert excursions(np.stack([np.sin(t), np.cos(t), t], axis=1)[:, None] * 0.05, 100.0) == []
