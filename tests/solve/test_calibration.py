"""Attachment calibration recovers misplaced markers; bad inputs are refused."""

import re
from dataclasses import replace

import numpy as np
import pytest
from scipy.optimize import least_squares

from handcap import HandcapError
from handcap.hand import OpenHand
from handcap.hand.attachment import MarkerAttachment
from handcap.layouts import LayoutMarker, MarkerLayout, load_layout
from handcap.quality.plausibility import SHAPE_BOUND
from handcap.solve import calibrate_attachment, solve_hand
from handcap.solve.calibration import SHAPE_PRIOR, _calibration_frames, _fit_shape
from handcap.solve.markers import MarkerModel


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


def test_the_shape_fit_reaches_the_optimum_of_scipys_least_squares(glove_session):
    # The shape fit keeps one Jacobian and takes linear steps (the markers move almost linearly with the shape);
    # scipy's least_squares, making its own Jacobian at each iteration, is the independent solver it must match.
    cal, _ = glove_session
    layout, hand = load_layout("glove-13"), OpenHand("right")
    result = calibrate_attachment(cal.markers, layout, fit_shape=True, rounds=2)
    target, observed, _ = _calibration_frames(cal.markers, layout, result.frames, 200)
    average = replace(result.attachment, betas=np.zeros(10))  # the fitted spots and poses, the average shape

    def cost(betas):
        fit = MarkerModel(hand, replace(average, betas=betas)).positions(result.poses.transl, result.poses.rot,
                                                                       result.poses.phi)
        return np.r_[(fit - np.nan_to_num(target))[observed].ravel(), SHAPE_PRIOR * np.sqrt(observed.sum()) * betas]

    ours = _fit_shape(hand, average, result.poses, target, observed)
    theirs = least_squares(cost, np.zeros(10), bounds=(-SHAPE_BOUND, SHAPE_BOUND), diff_step=1e-3).x
    start, reached, best = (float(np.sum(cost(b) ** 2)) for b in (np.zeros(10), ours, theirs))
    assert reached < 0.9 * start  # the shape mattered
    assert reached <= best * (1 + 1e-4)
    np.testing.assert_allclose(ours, theirs, atol=0.02)


def test_patches_printed_by_another_generator_calibrate_and_solve_from_their_template(dense_session, tmp_path):
    """The path of a lab whose patches another generator printed: its template (here handcap's hand patches
    renamed p0, p1, ... so that nothing leans on handcap's names) imported, a layout made from it with each patch's
    segment and no position, the markers placed by the calibration and the take solved."""
    import json

    from handcap.patterns import session_pattern
    from handcap.patterns.foreign import import_template
    from handcap.patterns.layout import pattern_layout

    cal, take = dense_session
    ours = session_pattern(("right",), ())
    grids, rules, rename = {}, [], {}
    for k, patch in enumerate(ours.patches):
        grids[f"p{k}"] = ["".join(t or "**" for t in row) for row in patch.tags]
        rules.append(f"p{k}={patch.segment}")
        rename.update({patch.corner_name(r, c, owner=False): f"p{k}_r{r}c{c}"
                       for r in range(patch.rows + 1) for c in range(patch.cols + 1)})
    (tmp_path / "theirs.json").write_text(json.dumps(grids))
    pattern, _ = import_template(tmp_path / "theirs.json")
    layout = pattern_layout(pattern, segments=rules)
    renamed = [replace(s.markers, names=tuple(rename.get(n, n) for n in s.markers.names)) for s in (cal, take)]
    seen = {n for n, ok in zip(renamed[0].names, np.isfinite(renamed[0].positions).all(-1).any(0)) if ok}
    layout = layout.subset(seen)
    assert len(layout) > 300
    result = calibrate_attachment(renamed[0], layout, betas=cal.attachment.betas, max_frames=40)
    motion = solve_hand(renamed[1], result.attachment)
    assert np.nanmean(motion.marker_residuals) < 0.001
    assert _joint_error(motion, take).mean() < 0.003


def test_drop_misfit_calibrates_again_without_the_markers_that_fit_no_bone(dense_session, tmp_path, capsys):
    """A patch put on the wrong segment (the index fingertip's on the palm) fits nowhere: --drop-misfit leaves its
    corners out, names them, and the calibration MRE falls; the right layout loses nothing."""
    from handcap.cli import main
    from handcap.io import write_markers
    from handcap.layouts import layout_template

    cal, _ = dense_session
    write_markers(cal.markers, tmp_path / "cal.c3d")
    dense = load_layout("dense-patches")
    wrong = MarkerLayout("wrong", "right", tuple(LayoutMarker(m.name, "palm" if m.patch == "index_distal" else
                                                              m.segment, None, m.patch) for m in dense.markers),
                         (), dense.marker_radius, dense.marker_kind)
    moved = {m.name for m in wrong.markers if m.patch == "index_distal"}
    betas = ",".join(f"{b:.6f}" for b in cal.attachment.betas)  # known: the shape is not what is tested
    for name, layout in (("wrong", wrong), ("right", dense)):
        (tmp_path / f"{name}.toml").write_text(layout_template(layout, positions=False))
        assert main(["calibrate-markers", str(tmp_path / "cal.c3d"), "--layout", str(tmp_path / f"{name}.toml"),
                     "--drop-misfit", "--frames", "0:20", "--drop-unseen", "--betas", betas, "--out",
                     str(tmp_path / f"{name}.npz")]) == 0
        out = capsys.readouterr()
        kept = set(MarkerAttachment.load(tmp_path / f"{name}.npz").marker_names)
        # --drop-unseen judges the frames used (--frames 0:20), where some palm corners are never seen.
        unseen = {n for n, ok in zip(cal.markers.names, np.isfinite(cal.markers.positions[:20]).all(-1).any(0))
                  if not ok and n in dense.names}
        assert unseen and f"{len(unseen)} of the layout's 395 markers were never seen in the calibration take's " \
                          "frames used" in out.err
        if name == "right":
            assert "fit the hand worse" not in out.err and kept == set(dense.names) - unseen
            continue
        dropped = {n for n in dense.names if n not in kept} - unseen
        assert moved <= dropped and len(dropped) < len(moved) + 5
        before, after = map(float, re.search(r"calibration MRE ([\d.]+) mm with them, ([\d.]+) mm", out.err).groups())
        assert after < 0.5 * before and "index_distal_r" in out.err
    assert main(["calibrate-markers", str(tmp_path / "cal.c3d"), "--layout", "dense-patches", "--drop-misfit", "0",
                 "--out", str(tmp_path / "zero.npz")]) == 2
    assert "give a residual in millimetres" in capsys.readouterr().err and not (tmp_path / "zero.npz").exists()
