"""handcap demo --images: rendered images -> detect -> triangulate -> clean -> calibrate -> solve, against truth."""

from __future__ import annotations

import json

import numpy as np
import pytest

from handcap.synth.config import SynthConfig

pytest.importorskip("moderngl", reason="the demo renders its images with moderngl (extra 'images')")



def test_demo_from_images_runs_every_stage_and_scores_it(gl_ok, tmp_path, monkeypatch, capsys):
    import handcap.demo_images as demo_images  # loads torch
    from handcap.cli import main  # loads torch
    from handcap.multiview import read_detections

    small = {"calibration": SynthConfig(layout="dense-patches", motion="calibration", frames=3, rate=4.0, seed=8,
                                        subject_seed=21, cameras=4, min_views=2),
             "take": SynthConfig(layout="dense-patches", motion="calibration", frames=2, rate=4.0, seed=9,
                                 subject_seed=21, cameras=4, min_views=2),
             "cube": SynthConfig(layout="dense-patches", motion="turn-cube", moves="R", rate=8.0, seed=5,
                                 subject_seed=21, cameras=4, min_views=2)}
    monkeypatch.setattr(demo_images, "IMAGE_DEMO_CONFIGS", small)
    out = tmp_path / "demo"
    assert main(["demo", "--images", "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    summary = json.loads((out / "summary.json").read_text())
    # The cube turned R, tracked from its facelet patches' corners (track-object --articulated cube2x2-patches).
    assert summary["cube_cube_moves"] == summary["cube_cube_moves_turned"] == "R"
    assert summary["cube_cube_position_error_median_mm"] < 1.0 and summary["cube_cube_cubie_error_median_deg"] < 1.0
    assert (out / "cube" / "cube_motion.npz").is_file()
    for key in ("calibration", "take"):
        assert len(list((out / key / "images").rglob("*.png"))) == 4 * small[key].frames
        detections = read_detections(out / key / "detections.npz")  # the 2D detections File contract
        assert detections.camera_names == tuple(f"cam_{k}" for k in range(4))
        # The named corners: most of those named lie at their true pixels, and they triangulate near the truth.
        assert summary[f"{key}_named_corners"] > 100
        assert summary[f"{key}_misnamed_fraction"] < 0.02
        assert summary[f"{key}_triangulation_median_mm"] < 0.3
        assert 0.85 * 5.0 < summary[f"{key}_patch_square_mm"] < 1.15 * 5.0  # the printed 5 mm, as the skin bends
        # The squares named from the other cameras (and found by the second look there) are in the file, marked.
        marked = np.load(out / key / "detections.npz")["block_from_views"]
        assert int(marked.sum()) == summary[f"{key}_squares_named_from_views"] + summary[
            f"{key}_squares_named_from_frames"] + summary[f"{key}_squares_found_by_a_second_look"]
        # The first camera's detections drawn over its frames, to look at.
        assert sorted(p.name for p in (out / key / "overlay" / "cam_0").iterdir()) == [
            f"{t:06d}.jpg" for t in range(small[key].frames)]
    assert np.isfinite(summary["solve_mre_mm"]) and np.isfinite(summary["joint_error_mm"])
    assert "take_triangulation_median_mm" in printed and "wrote" in printed
