"""The labeler adapting to a take of another day (issue 14): synthetic joints-19 takes with known truth."""

import warnings

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from handcap import MarkerSequence
from handcap.core.errors import HandcapWarning
from handcap.labeling import LabelingModel, corrupt, label_take, move_rigid_set, score_labels
from handcap.labeling.adapt import register_to_model, rigid_from_take
from handcap.labeling.model import rigid_transforms as _rigid_transforms
from handcap.layouts import load_layout
from handcap.objects.rigid import canonical_from_markers
from handcap.synth.scene import SynthConfig, synthesize

RIGID = ["hand_top", "hand_left", "hand_right"]


@pytest.fixture(scope="module")
def takes():
    layout = load_layout("joints-19")
    rom = synthesize(SynthConfig(layout="joints-19", motion="random", object="none", frames=1200, seed=11,
                                 subject_seed=5, cameras=8)).labeled_points(layout.names)
    test = synthesize(SynthConfig(layout="joints-19", motion="random", object="none", frames=500, seed=21,
                                  subject_seed=5, cameras=8)).labeled_points(layout.names)
    model = LabelingModel.train(rom, layout.names, layout.rigid)
    return layout, model, rom, test


def moved_triad(take, rotation, shift, scale=1.0):
    """The take with its back triad put elsewhere on the hand, as a glove put on again on another day."""
    return move_rigid_set(take, RIGID, rotation, shift, scale=scale)


def test_move_rigid_set_moves_the_set_and_keeps_the_rest(takes):
    # Independent check: in every frame the moved triad has the scaled distances, the fingers are untouched,
    # and the triad's offset from a finger marker, seen in the triad's own frame, changed by the same amount.
    _, _, _, test = takes
    turn = Rotation.from_rotvec([0.0, 0.2, 0.1]).as_matrix()
    moved = moved_triad(test, turn, np.array([0.004, 0.0, -0.003]), scale=1.1)
    idx = [test.index(n) for n in RIGID]
    others = [i for i in range(len(test.names)) if i not in idx]
    np.testing.assert_array_equal(moved.positions[:, others], test.positions[:, others])
    whole = ~np.isnan(test.positions[:, idx, 0]).any(axis=1)
    i, j = np.triu_indices(3, 1)
    before = np.linalg.norm(test.positions[whole][:, idx][:, i] - test.positions[whole][:, idx][:, j], axis=-1)
    after = np.linalg.norm(moved.positions[whole][:, idx][:, i] - moved.positions[whole][:, idx][:, j], axis=-1)
    np.testing.assert_allclose(np.median(after / before, axis=0), 1.1, atol=0.01)
    centre_shift = np.linalg.norm(moved.positions[whole][:, idx].mean(1) - test.positions[whole][:, idx].mean(1),
                                  axis=1)
    np.testing.assert_allclose(centre_shift, 0.005, atol=0.0002)  # the set's centre moved by |shift| = 5 mm
    assert not np.shares_memory(moved.positions, test.positions)


def test_moved_spatial_model_equals_moved_points(takes):
    # Independent computation: the moved model on points x gives the trained model's value on R x + t.
    _, model, _, _ = takes
    rng = np.random.default_rng(0)
    rot = Rotation.from_rotvec(rng.normal(0, 0.3, 3)).as_matrix()
    trans = rng.normal(0, 0.01, 3)
    points = model.spatial.means[:, 0] + rng.normal(0, 0.01, (len(model.spatial.names), 3))
    np.testing.assert_allclose(model.spatial.moved(rot, trans).log_likelihood(points),
                               model.spatial.log_likelihood(points @ rot.T + trans), rtol=1e-9, atol=1e-9)


@pytest.mark.parametrize("labelled", [False, True])
def test_registration_recovers_a_known_misalignment(takes, labelled):
    # The training take's own points, moved by a known 13 degree / 13 mm transform: registration finds it.
    _, model, rom, _ = takes
    n_rigid = len(model.rigid.names)
    positions = np.stack([rom.positions[:, rom.index(n)] for n in model.names], axis=1)
    rot, trans, ok = _rigid_transforms(model.rigid.canonical, positions[:, :n_rigid])
    local = np.einsum("tji,tmj->tmi", rot[ok], positions[ok, n_rigid:] - trans[ok, None])[::4]
    labels = np.broadcast_to(np.arange(local.shape[1]), local.shape[:2])
    seen = ~np.isnan(local[..., 0])
    local, labels = local[seen], labels[seen]
    true_rot = Rotation.from_rotvec(np.deg2rad(13) * np.array([0.3, -0.8, 0.52]) / np.linalg.norm([0.3, -0.8, 0.52]))
    true_rot = true_rot.as_matrix()
    true_trans = np.array([0.008, -0.006, 0.0085])  # 13 mm
    take_local = (local - true_trans) @ true_rot  # model = R take + t
    r, t = register_to_model(model.spatial, take_local, labels if labelled else None)
    angle = np.degrees(Rotation.from_matrix(r @ true_rot.T).magnitude())
    assert angle < 0.5 and np.linalg.norm(t - true_trans) < 0.001


def test_rigid_set_relearned_from_a_take_with_other_distances(takes):
    # Issue 14: a take whose triad distances differ by 3.5 mm from training; the trained tolerance is tighter.
    _, model, _, test = takes
    stretched = moved_triad(test, np.eye(3), np.zeros(3), scale=1.08)
    idx = [stretched.index(n) for n in RIGID]
    truth = canonical_from_markers(stretched.positions[:, idx])
    frames = [f[~np.isnan(f[:, 0])] for f in stretched.positions]
    new = rigid_from_take(model.rigid, frames, width=0.01)
    assert new is not None
    i, j = np.triu_indices(3, 1)
    got = np.linalg.norm(new.canonical[i] - new.canonical[j], axis=1)
    want = np.linalg.norm(truth[i] - truth[j], axis=1)
    trained = np.linalg.norm(model.rigid.canonical[i] - model.rigid.canonical[j], axis=1)
    assert np.abs(want - trained).max() > 0.003  # the case of the issue
    # Within a third of the labeler's own distance tolerance (2.2 mm on this take): the skin under the triad
    # is not rigid, so the take's mean shape is itself known to a few tenths of a millimetre.
    np.testing.assert_allclose(got, want, atol=model.rigid.tolerance / 3)


@pytest.fixture(scope="module")
def triad_13(takes):
    # The other-day take: the back triad 13 degrees / 13 mm from where it sat in the training take.
    _, model, _, test = takes
    axis = np.array([0.48, 0.6, -0.64])
    turn = Rotation.from_rotvec(np.deg2rad(13) * axis / np.linalg.norm(axis)).as_matrix()
    moved = moved_triad(test, turn, np.array([0.0075, -0.0075, 0.0075]))
    return corrupt(moved, ghost_rate=2.0, dropout=0.05, seed=0)


def test_triad_moved_relative_to_the_fingers_before(takes, triad_13):
    # Before: a spatial model trained on one take does not fit the other day's (measured: 25-50 % correct).
    _, model, _, _ = takes
    unlabeled, truth = triad_13
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", HandcapWarning)
        score = score_labels(label_take(unlabeled, model, adapt=False).markers, truth)
    assert score.fraction("correct") < 0.9


def test_triad_moved_relative_to_the_fingers_adapted(takes, triad_13):
    _, model, _, _ = takes
    unlabeled, truth = triad_13
    online = score_labels(label_take(unlabeled, model).markers, truth)
    offline = label_take(unlabeled, model, offline=True)
    two_pass = score_labels(offline.markers, truth)
    # Measured on this take: online 92.7 % correct / 0.90 % wrong (its first 25 frames, before the model is
    # aligned, fit too poorly to be trusted: withheld; labelled, they gave 95.1 % / 1.5 %), offline two passes
    # 98.6 % / 0.06 % (the goal, 99 % / 0.1 %, is met with the hand check: benchmark 7).
    assert online.fraction("correct") > 0.9 and online.fraction("erroneous") < 0.012
    assert two_pass.fraction("correct") > 0.98 and two_pass.fraction("erroneous") < 0.005
    assert offline.model is not None


def test_adaptation_does_not_hurt_a_take_of_the_same_day(takes):
    _, model, _, test = takes
    unlabeled, truth = corrupt(test, ghost_rate=2.0, dropout=0.05, seed=1)
    plain = score_labels(label_take(unlabeled, model, adapt=False).markers, truth)
    online_result = label_take(unlabeled, model)
    offline_result = label_take(unlabeled, model, offline=True)
    online, offline = (score_labels(r.markers, truth) for r in (online_result, offline_result))
    assert not any("rigid markers' distances" in w or "not found where" in w or "for the median label" in w
                   for w in online_result.warnings + offline_result.warnings)
    assert online.fraction("correct") >= plain.fraction("correct") - 0.003
    assert offline.fraction("correct") >= plain.fraction("correct") - 0.001
    assert offline.fraction("erroneous") <= plain.fraction("erroneous") + 0.001


def test_a_rigid_set_relearned_from_the_take_is_a_warning(takes):
    # Issue 14: a triad put back with its distances 8 % (3-5 mm) longer is re-learned from the take; the labels
    # rest on that, and the result says so (printed and stored), online and offline.
    _, model, _, test = takes
    stretched = moved_triad(test, np.eye(3), np.zeros(3), scale=1.08)
    idx = [test.index(n) for n in RIGID]
    i, j = np.triu_indices(3, 1)

    def distances(take):  # (T, 3) distances between the triad's markers, metres
        p = take.positions[:, idx]
        return np.linalg.norm(p[:, i] - p[:, j], axis=-1)

    grown = np.nanmedian(distances(stretched) - distances(test), axis=0)
    unlabeled, _ = corrupt(stretched, ghost_rate=2.0, dropout=0.05, seed=0)
    for options in ({}, {"offline": True}):
        with pytest.warns(HandcapWarning, match="differ from training by up to"):
            result = label_take(unlabeled, model, **options)
        line = next(w for w in result.warnings if "rigid markers' distances" in w)
        assert line in result.markers.warnings
        said = float(line.split("by up to ")[1].split(" mm")[0])
        assert abs(said - 1000 * grown.max()) < 1.5  # the largest change, as the take shows it
        assert result.rigid is not None and result.rigid is not model.rigid


def test_online_frames_in_doubt_are_withheld_not_mislabelled(takes):
    # Issue 14, live: a triad put back 8 % larger is not found at its trained distances, and a look-alike set of
    # knuckle and finger markers is taken for it. Its frames fit the model far worse than the model typically
    # fits (SpatialModel.typical_fit): their labels are withheld and they count as lost, so the rigid set is
    # re-learned from the take within the first second. Measured on this take: 77.97 % correct / 7.38 % wrong
    # labelling them; 91.16 % / 0.90 % withholding them (36 frames, all in the first 100).
    _, model, _, test = takes
    unlabeled, truth = corrupt(moved_triad(test, np.eye(3), np.zeros(3), scale=1.08), ghost_rate=2.0,
                               dropout=0.05, seed=0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", HandcapWarning)
        result = label_take(unlabeled, model)
    score = score_labels(result.markers, truth)
    assert score.fraction("erroneous") < 0.015 and score.fraction("correct") > 0.88
    assert 10 <= len(result.lost_frames) <= 60 and result.lost_frames.max() < 120
    withheld = [lab for t, lab in enumerate(result.labels) if t in set(result.lost_frames.tolist())]
    assert all((lab < 0).all() for lab in withheld)  # none rather than wrong


def test_a_triad_side_a_centimetre_longer_is_found_with_its_corners_named_right(takes):
    # The triad's top marker stuck on elsewhere: 10 mm further from hand_left, 2 mm nearer hand_right (seed 37 of
    # benchmarks/labeling.py section 9: a side 10.4 mm longer than training's). Named as trained, the triangle
    # lies beyond the search's 10 mm; with hand_left and hand_right named the other way round, within, and it
    # recurs as often: each naming is tried and the spatial fit picks the one in whose hand frame the other
    # markers fit (the triad was missed, and the take not labelled: 28 % correct offline).
    _, model, _, test = takes
    take = test.select(test.names)
    idx = [take.index(n) for n in RIGID]
    c = canonical_from_markers(take.positions[:, idx])  # top, left, right in the take's hand frame
    i, j = np.triu_indices(3, 1)
    trained = np.linalg.norm(model.rigid.canonical[i] - model.rigid.canonical[j], axis=1)  # (tl, tr, lr)
    to_left, to_right = trained[0] + 0.010, trained[1] - 0.002
    # The top marker's new place: in the triad's plane, at those distances from the other two (on its side).
    left, right = c[1], c[2]
    span = np.linalg.norm(right - left)
    u = (right - left) / span
    normal = np.cross(c[1] - c[0], c[2] - c[0])
    v = np.cross(normal / np.linalg.norm(normal), u)
    x = (to_left**2 - to_right**2 + span**2) / (2 * span)
    top = left + x * u + np.sign(np.dot(c[0] - left, v)) * np.sqrt(to_left**2 - x**2) * v
    rot, trans, ok = _rigid_transforms(c, take.positions[:, idx])
    take.positions[ok, idx[0]] = np.einsum("tij,j->ti", rot[ok], top) + trans[ok]
    want = np.linalg.norm(np.array([top, left, right])[i] - np.array([top, left, right])[j], axis=1)
    assert np.abs(want - trained).max() > 0.0099  # beyond the search, named as trained
    frames = [f[~np.isnan(f[:, 0])] for f in take.positions]
    new = rigid_from_take(model.rigid, frames, spatial=model.spatial, width=0.01)
    got = np.linalg.norm(new.canonical[i] - new.canonical[j], axis=1)
    np.testing.assert_allclose(got, want, atol=model.rigid.tolerance / 3)


def test_the_online_search_for_the_rigid_set_starts_from_the_trained_one(takes):
    # A set re-learned wrongly (from a take's first few frames, where look-alike triangles of finger markers
    # recur as often) must not move the next search: searched for near it, the take's own triad (3 mm from
    # training, 16 mm from the wrong set) was out of reach, and each search drifted further (seed 45 of
    # benchmarks/labeling.py section 9: 7, 12, then 21 mm from training, 9 % of the points labelled).
    from handcap.labeling import OnlineLabeler
    from handcap.labeling.frame import HandFrameFinder
    from handcap.labeling.rigid_set import RigidSet

    _, model, _, test = takes
    stretched = moved_triad(test, np.eye(3), np.zeros(3), scale=1.07)
    frames = [f[~np.isnan(f[:, 0])] for f in stretched.positions[:100]]
    labeler = OnlineLabeler(model)
    trained = model.rigid
    wrong = RigidSet(trained.names, 1.35 * trained.canonical, trained.tolerance)
    labeler.finder = HandFrameFinder(wrong)
    assert labeler._adaptation.relearn_rigid(frames)
    i, j = np.triu_indices(3, 1)
    truth = canonical_from_markers(stretched.positions[:, [stretched.index(n) for n in RIGID]])
    got = np.linalg.norm(labeler.finder.rigid.canonical[i] - labeler.finder.rigid.canonical[j], axis=1)
    want = np.linalg.norm(truth[i] - truth[j], axis=1)
    np.testing.assert_allclose(got, want, atol=trained.tolerance / 3)
    # Once it holds the take's triad, searching again keeps it.
    assert not labeler._adaptation.relearn_rigid(frames)


def test_offline_another_subject_takes_the_rigid_set_the_online_pass_found(takes):
    # Issue 14: on another subject's take the triad's distances are 8 mm off (12 mm before joints-19's top
    # triad marker moved off the knuckles); the search over the whole take can take a look-alike set of knuckle
    # and finger markers for it, the online pass (its re-learned sets judged once the model is aligned) finds
    # the triad, and the offline labeling keeps whichever labels more points.
    layout, model, _, _ = takes
    other = synthesize(SynthConfig(layout="joints-19", motion="random", object="none", frames=500, seed=21,
                                   subject_seed=7, cameras=8)).labeled_points(layout.names)
    unlabeled, truth = corrupt(other, ghost_rate=2.0, dropout=0.05, seed=0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", HandcapWarning)
        result = label_take(unlabeled, model, offline=True)
    score = score_labels(result.markers, truth)
    assert score.fraction("correct") > 0.95 and score.fraction("erroneous") < 0.02
    # Its pinky_mcp sits 15 mm from where the trained model puts it: found by the wider search, and said so.
    assert any(w.startswith("pinky_mcp not found where the training take puts it") for w in result.warnings)
    # The set it labelled with is the subject's triad: the warning gives its change from training, which the
    # truth's triad distances give independently.
    idx = [other.index(n) for n in RIGID]
    i, j = np.triu_indices(3, 1)
    true = canonical_from_markers(other.positions[:, idx])
    change = np.abs(np.linalg.norm(true[i] - true[j], axis=1)
                    - np.linalg.norm(model.rigid.canonical[i] - model.rigid.canonical[j], axis=1)).max()
    line = next(w for w in result.warnings if "rigid markers' distances" in w)  # never silent
    assert change > 0.005 and abs(float(line.split("by up to ")[1].split(" mm")[0]) - 1000 * change) < 1.5


def test_a_marker_stuck_on_elsewhere_is_found_by_a_wider_search(takes):
    # Issue 14: one marker 15 mm from its trained place (in the hand frame), the rest as trained. Its components
    # are about 1 mm wide, so the trained model never gives its label; the offline labeling searches again with
    # every component widened, moves that label alone, and says so. The label's truth is the moved marker.
    layout, model, _, test = takes
    take = test[:300].select(test.names)
    rot, _, _ = _rigid_transforms(model.rigid.canonical, take.positions[:, [take.index(n) for n in RIGID]])
    column = take.index("pinky_mcp")
    take.positions[:, column] += rot @ np.array([0.012, 0.0, -0.009])
    unlabeled, truth = corrupt(take, ghost_rate=2.0, dropout=0.05, seed=1)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", HandcapWarning)
        result = label_take(unlabeled, model, offline=True)
    score = score_labels(result.markers, truth)
    k = score.names.index("pinky_mcp")
    seen = score.correct[k] + score.erroneous[k] + score.false_occlusion[k]
    assert score.correct[k] >= 0.95 * seen and score.erroneous[k] == 0
    # The other labels: measured 97.74 / 0.55 % correct / wrong, against 98.68 / 0.12 for the same take without
    # the moved marker (the wider search costs thumb_tip and pinky_tip some frames: not solved yet).
    assert score.fraction("correct") > 0.97 and score.fraction("erroneous") < 0.008
    assert [w for w in result.warnings if "not found where the training take puts" in w] == [
        "pinky_mcp not found where the training take puts it; labelled after a search 5 mm wider (another subject "
        "or marker placement): check this label, or train on a take of this subject"]


def test_a_marker_missing_from_the_take_is_a_warning(takes):
    # A glove that lost a marker: its label is given in (almost) no frame, and the result says so instead of
    # quietly leaving a column empty. The figures in the line are the labelled shares of the result itself.
    layout, model, _, test = takes
    take = test.select(test.names)
    take.positions[:, take.index("index_tip")] = np.nan
    unlabeled, _ = corrupt(take, ghost_rate=2.0, dropout=0.05, seed=1)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", HandcapWarning)
        result = label_take(unlabeled, model)
    given = np.mean(~np.isnan(result.markers.positions[..., 0]), axis=0)
    median = np.median([given[result.markers.index(n)] for n in model.spatial.names])
    line = next(w for w in result.warnings if " % for the median label" in w)
    assert line.startswith(f"index_tip labelled in {100 * given[result.markers.index('index_tip')]:.0f} % of the "
                           f"frames, against {100 * median:.0f} % for the median label: hidden most of the take, "
                           "missing from it")
    assert line in result.markers.warnings


def test_a_lost_hand_frame_is_a_warning_stored_with_the_result(takes):
    # The back markers hidden in every frame (and the knuckle markers, rigid with them, that can pass for a
    # triad): the hand frame is lost, and the result says so (it was exit 0 without a word).
    _, model, _, test = takes
    positions = test[:200].positions.copy()
    positions[:, [test.index(n) for n in RIGID + [f"{f}_mcp" for f in ("index", "middle", "ring", "pinky")]]] = np.nan
    unlabeled, _ = corrupt(MarkerSequence(positions, test.names, test.rate), ghost_rate=0.0, dropout=0.0, seed=0)
    with pytest.warns(HandcapWarning, match="hand frame lost in"):
        result = label_take(unlabeled, model, adapt=False)
    assert any("hand frame lost" in w for w in result.warnings)
    assert any("labels for" in w for w in result.warnings)
    assert result.markers.warnings == result.warnings
    # Adapting, the labeler may re-learn a "rigid set" from other points; the few labels still warn.
    with pytest.warns(HandcapWarning):
        adapted = label_take(unlabeled, model)
    assert adapted.warnings


def test_several_training_takes(takes):
    # Two takes of other days (the second with its triad put on again 13 degrees / 13 mm away): pooled in
    # their own hand frames, the mixtures are as tight as from one take; the tolerance is the within-take spread.
    layout, model, rom, _ = takes
    turn = Rotation.from_rotvec(np.deg2rad(13) * np.array([0.0, 0.6, 0.8])).as_matrix()
    other_day = moved_triad(rom, turn, np.array([0.0075, -0.0075, 0.0075]))
    both = LabelingModel.train([rom[:600], other_day[600:]], layout.names, layout.rigid)
    # Trained on both halves, labelling a take of the first day is as good as with a model of the first day.
    np.testing.assert_allclose(both.rigid.canonical, model.rigid.canonical, atol=0.001)
    assert 0.5 * model.rigid.tolerance < both.rigid.tolerance < 2 * model.rigid.tolerance
    spread_one = np.sqrt(np.trace(np.linalg.inv(model.spatial.precision_chol @ np.swapaxes(
        model.spatial.precision_chol, -1, -2)), axis1=-2, axis2=-1)).mean()
    spread_two = np.sqrt(np.trace(np.linalg.inv(both.spatial.precision_chol @ np.swapaxes(
        both.spatial.precision_chol, -1, -2)), axis1=-2, axis2=-1)).mean()
    assert spread_two < 1.3 * spread_one
    with pytest.raises(Exception, match="different frame rates"):
        LabelingModel.train([rom, MarkerSequence(rom.positions, rom.names, 50.0)], layout.names, layout.rigid)


def test_a_smooth_but_spatially_unlikely_point_starts_a_track(takes, monkeypatch):
    # Issue 14: a marker where the spatial model puts no label (the index fingertip 4 cm further out along its
    # finger, as on a longer finger) but moving as a marker moves. Without births its label is left out in most
    # frames; a chain of 5 smooth frames starts the label's track on it once the labeler has aligned to the take.
    # Births also start tracks on wrong points, which is why they are off by default (offline too): on this take
    # the label was on the moved point in 11.8 % of the frames without births, 17.2 % with them, but wrong 0.37 ->
    # 1.55 % (with fingers that passed through each other in synth, 22 -> 51 % and wrong 1.45 -> 0.25 %).
    # Births alone: the online search of a hardly given label 5 mm wider (adapt.WIDEN_AFTER) is off here.
    monkeypatch.setattr("handcap.labeling.adapt.WIDEN_AFTER", 10**9)
    _, model, _, test = takes
    pos = test.positions.copy()
    tip, dip = test.index("index_tip"), test.index("index_dip")
    step = pos[:, tip] - pos[:, dip]
    pos[:, tip] += 0.04 * step / np.linalg.norm(step, axis=1, keepdims=True)
    moved = MarkerSequence(pos, test.names, test.rate)
    covered, score = {}, {}
    for birth in (0, 5):
        result = label_take(moved, model, birth=birth)
        got = result.markers.positions[:, result.markers.index("index_tip")]
        covered[birth] = np.isclose(got, pos[:, tip]).all(axis=1).mean()
        score[birth] = score_labels(result.markers, moved)
    assert covered[0] < 0.35
    assert covered[5] > 1.3 * covered[0]
    assert score[5].fraction("erroneous") > score[0].fraction("erroneous")  # the cost that keeps them off


def test_a_look_alike_found_in_the_first_frame_is_left_for_the_hand(takes):
    # Issue 14, another subject's take: in its first frame a back marker was hidden and three finger markers
    # matched the triad's distances; the labeler locked onto them and, with its yardstick set by that frame,
    # tracked them for 50 frames with no finger labelled. Here a look-alike triad (the real one 6 cm off,
    # moving with the hand) is in the first 80 frames, and hand_top is hidden in the first. The model's own
    # typical fit flags the look-alike's frames, and the hand is found from the next frame on. Measured in
    # frames 1-79: 9.95 % correct / 41.5 % wrong before (online, not adapting; offline alike), 94.9 / 1.3 after.
    layout, model, _, test = takes
    positions = test.positions.copy()
    rigid = [test.index(n) for n in RIGID]
    look_alike = np.full((test.n_frames, 3, 3), np.nan)
    look_alike[:80] = positions[:80, rigid] + [0.05, -0.03, 0.02]
    positions[0, rigid[0]] = np.nan
    take = MarkerSequence(np.concatenate([positions, look_alike], axis=1), test.names + ("g1", "g2", "g3"),
                          test.rate)
    truth = MarkerSequence(positions, test.names, test.rate)
    for options in ({"adapt": False}, {}, {"offline": True}):
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", HandcapWarning)
            result = label_take(take, model, **options)
        start = score_labels(result.markers[1:80], truth[1:80])
        assert start.fraction("correct") > 0.92 and start.fraction("erroneous") < 0.02, options


def test_a_label_hardly_given_online_is_searched_for_wider_and_said(takes, monkeypatch):
    # Another subject's take (subject 7) labelled online with subject 5's model: some knuckle and middle markers
    # sit several millimetres from where training puts them, and are hardly given. Searched 5 mm wider (kept because
    # more of the points get a label), more are labelled right and no more wrong (measured: 83.83 -> 86.80 %
    # correct, 1.45 % wrong both ways), and a warning names the labels so searched.
    layout, model, _, _ = takes
    take = synthesize(SynthConfig(layout="joints-19", motion="random", object="none", frames=600, seed=21,
                                  subject_seed=7, cameras=8)).labeled_points(layout.names)
    result = label_take(take, model)
    assert result.widened and set(result.widened) <= set(model.spatial.names)
    assert any("labelled after a search 5 mm wider" in w and result.widened[0] in w for w in result.warnings)
    wide = score_labels(result.markers, take)
    monkeypatch.setattr("handcap.labeling.adapt.WIDEN_AFTER", 10**9)
    plain = label_take(take, model)
    assert not plain.widened and not any("5 mm wider" in w for w in plain.warnings)
    narrow = score_labels(plain.markers, take)
    assert wide.fraction("correct") > narrow.fraction("correct") + 0.015
    assert wide.fraction("erroneous") < narrow.fraction("erroneous") + 0.002


def test_another_subject_is_labelled_from_its_first_frames_as_the_stream_labels(takes, monkeypatch):
    # The live stream re-aligns the model once a second (here every 100 frames, lag 0, 2 hypotheses); another
    # subject's points fit the model only once it is aligned. Aligned provisionally every 10 frames until then,
    # subject 9's first second is labelled (measured: 77.2 % of its points right against 0.6 %; the whole 3 s take
    # 85.2 % against 39.3 %, 0.02 % wrong both ways).
    layout, model, _, _ = takes
    take = synthesize(SynthConfig(layout="joints-19", motion="random", object="none", frames=300, seed=21,
                                  subject_seed=9, cameras=8)).labeled_points(layout.names)
    scores = {}
    for provisional in (True, False):
        if not provisional:
            monkeypatch.setattr("handcap.labeling.adapt.PROVISIONAL_EVERY", 10**9)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", HandcapWarning)
            markers = label_take(take, model, hypotheses=2, adapt_every=100).markers
        scores[provisional] = score_labels(markers, take), score_labels(markers[:100], take[:100])
    (whole, first), (plain, plain_first) = scores[True], scores[False]
    assert first.fraction("correct") > 0.6 and plain_first.fraction("correct") < 0.1
    assert whole.fraction("correct") > plain.fraction("correct") + 0.3
    assert whole.fraction("erroneous") < plain.fraction("erroneous") + 0.002


def test_a_label_searched_wider_that_lies_the_other_way_round_is_exchanged(monkeypatch):
    # Section 9 of benchmarks/labeling.py, subject 43 labelled online by subject 5's model: ring_mcp holds
    # middle_mcp's marker from frame 50 on (middle_mcp's marker lies 7 mm from both labels' means, ring_mcp's
    # 20 mm from any), so middle_mcp is hardly given. Searched wider, middle_mcp takes ring_mcp's marker, and the
    # two labels' points lie the other way round than the model's means: the two are exchanged, and said as a
    # release. Measured: 1,813 -> 568 points wrong, 81.3 -> 87.9 % correct.
    layout = load_layout("joints-19")

    def take(seed, subject, frames):
        config = SynthConfig(layout="joints-19", motion="random", object="none", frames=frames, seed=seed,
                             subject_seed=subject, cameras=8)
        return synthesize(config, progress=False).labeled_points(layout.names)

    model = LabelingModel.train(take(11, 5, 2000), layout.names, layout.rigid)
    points, truth = corrupt(take(21, 43, 1000), ghost_rate=2.0, dropout=0.05, seed=0)
    results = {}
    for least in (None, 10**9):
        if least is not None:
            monkeypatch.setattr("handcap.labeling.plausible.REVERSED_LEAST", least)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", HandcapWarning)
            results[least] = label_take(points, model)
    exchanged, plain = results[None], results[10**9]
    assert any(set(r.labels) == {"middle_mcp", "ring_mcp"} for r in exchanged.released)
    assert not any(set(r.labels) == {"middle_mcp", "ring_mcp"} for r in plain.released)
    assert any("middle_mcp and ring_mcp at frame" in w for w in exchanged.warnings)
    after, before = score_labels(exchanged.markers, truth), score_labels(plain.markers, truth)
    assert after.erroneous.sum() < 0.5 * before.erroneous.sum()
    assert after.fraction("correct") > before.fraction("correct") + 0.04
    ring = list(after.names).index("ring_mcp")
    assert after.erroneous[ring] < 0.5 * before.erroneous[ring]
