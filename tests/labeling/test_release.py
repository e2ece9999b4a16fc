"""A swap the tracks carry is handed back to the spatial model (``OnlineLabeler(release=...)``).

Two labels' tracks exchanged in every hypothesis, as a swap begun at a restart would leave them: both points are
plausible for either label, so the tracks' continuity alone would keep the swap for good. The evidence the
spatial model adds up against it releases the two labels, and they are right again from there.
"""

import numpy as np
import pytest

from handcap import HandcapError
from handcap.labeling import OnlineLabeler, label_take
from handcap.labeling.release import Release, release_warning
from handcap.synth.scene import SynthConfig, synthesize

SWAP_AT = 60


@pytest.fixture(scope="module")
def model_and_take(joints_model):
    take = synthesize(SynthConfig(layout="joints-19", motion="random", frames=400, rate=120.0, seed=4,
                                  subject_seed=3), progress=False)
    return joints_model, take.labeled_points(joints_model.names)


def _swapped_frames(model, take, a, b, **options):
    """Label ``take`` (its points in label order) with the tracks of ``a`` and ``b`` exchanged at ``SWAP_AT``;
    per frame, whether each of the two points carries the other's label; and the labeler."""
    labeler = OnlineLabeler(model, adapt=False, **options)
    ia, ib = labeler.names.index(a), labeler.names.index(b)
    free = list(model.free_names)
    pair = [free.index(a), free.index(b)]
    out = []
    for t, frame in enumerate(take.positions):
        if t == SWAP_AT:  # every hypothesis' filters of the two labels exchanged
            filters = labeler._filters
            for values in (filters.state, filters.cov, filters.age, filters.missed):
                per_label = values.reshape((-1, len(free)) + values.shape[1:])
                per_label[:, pair] = per_label[:, pair[::-1]]
        labels = labeler.update(frame)
        out.append((labels[ia] == ib, labels[ib] == ia))
    return np.array(out), labeler


def test_a_swap_kept_by_the_tracks_alone_is_released_to_the_spatial_model(model_and_take):
    model, take = model_and_take
    kept, _ = _swapped_frames(model, take, "middle_dip", "ring_tip", release=np.inf)
    mended, labeler = _swapped_frames(model, take, "middle_dip", "ring_tip")
    assert not kept[:SWAP_AT].any() and not mended[:SWAP_AT].any()
    # Without the release the swap lasts to the end of the take (measured: 302 of the 340 frames after it) ...
    assert kept[SWAP_AT:].all(axis=1).sum() > 0.8 * (len(take.positions) - SWAP_AT)
    assert kept[-50:].any(axis=1).mean() > 0.8
    # ... with it, both labels are released (measured: 239 frames, 2.0 s, after the swap) and right from there on.
    released = [r for r in labeler.released if {"middle_dip", "ring_tip"} & set(r.labels)]
    assert len(released) == 1 and set(released[0].labels) == {"middle_dip", "ring_tip"}
    assert SWAP_AT <= released[0].since < released[0].frame < len(take.positions) - 50
    assert not mended[released[0].frame + 5:].any()
    assert mended.all(axis=1).sum() < 0.8 * kept.all(axis=1).sum()  # measured: 216 frames swapped against 302


def test_release_settings_are_checked(model_and_take):
    model, _ = model_and_take
    for options in ({"release": 0.0}, {"release": -1.0}, {"release_drift": -0.5}):
        with pytest.raises(HandcapError, match="release"):
            OnlineLabeler(model, **options)


def test_releases_are_a_warning_stored_with_the_labels(model_and_take):
    """A release says the labels were probably swapped before it: label_take stores and prints the line."""
    model, take = model_and_take
    with pytest.warns(UserWarning, match="released to the spatial model"):
        result = label_take(take, model, release=30.0)  # a low threshold releases labels on an ordinary take
    assert result.released
    line = [w for w in result.warnings if "released to the spatial model" in w]
    assert len(line) == 1 and line[0] in result.markers.warnings
    first = result.released[0]
    assert f"{' and '.join(first.labels)} at frame {first.frame} (since frame {first.since}:" in line[0]
    assert not any("released" in w for w in label_take(take, model).warnings)  # the default: none here


def test_several_hands_release_with_their_prefixes(model_and_take):
    from handcap.labeling import MultiHandLabeler

    model, take = model_and_take
    one = OnlineLabeler(model, release=30.0)
    both = MultiHandLabeler([model], prefixes=("R_",), release=30.0)
    for frame in take.positions:  # (the low threshold releases labels of this take at frames 371 and 379)
        one.update(frame)
        both.update(frame)
    assert one.released and [(r.frame, r.since) for r in both.released] == [(r.frame, r.since) for r in one.released]
    assert [r.labels for r in both.released] == [tuple("R_" + n for n in r.labels) for r in one.released]


def test_release_warning_names_five_and_counts_the_rest():
    releases = [Release(100 * k + 50, 100 * k, ("index_tip", "middle_tip")) for k in range(7)]
    line = release_warning(releases, 100.0)
    assert line.startswith("labels released to the spatial model 7 time(s)")
    assert "index_tip and middle_tip at frame 50 (since frame 0: 0.00-0.50 s)" in line and "; and 2 more" in line
    assert release_warning([], 100.0) is None


def test_released_labels_take_over_the_tracks_that_hold_their_points():
    # Two frames of a swap: the best hypothesis gives labels a and b each other's points, the spatial model's the
    # points the other way round. At the release each takes over the filter that followed its point, in every
    # hypothesis where a released label's track holds it; a label whose point no released track holds starts afresh.
    from handcap.labeling.release import TrackEvidence

    world = np.arange(30.0).reshape(10, 3)
    evidence = TrackEvidence(["a", "b", "c", "d"], release=1000.0, drift=0.0)
    hyps = np.array([[5, 7, 9, 2], [7, 5, 9, 3]])  # best: a and b swapped; top: right, and d on another point
    assert evidence.weigh(hyps, np.array([0.0, 600.0]), 0, 10, world) is None
    found = evidence.weigh(hyps, np.array([0.0, 600.0]), 0, 11, world)
    assert found.labels == ("a", "b", "d") and found.since == 10
    released = evidence.take_pending()
    obs = np.where((hyps >= 0)[..., None], world[hyps], np.nan)
    index, fresh = evidence.hand_over(obs, released)
    # Hypothesis 0 (swapped): a takes b's filter and b a's; c keeps its own; d's point (3) is held by no track there.
    # Hypothesis 1 (right): every label keeps its own filter.
    np.testing.assert_array_equal(index, [1, 0, 2, 3, 4, 5, 6, 7])
    np.testing.assert_array_equal(fresh, [[False, False, False, True], [False, False, False, False]])
