"""The steps of handcap.steps (what the command line calls) and the summary() of every result they return."""

import importlib

import numpy as np
import pytest

from handcap.core.errors import HandcapError
from handcap.core.markers import MarkerSequence
from handcap.core.motion import HandMotion, ObjectMotion
from handcap.io import read_markers, write_markers
from handcap.labeling.take import LabelResult
from handcap.multiview.clean import CleanReport
from handcap.multiview.reconstruct import TriangulatedMarkers
from handcap.occlusion.fill import FillReport
from handcap.steps import Step
from handcap.steps import markers as marker_steps
from handcap.steps.multiview import clean


def _take(rng, frames=40, missing=0.1):
    positions = 0.1 * rng.normal(size=(frames, 4, 3))
    positions[rng.random((frames, 4)) < missing] = np.nan
    return MarkerSequence(positions, ["a", "b", "c", "d"], 100.0)


def test_step_summary_joins_its_lines():
    assert Step(("one", "two"), ("w",)).summary() == "one\ntwo"
    assert Step(()).summary() == "" and Step(()).warnings == ()


def test_convert_step_writes_the_file_and_says_so(tmp_path):
    take = _take(np.random.default_rng(0))
    source, out = tmp_path / "a.npz", tmp_path / "b.c3d"
    write_markers(take, source)
    before = source.read_bytes()
    done = marker_steps.convert(source, out)
    assert done.outputs == (str(out),) and source.read_bytes() == before
    np.testing.assert_allclose(read_markers(out).positions, take.positions, atol=1e-6)  # mm in C3D, float32
    assert done.summary().startswith(f"{out}: 40 frames, 4 markers at 100 Hz")
    with pytest.raises(HandcapError):
        marker_steps.convert(source, source)  # never over its input


def test_clean_step_refuses_an_unwritable_suffix_before_reading(tmp_path):
    with pytest.raises(HandcapError, match="cannot write '.txt' marker files"):
        clean(tmp_path / "missing.npz", tmp_path / "out.txt")


def test_marker_and_motion_summaries_give_their_figures():
    take = _take(np.random.default_rng(1))
    missing = 100 * np.isnan(take.positions[..., 0]).mean()
    assert take.summary() == f"40 frames, 4 markers at 100 Hz, {missing:.1f}% missing"
    residuals = np.random.default_rng(2).random((40, 4)) / 1000
    motion = HandMotion(np.zeros(10), np.zeros((40, 3)), np.zeros((40, 45)), np.zeros((40, 3)), 50.0,
                        marker_names=("a", "b", "c", "d"), marker_fit=np.zeros((40, 4, 3)),
                        marker_residuals=residuals)
    assert f"MRE {1000 * residuals.mean():.2f} ± {1000 * residuals.std():.2f} mm" in motion.summary()
    translation = np.zeros((6, 3))
    translation[2] = np.nan
    obj = ObjectMotion(np.zeros((6, 3)), translation, 50.0, name="box")
    assert obj.summary() == "box: 6 frames at 50 Hz, 5 with a pose"


def test_label_clean_fill_and_triangulation_summaries_count_what_they_hold():
    take = _take(np.random.default_rng(3), missing=0.25)
    seen = 100 * (~np.isnan(take.positions[..., 0])).mean()
    result = LabelResult(take, [], np.array([4, 9]))
    assert result.summary() == (f"40 frames, 4 labels, {seen:.1f} % of label-frames filled; hand frame not found in "
                                f"2 frames (first: 4)")
    masks = [np.zeros((40, 4), bool) for _ in range(6)]
    masks[1][:3] = True  # 12 spikes
    masks[5][0, 0] = True
    report = CleanReport(*masks)
    assert report.counts()["outlier_removed"] == 12
    assert "and 12 spikes" in report.summary() and "1 of 160 samples missing" in report.summary()
    fill = FillReport("linear", 50, 3, 26, 1, 2, ("x",))
    assert fill.summary() == ("26 samples in 3 gaps filled (linear, gaps up to 50 frames), 1 gaps (2 samples) left "
                              "missing; not in the model, left as they were: x")
    positions = np.zeros((2, 2, 3))
    positions[0, 1] = np.nan
    views = np.array([[3, 0], [4, 2]])
    tri = TriangulatedMarkers(positions, ("a", "b"), 100.0, np.array([[1.0, np.nan], [2.0, 3.0]]), views,
                              np.zeros((2, 2)), np.array([True] * 9 + [False]))
    assert tri.counts()["points"] == 3 and tri.counts()["rejected"] == 1
    assert tri.summary() == ("2 frames, 2 markers, 3 points from 10 detections (1 rejected), mean reprojection "
                             f"error 2.00 px over {(3 + 4 + 2) / 3:.1f} views")


@pytest.mark.parametrize("name", ["handcap.core.markers.MarkerSequence", "handcap.core.motion.HandMotion",
                                  "handcap.core.motion.ObjectMotion", "handcap.labeling.take.LabelResult",
                                  "handcap.labeling.score.LabelScore", "handcap.layouts.check.LayoutCheck",
                                  "handcap.multiview.clean.CleanReport", "handcap.multiview.intrinsics.Intrinsics",
                                  "handcap.multiview.reconstruct.TriangulatedMarkers",
                                  "handcap.multiview.rig.RigCalibration", "handcap.objects.rigid.RigidTrack",
                                  "handcap.occlusion.fill.FillReport", "handcap.occlusion.model.OcclusionModel",
                                  "handcap.solve.calibration.Calibration", "handcap.synth.scene.SynthCapture",
                                  "handcap.steps.step.Step"])
def test_every_result_a_step_returns_has_a_text_summary(name):
    module, _, cls = name.rpartition(".")
    summary = getattr(getattr(importlib.import_module(module), cls), "summary", None)
    assert callable(summary) and summary.__annotations__.get("return") == "str"


def test_calibration_drops_the_markers_a_take_never_shows_only_when_asked(tmp_path):
    from handcap.hand.attachment import MarkerAttachment
    from handcap.steps.solve import calibrate_markers
    from handcap.synth.scene import SynthConfig, synthesize

    capture = synthesize(SynthConfig(motion="calibration", frames=60, seed=3, dropout=0.0, swap_rate=0.0,
                                     ghost_rate=0.0), progress=False)
    markers = capture.markers
    hidden = markers.positions.copy()
    hidden[:, markers.index("ring_tip")] = np.nan  # no camera ever saw it
    write_markers(MarkerSequence(hidden, markers.names, markers.rate), tmp_path / "calib.c3d")
    with pytest.raises(HandcapError, match="1 of the layout's 13 markers never seen .*: ring_tip; .*--drop-unseen"):
        calibrate_markers(tmp_path / "calib.c3d", tmp_path / "a.npz", layout="glove-13")
    with pytest.warns(UserWarning, match="1 of the layout's 13 markers were never seen"):
        done = calibrate_markers(tmp_path / "calib.c3d", tmp_path / "a.npz", layout="glove-13", drop_unseen=True)
    attachment = MarkerAttachment.load(tmp_path / "a.npz")
    assert "ring_tip" not in attachment.marker_names and len(attachment.marker_names) == 12
    assert any("never seen" in w for w in attachment.warnings) and done.result.mre < 0.002


def test_a_layout_subset_keeps_order_and_rigid_markers():
    from handcap.layouts import load_layout

    layout = load_layout("glove-13")
    part = layout.subset(reversed(layout.names[2:]))
    assert part.names == layout.names[2:] and set(part.rigid) == set(layout.rigid) & set(layout.names[2:])
