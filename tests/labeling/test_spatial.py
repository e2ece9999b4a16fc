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


def test_typical_fit_of_one_gaussian_is_its_density_at_the_median_distance():
    # Independent computation: for one label with one Gaussian component, a point's log-likelihood is
    # log N(0) - d^2 / 2 with d^2 chi-squared with 3 degrees of freedom, so the median is at chi2's median.
    from scipy.stats import chi2

    rng = np.random.default_rng(3)
    a = rng.normal(size=(3, 3))
    cov = (a @ a.T + 3 * np.eye(3)) * 1e-5  # a few millimetres, not axis-aligned
    chol = np.linalg.cholesky(np.linalg.inv(cov))  # precision = P P^T
    log_norm = -1.5 * np.log(2 * np.pi) + np.log(np.diag(chol)).sum()
    model = SpatialModel(("m",), np.ones((1, 1)), np.array([[[0.01, -0.02, 0.03]]]), chol[None, None],
                         np.array([[log_norm]]))
    want = log_norm - 0.5 * chi2.ppf(0.5, 3)
    assert abs(model.typical_fit(samples=20000) - want) < 0.05
    # A rigid move of the model's frame changes nothing; the value is reproducible for a seed.
    turn = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    assert abs(model.moved(turn, np.array([0.1, 0.0, 0.0])).typical_fit(samples=20000) - want) < 0.05
    assert model.typical_fit() == model.typical_fit()


def test_widened_mixture_is_the_mixture_of_wider_gaussians():
    # Independent computation: each component's density with covariance Sigma + s^2 I (scipy), weighted and summed.
    from scipy.stats import multivariate_normal
    rng = np.random.default_rng(3)
    local = np.stack([rng.normal([0.05, 0.0, 0.0], [0.01, 0.002, 0.004], (300, 3)),
                      rng.normal([0.0, 0.08, 0.0], 0.001, (300, 3))], axis=1)
    model = SpatialModel.fit(["a", "b"], local, components=2, seed=0)
    wide = model.widened(0.005)
    query = rng.normal(0.03, 0.03, (7, 3))
    precision = model.precision_chol @ np.swapaxes(model.precision_chol, -1, -2)
    for i in range(2):
        density = sum(model.weights[i, k] * multivariate_normal(model.means[i, k], np.linalg.inv(precision[i, k])
                                                                + 0.005 ** 2 * np.eye(3)).pdf(query)
                      for k in range(2))
        np.testing.assert_allclose(wide.log_likelihood(query)[i], np.log(density), rtol=1e-9)
    np.testing.assert_array_equal(wide.means, model.means)
    # A point 15 mm from a 1 mm wide label: hopeless before, plausible after.
    far = model.means[1, 0] + [0.015, 0.0, 0.0]
    assert model.log_likelihood(far[None])[1, 0] < -30 < 0 < wide.log_likelihood(far[None])[1, 0]  # theta_min: -2
    # Only some labels widened (the online search of a label hardly given): the others as they were.
    some = model.widened(0.005, np.array([False, True]))
    np.testing.assert_allclose(some.log_likelihood(query)[0], model.log_likelihood(query)[0], rtol=1e-12)
    np.testing.assert_allclose(some.log_likelihood(query)[1], wide.log_likelihood(query)[1], rtol=1e-12)
