"""The live solver's pull towards the angles the frames before predict (``FrameSolver(smoothing=...)``): the real
glove no longer jumps between the two poses its markers allow, synthetic takes come closer to their truth, and its
weight follows the stream (rate, noise), not a constant."""


import numpy as np
import pytest

from handcap import HandcapError
from handcap.hand import OpenHand
from handcap.quality.metrics import msnr
from handcap.quality.motion_checks import jerk_spikes
from handcap.stream.solver import FrameSolver
from handcap.synth.scene import SynthConfig, synthesize

pytest.importorskip("numba", reason="the compiled live solver needs numba (extra 'stream')")


def _solved(solver, frames):
    out = [solver.solve(f) for f in frames]
    return np.array([o[0] for o in out]), np.array([o[2] for o in out])


def test_the_real_glove_streams_without_jumping_between_poses(real_glove):
    take, attachment = real_glove
    frames = take.positions[1500:3000]  # frames the calibration did not see
    alone, alone_rms = _solved(FrameSolver(attachment, OpenHand("right"), smoothing=0.0), frames)
    pulled, pulled_rms = _solved(FrameSolver(attachment, OpenHand("right")), frames)
    # measured: 28 -> 0 jerk spikes, 3.3 -> 12.4 dB, RMS marker residual 1.93 -> 2.16 mm
    assert len(jerk_spikes(alone, 100.0)) >= 15 and len(jerk_spikes(pulled, 100.0)) <= 2
    assert msnr(pulled) > msnr(alone) + 6.0
    assert np.nanmean(pulled_rms) < 1.2 * np.nanmean(alone_rms)  # the markers still fitted


@pytest.mark.parametrize("layout, rate, frames, seed", [("joints-19", 120.0, 360, 4), ("glove-13", 60.0, 240, 2)])
def test_synthetic_joints_come_closer_to_the_truth(layout, rate, frames, seed):
    capture = synthesize(SynthConfig(layout=layout, motion="random", frames=frames, rate=rate, seed=seed,
                                     subject_seed=3), progress=False)
    markers = capture.markers.select(list(capture.attachment.marker_names)).positions
    error = {}
    for smoothing in (0.0, 0.5):
        joints, _ = _solved(FrameSolver(capture.attachment, OpenHand("right"), smoothing=smoothing), markers)
        error[smoothing] = np.linalg.norm(joints - capture.hand_motion.joints, axis=-1)
    # measured (median / p99): joints-19 0.314 / 1.38 -> 0.281 / 0.99 mm; glove-13 0.449 / 2.35 -> 0.404 / 1.71 mm
    assert np.nanmedian(error[0.5]) < 0.95 * np.nanmedian(error[0.0])
    assert np.nanpercentile(error[0.5], 99) < 0.9 * np.nanpercentile(error[0.0], 99)


def _weight(solver):
    """The pull's weight the solver reached, metres per radian (checked against its medians)."""
    solver.idle()
    assert solver.weight == pytest.approx(solver.smoothing * np.median(solver.residuals) / np.median(solver.surprises))
    return solver.weight


def test_the_pull_weighs_what_the_stream_gives_it():
    capture = synthesize(SynthConfig(layout="glove-13", motion="random", frames=120, rate=100.0, seed=4,
                                     subject_seed=3), progress=False)
    markers = capture.markers.select(list(capture.attachment.marker_names)).positions
    solver = FrameSolver(capture.attachment, OpenHand("right"))
    _solved(solver, markers)
    # the markers sit on the calibrated spots (0.3 mm of noise): measured 0.006 m/rad; 4 mm off them, as a glove's
    # markers can sit, the markers alone fit worse and the pull weighs more (measured 0.035 m/rad)
    off = capture.markers.select(list(capture.attachment.marker_names)).positions + np.random.default_rng(0).normal(
        0, 0.004, (1, markers.shape[1], 3))
    shifted = FrameSolver(capture.attachment, OpenHand("right"))
    _solved(shifted, off)
    assert _weight(shifted) > 2 * _weight(solver)
    # a frame with fewer than 3 markers ends the prediction: the next two frames start it again
    assert len(solver.recent) == 2
    solver.solve(np.full_like(markers[0], np.nan))
    assert solver.recent == []
    with pytest.raises(HandcapError, match="smoothing must be 0 or more"):
        FrameSolver(capture.attachment, OpenHand("right"), smoothing=-0.5)
