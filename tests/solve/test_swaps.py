"""Two labels swapped for a stretch of frames are found by the hand solved from them, solved exchanged and named in a
warning; labels that are right are left alone, on synthetic takes and on the real glove."""

import warnings

import numpy as np
import pytest

from handcap.cli import main
from handcap.core.errors import HandcapWarning
from handcap.core.markers import MarkerSequence
from handcap.io import write_markers
from handcap.solve import solve_hand
from handcap.solve.swaps import find_swaps
from handcap.synth.scene import SynthConfig, synthesize


def _solve(markers, attachment, **options):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", HandcapWarning)
        return solve_hand(markers, attachment, **options)


@pytest.fixture(scope="module")
def clean_take():
    """A glove-13 grasp without synth's own label swaps: (markers, capture)."""
    capture = synthesize(SynthConfig(layout="glove-13", motion="grasp", frames=200, rate=50.0, seed=11,
                                     subject_seed=3, swap_rate=0.0), progress=False)
    return capture.markers.select(list(capture.attachment.marker_names)), capture


def _swapped(markers, a, b, frames):
    positions = markers.positions.copy()
    i, j = markers.names.index(a), markers.names.index(b)
    positions[frames, [i, j]] = positions[frames, [j, i]]
    return MarkerSequence(positions, markers.names, markers.rate)


def test_a_swap_is_found_solved_exchanged_and_named(clean_take):
    markers, capture = clean_take
    swapped = _swapped(markers, "middle_tip", "ring_tip", slice(80, 111))
    before = swapped.positions.copy()
    kept = _solve(swapped, capture.attachment, mend_swaps=False)
    mended = _solve(swapped, capture.attachment)
    assert np.array_equal(swapped.positions, before, equal_nan=True)  # the input is not touched
    truth = capture.hand_motion.joints[80:111]
    tips = [18, 19]  # the middle and ring fingertips (16 MANO joints, then the tips of thumb, index, middle, ...)
    right = _solve(markers, capture.attachment)  # the same take with its labels right

    def error(motion):  # the two fingertips' largest distance from the truth in the swapped frames, metres
        return np.linalg.norm(motion.joints[80:111, tips] - truth[:, tips], axis=-1).max()

    assert error(kept) > error(right) + 0.02  # 34 mm against 8 mm
    assert error(mended) < error(right) + 0.001
    said = [w for w in mended.warnings if "label swap" in w]
    assert len(said) == 1 and "middle_tip and ring_tip in frames 80-110" in said[0]
    assert not any("label swap" in w for w in kept.warnings)
    # The residuals the motion keeps are those of the labels as solved: small where they were swapped.
    assert np.nanmax(mended.marker_residuals[80:111]) < 0.005 < np.nanmax(kept.marker_residuals[80:111])


def test_right_labels_are_left_alone(clean_take):
    markers, capture = clean_take
    motion = _solve(markers, capture.attachment)
    again = _solve(markers, capture.attachment, mend_swaps=False)
    assert not any("label swap" in w for w in motion.warnings)
    assert np.array_equal(motion.joints, again.joints)


def test_synths_own_swaps_are_found_where_it_made_them():
    # glove-13 grasp at 30 Hz: synth swapped the ring and little fingertips' labels in frames 49-67; solved as
    # labelled the ring fingertip ends 40 mm from the truth there (the take's p99 joint error 17.2 mm -> 6.6 mm).
    capture = synthesize(SynthConfig(layout="glove-13", motion="grasp", frames=300, rate=30.0, seed=15,
                                     subject_seed=3), progress=False)
    markers = capture.markers.select(list(capture.attachment.marker_names))
    (first, end, i, j), = capture.truth["swaps"]
    names = capture.truth["names"]
    motion = _solve(markers, capture.attachment)
    said = [w for w in motion.warnings if "label swap" in w]
    pair = [str(names[k]) for k in sorted((i, j))]
    assert len(said) == 1 and f"{pair[0]} and {pair[1]} in frames {first}-{end - 1}" in said[0], said
    error = np.linalg.norm(motion.joints - capture.hand_motion.joints, axis=-1)
    assert error[first:end].max() < 0.01


def test_markers_that_stray_without_a_swap_are_not_exchanged():
    # Two markers off the fitted hand in the same frames that the hand fits no better exchanged: no swap. Nor two
    # that lie near each other's places when the hand, solved exchanged, still misses them by more than the limit.
    rng = np.random.default_rng(0)
    fit = rng.normal(0.0, 0.05, (20, 10, 3))
    target = fit.copy()
    target[5:10, 1] += [0.012, 0.0, 0.0]
    target[5:10, 2] += [0.0, 0.012, 0.0]
    observed = np.ones((20, 10), dtype=bool)

    def solve(t, o):  # the hand as before, wherever the labels are
        return fit[:len(t)]

    assert find_swaps(target, observed, fit, solve)[0] == []
    target[5:10, [1, 2]] = fit[5:10, [2, 1]] + 0.006  # close to each other's places, but the hand fits neither
    assert find_swaps(target, observed, fit, lambda t, o: np.where(o[..., None], t + 0.006, t))[0] == []


def test_the_real_glove_has_no_swap(real_glove):
    # Its markers stray up to 16 mm from the fitted hand (the glove slides), two at once in 432 frames, but no
    # pair lies within 4.6 times its residual of the other's place.
    take, attachment = real_glove
    motion = _solve(take.frames(3000, 4500), attachment)
    assert np.nanmax(motion.marker_residuals) > 0.010
    assert not any("label swap" in w for w in motion.warnings)


def test_the_command_solves_swaps_exchanged_unless_told_and_says_so(clean_take, tmp_path, capsys):
    markers, capture = clean_take
    swapped = _swapped(markers, "index_tip", "middle_tip", slice(120, 141))
    write_markers(swapped, tmp_path / "take.c3d")
    capture.attachment.save(tmp_path / "attachment.npz")
    stamp = (tmp_path / "take.c3d").read_bytes()
    assert main(["solve", str(tmp_path / "take.c3d"), "--attachment", str(tmp_path / "attachment.npz"),
                 "--out", str(tmp_path / "mended.npz")]) == 0
    err = capsys.readouterr().err
    assert "index_tip and middle_tip in frames 120-140" in err and "--keep-swaps" in err
    with np.load(tmp_path / "mended.npz") as data:
        assert any("label swap" in str(w) for w in data["warnings"])
    assert main(["solve", str(tmp_path / "take.c3d"), "--attachment", str(tmp_path / "attachment.npz"),
                 "--out", str(tmp_path / "kept.npz"), "--keep-swaps"]) == 0
    assert "label swap" not in capsys.readouterr().err
    assert (tmp_path / "take.c3d").read_bytes() == stamp


def test_three_labels_round_a_cycle_are_found_and_solved_exchanged(clean_take):
    # index_tip carries middle_tip's label, middle_tip ring_tip's and ring_tip index_tip's in frames 80-110: no
    # exchange of two of them fits, the cycle does.
    markers, capture = clean_take
    names = list(markers.names)
    i, m, r = (names.index(n) for n in ("index_tip", "middle_tip", "ring_tip"))
    positions = markers.positions.copy()
    frames = slice(80, 111)
    positions[frames, [m, r, i]] = markers.positions[frames][:, [i, m, r]]  # column m holds index_tip's marker ...
    cycled = MarkerSequence(positions, markers.names, markers.rate)
    kept = _solve(cycled, capture.attachment, mend_swaps=False)
    mended = _solve(cycled, capture.attachment)
    right = _solve(markers, capture.attachment)
    tips = [17, 18, 19]  # the index, middle and ring fingertips
    truth = capture.hand_motion.joints[frames, tips]

    def error(motion):
        return np.linalg.norm(motion.joints[frames, tips] - truth, axis=-1).max()

    said = [w for w in mended.warnings if "label swap" in w]
    assert len(said) == 1 and "round a cycle (index_tip read from middle_tip's label, middle_tip from ring_tip's, " \
        "ring_tip from index_tip's) in frames 80-110" in said[0], said
    assert error(kept) > error(right) + 0.02 and error(mended) < error(right) + 0.001
