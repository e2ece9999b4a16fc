"""Labeling a whole take (handcap.labeling.take): offline and with a lag, on the real glove recording."""


from handcap.labeling import corrupt, label_take, score_labels


def test_offline_and_lag_decide_at_least_as_well(glove):
    take, model, _ = glove
    unlabeled, truth = corrupt(take[3500:4300], ghost_rate=2.0, dropout=0.05, seed=1)
    online = score_labels(label_take(unlabeled, model).markers, truth)
    lagged = score_labels(label_take(unlabeled, model, lag=5).markers, truth)
    offline = score_labels(label_take(unlabeled, model, offline=True).markers, truth)
    assert lagged.fraction("correct") >= online.fraction("correct") - 0.001
    assert offline.fraction("correct") >= online.fraction("correct") - 0.001
