"""Labels checked against the solved hand (issue 14): wrong labels removed, missed markers labelled, against the
synthetic truth; the verb's offline labelling runs the check."""

import warnings

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from handcap.core.errors import HandcapWarning
from handcap.labeling import LabelingModel, corrupt, label_take, move_rigid_set, score_labels
from handcap.layouts import load_layout
from handcap.solve import Priors, calibrate_attachment
from handcap.solve.relabel import CALIBRATION_PRIOR, check_labels
from handcap.steps.label import checked_by_hand
from handcap.synth.scene import SynthConfig, synthesize


@pytest.fixture(scope="module")
def turned():
    """A joints-19 take of another day (its back triad turned 13 degrees and moved 13 mm), its unlabelled points
    with ghosts and dropouts, the truth, and a model trained on a take of the first day (as in
    ``benchmarks/labeling.py`` section 7)."""
    layout = load_layout("joints-19")

    def take(seed, frames):
        return synthesize(SynthConfig(layout="joints-19", motion="random", object="none", frames=frames, seed=seed,
                                      subject_seed=5, cameras=8), progress=False).labeled_points(layout.names)

    model = LabelingModel.train(take(11, 2000), layout.names, layout.rigid)
    axis = np.array([0.48, 0.6, -0.64])
    turn = Rotation.from_rotvec(np.deg2rad(13) * axis / np.linalg.norm(axis)).as_matrix()
    moved = move_rigid_set(take(21, 1000), layout.rigid, turn, np.full(3, 0.0075) * [1, -1, 1])
    unlabelled, truth = corrupt(moved, ghost_rate=2.0, dropout=0.05, seed=0)
    return layout, model, unlabelled, truth


@pytest.fixture(scope="module")
def labelled(turned):
    """The turned take labelled offline, and the attachment calibrated on those labels as the verb's check
    calibrates it."""
    layout, model, unlabelled, _ = turned
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", HandcapWarning)
        markers = label_take(unlabelled, model, offline=True).markers
        priors = Priors(rest=np.zeros(27), rest_weight=CALIBRATION_PRIOR)  # as the verb's check calibrates
        return markers, calibrate_attachment(markers, layout, priors=priors).attachment


def test_the_check_removes_wrong_labels_and_labels_missed_markers(turned, labelled):
    layout, model, unlabelled, truth = turned
    labelled, attachment = labelled
    check = check_labels(labelled, unlabelled, attachment, rigid=layout.rigid)
    before, after = score_labels(labelled, truth), score_labels(check.markers, truth)
    assert after.fraction("erroneous") <= 0.001 and after.fraction("correct") >= 0.99  # issue 14's line
    assert after.fraction("erroneous") < before.fraction("erroneous")
    # Measured 99.21 -> 99.74 % correct here (wrong 0.045 -> 0.009 %); section 8 of benchmarks/labeling.py has it
    # raise every subject's correct labels (it lowered 8 of 11 by up to 0.44 points when its calibration pulled
    # the take's poses to the open hand).
    assert after.fraction("correct") > before.fraction("correct") + 0.003
    assert check.removed.sum() > 0 and check.added.sum() > 0 and check.explained.mean() > 0.9
    # every label added is a point of the frame, and the one the truth gives that marker
    names = list(check.markers.names)
    t, m = np.nonzero(check.added)
    true = truth.select(names).positions[t, m]
    assert np.isfinite(true[:, 0]).mean() > 0.95
    assert np.nanmax(np.linalg.norm(check.markers.positions[t, m] - true, axis=-1)) < 1e-9


def test_labels_swapped_between_two_fingertips_are_removed(turned):
    # The true labels with the index and middle tips swapped for 30 frames: the solved hand cannot have made
    # them, so they go (or, both gone, a tip's label takes its own point back); nothing else wrong comes in (a
    # tip left without its marker is a gap, not a guess). And
    # pinky_mcp is never labelled (another subject's may not be: it sits where the trained model expects no
    # marker): the calibration cannot place it, so the check (as the verb runs it) leaves it out, saying so, and
    # checks every other marker.
    layout, _, unlabelled, truth = turned
    names = list(truth.names)
    swapped = truth.positions.copy()
    swapped[:, names.index("pinky_mcp")] = np.nan
    i, j = names.index("index_tip"), names.index("middle_tip")
    frames = slice(300, 330)
    swapped[frames, [i, j]] = swapped[frames, [j, i]]
    labelled = truth.__class__(swapped, truth.names, truth.rate)
    assert score_labels(labelled, truth).erroneous.sum() > 50
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", HandcapWarning)
        checked, line = checked_by_hand(labelled, unlabelled, layout)
    assert line.startswith("checked against the solved hand") and "pinky_mcp never labelled: not checked" in line
    seen = np.isfinite(swapped[frames][:, [i, j], 0])
    # A swapped label is removed, or (where the other tip's label went too) given its own tip's point: measured 59
    # of the 59 seen, the solve having found the swap itself. Before it did, in 5 of the 30 frames it bent the middle
    # finger to the index tip's point (1 mm off it) and that label stayed (54 of 59).
    gone = np.isnan(checked.positions[frames][:, [i, j], 0])
    own = np.linalg.norm(checked.positions[frames][:, [i, j]] - truth.positions[frames][:, [i, j]], axis=-1) < 1e-9
    mended = (gone | own)[seen]
    print(f"swapped tip labels removed or given back: {mended.sum()} of {mended.size}")
    assert mended.mean() > 0.95 and gone[seen].any()
    after = score_labels(checked, truth)
    assert after.erroneous.sum() == (~mended).sum() and after.false_marker.sum() == 0  # nothing else wrong
    assert np.isnan(checked.positions[:, names.index("pinky_mcp")]).all()  # nothing guessed for it
    # The true labels elsewhere stay, but for those the check removes from the true labels alone: 4 (145 of
    # index_tip and pinky_tip when the check's calibration pulled to the open hand and the solve then fitted
    # the most bent poses 10 mm off; see CALIBRATION_PRIOR).
    alone = swapped.copy()
    alone[frames, [i, j]] = truth.positions[frames][:, [i, j]]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", HandcapWarning)
        base = checked_by_hand(truth.__class__(alone, truth.names, truth.rate), unlabelled, layout)[0]
    lost_alone = np.isfinite(alone[..., 0]) & np.isnan(base.positions[..., 0])
    removed = np.isfinite(swapped[..., 0]) & np.isnan(checked.positions[..., 0])
    print(f"true labels the check removes: {lost_alone.sum()}; with the swap: {removed.sum()}")
    assert lost_alone.sum() < 20 and removed.sum() < lost_alone.sum() + 2 * seen.sum() + 10


def test_labels_that_fit_no_hand_are_warnings(turned):
    # The fingers' labels rotated among the fingers (each finger's given to the next): in bursts of 6 frames the
    # check removes them and says that many labels did not fit; over a long stretch it cannot judge them and says
    # so; in every frame it checks nothing and says why. Each warning is stored with the labels.
    layout, _, unlabelled, truth = turned
    unlabelled, truth = unlabelled.frames(0, 600), truth.frames(0, 600)  # 600 of the 1000 frames are enough
    fingers = slice(3, 19)  # index, middle, ring and pinky: 4 markers each

    def rotated(frames):
        positions = truth.positions.copy()
        positions[frames, fingers] = np.roll(positions[frames, fingers], 4, axis=1)
        return truth.__class__(positions, truth.names, truth.rate)

    bursts = np.flatnonzero(np.arange(truth.n_frames) % 40 < 6)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", HandcapWarning)
        attachment = calibrate_attachment(truth, layout).attachment
        checks = [check_labels(rotated(frames), unlabelled, attachment, rigid=layout.rigid)
                  for frames in (bursts, slice(0, 330), slice(None))]
    burst, stretch, everywhere = checks
    assert len(burst.warnings) == 1 and "removed" in burst.warnings[0]
    assert score_labels(burst.markers, truth).erroneous.sum() < 0.1 * score_labels(rotated(bursts),
                                                                                  truth).erroneous.sum()
    assert any("not checked" in w for w in stretch.warnings) and stretch.judged[:300].sum() < 30
    assert everywhere.removed.sum() == 0 and "explains" in everywhere.warnings[0]
    for check in checks:
        assert set(check.warnings) <= set(check.markers.warnings)


def test_wrong_labels_no_longer_throw_the_hand_off(turned, labelled, monkeypatch):
    # The labeler put the rigid back triad on finger points in some frames. Solved frame by frame, the hand followed
    # the triad, tens of millimetres from where it was; with the excursions mended (handcap.solve.continuity) it
    # stays with its fingers. The check then removes those triad labels where they lie further than a carried
    # frame allows (test above: 99.74 % correct; 99.50 % while it kept them).
    import handcap.solve.motion as motion_module
    from handcap.solve import solve_hand

    truth = turned[3]
    labelled, attachment = labelled
    with warnings.catch_warnings():  # excursions only (no label swap is looked for)
        warnings.simplefilter("ignore", HandcapWarning)
        after = solve_hand(labelled, attachment, mend_swaps=False)
        monkeypatch.setattr(motion_module, "mend_excursions", lambda *a: 0)
        before = solve_hand(labelled, attachment, mend_swaps=False)
    true = truth.select(list(attachment.marker_names)).positions
    off_before = 1000 * np.nanmean(np.linalg.norm(before.marker_fit - true, axis=-1))
    off_after = 1000 * np.nanmean(np.linalg.norm(after.marker_fit - true, axis=-1))
    print(f"mean marker error, excursions left / mended: {off_before:.2f} / {off_after:.2f} mm")
    assert off_after < 0.8 * off_before, (off_before, off_after)  # measured 1.55 -> 0.94 mm (swaps not mended)
