"""Attachment calibration recovers misplaced markers; bad inputs are refused."""

import numpy as np
import pytest

from handcap import HandcapError
from handcap.hand import OpenHand
from handcap.hand.attachment import MarkerAttachment
from handcap.layouts import LayoutMarker, MarkerLayout, load_layout
from handcap.solve import calibrate_attachment, solve_hand


def attachment_error(att, truth, hand):
    verts = hand.forward(truth.betas).vertices
    return np.linalg.norm(att.positions(verts, hand.faces) - truth.positions(verts, hand.faces), axis=1)


def _joint_error(motion, capture):
    return np.linalg.norm(motion.joints - capture.hand_motion.joints, axis=-1)


def test_dense_calibration_finds_the_true_spots(dense_session):
    cal, take = dense_session
    hand = OpenHand()
    truth = cal.attachment
    nominal = MarkerAttachment.from_layout(load_layout("dense-patches"), hand, truth.betas)
    result = calibrate_attachment(cal.markers, load_layout("dense-patches"), hand, betas=truth.betas, max_frames=40)
    before, after = attachment_error(nominal, truth, hand), attachment_error(result.attachment, truth, hand)
    assert before.mean() > 0.003  # the synthetic subject stuck its patches off the nominal spots
    assert after.mean() < 0.0015 and after.max() < 0.004
    motion = solve_hand(take.markers, result.attachment)
    assert np.nanmean(motion.marker_residuals) < 0.001
    assert _joint_error(motion, take).mean() < 0.003


def test_glove_calibration_and_solve(glove_session):
    cal, take = glove_session
    result = calibrate_attachment(cal.markers, load_layout("glove-13"))
    assert result.mre < 0.003
    motion = solve_hand(take.markers, result.attachment)
    assert _joint_error(motion, take).mean() < 0.006


def test_own_layout_without_positions(glove_session):
    cal, _ = glove_session
    glove = load_layout("glove-13")
    mine = MarkerLayout("mine", "right", tuple(LayoutMarker(m.name, m.segment) for m in glove.markers),
                        glove.rigid, glove.marker_radius)
    result = calibrate_attachment(cal.markers, mine)
    assert result.mre < 0.0015 and len(result.attachment) == 13  # issue 14: was 3.3 mm (markers stuck together)


def test_real_glove_recording(shared_data):
    from handcap.io import read_markers
    layout = load_layout("glove-13")
    markers = read_markers(shared_data / "markers" / "hand_embodiment_glove" / "recording.tsv").select(layout.names)
    result = calibrate_attachment(markers, layout, frames=slice(0, 1000), fit_shape=True)
    motion = solve_hand(markers[1000:1600], result.attachment)
    assert np.nanmean(motion.marker_residuals) < 0.004  # issue 3: mean MRE within 4 mm


def test_bad_inputs(glove_session):
    cal, _ = glove_session
    layout = load_layout("glove-13")
    with pytest.raises(HandcapError, match="absent from the calibration take"):
        calibrate_attachment(cal.markers.select(["hand_top", "hand_left", "hand_right"]), layout)
    positions = cal.markers.positions.copy()
    positions[:, list(cal.markers.names).index("ring_tip")] = np.nan
    from handcap import MarkerSequence
    with pytest.raises(HandcapError, match="never seen"):
        calibrate_attachment(MarkerSequence(positions, cal.markers.names, cal.markers.rate), layout)
    with pytest.raises(HandcapError, match="calibration frames show 3 or more"):
        calibrate_attachment(cal.markers, layout, frames=slice(0, 2))
