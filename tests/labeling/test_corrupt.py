"""Making a labeling test from a labeled take (handcap.labeling.corrupt)."""

import numpy as np

from handcap.labeling import corrupt


def test_corrupt_keeps_every_point_and_adds_ghosts(glove):
    take, _, _ = glove
    part = take[:1000]
    unlabeled, truth = corrupt(part, ghost_rate=5.0, dropout=0.1, seed=3)
    assert truth.names == part.names
    kept = ~np.isnan(truth.positions[..., 0])
    dropped = ~np.isnan(part.positions[..., 0]) & ~kept
    assert 0.08 < dropped.sum() / (~np.isnan(part.positions[..., 0])).sum() < 0.12
    counts = (~np.isnan(unlabeled.positions[..., 0])).sum(axis=1)
    ghosts = counts - kept.sum(axis=1)
    assert (ghosts >= 0).all() and 5.0 * 0.5 < ghosts.sum() / (1000 / take.rate) / 5.5 < 5.0 * 2
    for t in (0, 500, 999):  # every true point is among the unlabeled ones
        pts = unlabeled.positions[t][~np.isnan(unlabeled.positions[t, :, 0])]
        for p in truth.positions[t][kept[t]]:
            assert np.isclose(np.linalg.norm(pts - p, axis=1).min(), 0.0)
    again, _ = corrupt(part, ghost_rate=5.0, dropout=0.1, seed=3)
    np.testing.assert_array_equal(again.positions, unlabeled.positions)
