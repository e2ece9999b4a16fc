"""The spatial model (handcap.labeling.spatial) against scikit-learn's Gaussian mixtures."""


import numpy as np

from handcap.labeling import SpatialModel


def test_spatial_model_matches_scikit_learn():
    from sklearn.mixture import GaussianMixture
    rng = np.random.default_rng(2)
    local = np.stack([rng.normal([0.05, 0.0, 0.0], 0.01, (300, 3)),
                      np.concatenate([rng.normal([0.0, 0.08, 0.0], 0.004, (150, 3)),
                                      rng.normal([0.0, 0.1, 0.03], 0.006, (150, 3))])], axis=1)
    local[::7, 1] = np.nan
    model = SpatialModel.fit(["a", "b"], local, components=3, seed=0)
    query = rng.normal(0.03, 0.05, (9, 3))
    for i in range(2):
        x = local[:, i][~np.isnan(local[:, i, 0])]
        ref = GaussianMixture(3, covariance_type="full", reg_covar=1e-6, random_state=0).fit(x)
        np.testing.assert_allclose(model.log_likelihood(query)[i], ref.score_samples(query), rtol=1e-9)
    again = SpatialModel.from_arrays(model.to_arrays())
    np.testing.assert_array_equal(again.log_likelihood(query), model.log_likelihood(query))
