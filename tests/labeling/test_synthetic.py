"""The labeler on a synthetic glove-13 grasp: occlusion by the held cylinder, ghosts, its markers in the stream."""

import numpy as np
import pytest

from handcap.core.points import PointCloudSequence
from handcap.labeling import LabelingModel, RigidSet, label_take, score_labels
from handcap.layouts import load_layout
from handcap.synth.scene import SynthConfig, synthesize


@pytest.fixture(scope="module")
def grasp():
    layout = load_layout("glove-13")
    rom = synthesize(SynthConfig(layout="glove-13", motion="random", frames=1200, seed=11, subject_seed=5, cameras=8))
    take = synthesize(SynthConfig(layout="glove-13", motion="grasp", frames=600, seed=12, subject_seed=5, cameras=8))
    model = LabelingModel.train(rom.labeled_points(layout.names), layout.names, layout.rigid)
    return layout, model, take, take.labeled_points(layout.names)


def test_glove_grasp_with_the_object_known(grasp):
    layout, model, take, truth = grasp
    om = take.object_motion
    cylinder = RigidSet.for_object(om.marker_names, om.canonical)
    result = label_take(take.points, model, objects=[cylinder])
    score = score_labels(result.markers, truth)
    without = score_labels(label_take(take.points, model).markers, truth)
    # Measured here: 100 % correct with the cylinder known; 97.6 % correct, 1.5 % erroneous without it.
    assert score.fraction("correct") > 0.995 and score.fraction("erroneous") < 0.3 * without.fraction("erroneous")
    # The cylinder's markers are labelled too, and almost never with a finger's point.
    hand = take.truth["positions"][:, :len(layout.names)]
    got = result.markers.positions[:, len(layout.names):]
    near = np.linalg.norm(hand[:, None] - got[:, :, None], axis=-1).min(axis=2)  # (T, objects)
    labelled = ~np.isnan(got[..., 0])
    assert labelled.mean() > 0.5 and (near[labelled] < 0.002).mean() < 0.01


def test_object_markers_are_the_hard_case_without_the_object(grasp):
    # Without the object's shape, its markers moving with the hand pass for hidden finger markers.
    layout, model, take, truth = grasp
    without = score_labels(label_take(take.points, model).markers, truth)
    obj = take.truth["positions"][:, len(layout.names):]
    frames = [pts[np.linalg.norm(pts[:, None] - obj[t][None], axis=-1).min(axis=1) > 0.003]
              for t, pts in enumerate(take.points.frames)]
    alone = score_labels(label_take(PointCloudSequence(tuple(frames), take.points.rate), model).markers, truth)
    assert alone.fraction("correct") > 0.995
    assert without.fraction("erroneous") > alone.fraction("erroneous")


def test_an_unknown_objects_markers_do_not_lose_the_hand(grasp):
    # The cylinder's markers, unknown to the labeler, fit no label. Counted over the points alone, the frames' fit
    # put the hand frame in doubt until the adaptation settled, and the online labeler lost frames 0-84 (67 frames,
    # 87.1 % correct, 11.1 % of the points hidden). Each label still finds its own marker: counted over the
    # labels too, no frame is lost (98.2 % correct, the same 1.7 % wrong: object markers taken for fingers').
    layout, model, take, truth = grasp
    result = label_take(take.points, model)
    score = score_labels(result.markers, truth)
    assert len(result.lost_frames) <= 5
    assert score.fraction("false_occlusion") < 0.01 and score.fraction("correct") > 0.97
    # (A look-alike hand frame is still doubted: tests/labeling/test_adapt.py, the look-alike in the first frame.)


def test_an_unknown_object_is_found_by_its_shape_named_online_and_labelled_offline(grasp):
    # The cylinder not given: its markers keep their distances as no leftover points of the hand or ghosts do.
    # Online it is named in a warning; offline its markers are labelled object:0, ... and kept out of the
    # fingers' candidates (measured: 97.5 / 2.1 -> 100.0 / 0.0 % correct / wrong of the hand's labels).
    layout, model, take, truth = grasp
    online = label_take(take.points, model)
    assert any("keep their distances, as a rigid body's markers do" in w and "label the take offline" in w
               for w in online.warnings)
    assert not any(n.startswith("object:") for n in online.markers.names)
    offline = label_take(take.points, model, offline=True)
    found = [n for n in offline.markers.names if n.startswith("object:")]
    assert 3 <= len(found) <= len(take.object_motion.marker_names)
    assert any(f"labelled {found[0]}-{found[-1]}" in w for w in offline.warnings)
    score = score_labels(offline.markers, truth)
    assert score.fraction("correct") > 0.995 and score.fraction("erroneous") < 0.001
    # Each object label holds one of the cylinder's markers wherever it is given.
    cylinder = take.truth["positions"][:, len(layout.names):]
    got = offline.markers.positions[:, [offline.markers.index(n) for n in found]]
    near = np.linalg.norm(cylinder[:, None] - got[:, :, None], axis=-1)  # (T, found, cylinder markers)
    given = ~np.isnan(got[..., 0])
    assert given.mean() > 0.5 and (np.nanmin(near, axis=2)[given] < 0.002).mean() > 0.99


def test_two_unknown_objects_are_found_one_after_the_other_offline(grasp):
    # Besides the held cylinder, a tool of five markers turns slowly half a metre away; neither is given.
    from scipy.spatial.transform import Rotation

    layout, model, take, truth = grasp
    tool = np.array([[0.0, 0.0, 0.0], [0.06, 0.0, 0.0], [0.0, 0.09, 0.0], [0.04, 0.03, 0.05], [0.1, 0.07, 0.02]])
    t = np.arange(take.points.n_frames) / take.points.rate
    turns = Rotation.from_rotvec(np.outer(0.8 * t, [0.3, 0.9, 0.3])).as_matrix()
    centre = np.mean([f.mean(axis=0) for f in take.points.frames if len(f)], axis=0) + [0.5, 0.0, 0.1]
    frames = tuple(np.vstack([f, tool @ turns[k].T + centre + [0.1 * np.sin(t[k]), 0.0, 0.0]])
                   for k, f in enumerate(take.points.frames))
    result = label_take(PointCloudSequence(frames, take.points.rate), model, offline=True)
    sizes = sorted(sum(n.startswith(f"{body}:") for n in result.markers.names) for body in ("object", "object2"))
    assert sizes[0] == len(tool) and sizes[1] <= len(take.object_motion.marker_names)  # in either order
    assert sum("keep their distances, as a rigid body's markers do" in w for w in result.warnings) == 2
    score = score_labels(result.markers, truth)
    assert score.fraction("correct") > 0.995 and score.fraction("erroneous") < 0.001
