"""Which covariance a fit reports (`fitting.uncertainty.covariance_choice`): the stated noise
while chi^2/dof agrees with it, the residuals' scale where it does not -- checked on a linear
model fitted by closed-form least squares over many noise seeds (no fitting code involved)."""

import math

import numpy as np
import pytest

from fitting.uncertainty import MODEL_ERROR_ALLOWANCE, covariance_choice, covariance_from_jacobian, noise_band


def _linear_fits(stated_over_true: float, seeds: int = 400, n: int = 2000):
    """Fits of y = a + b t with noise sigma_true, whitened by a stated sigma; returns the
    estimates (seeds, 2), their chi^2 (seeds,), the whitened Jacobian."""
    rng = np.random.default_rng(1)
    t = np.linspace(0.0, 1.0, n)
    design = np.column_stack([np.ones(n), t])
    sigma_true = 0.3
    sigma_stated = stated_over_true * sigma_true
    y = design @ [1.0, 2.0] + sigma_true * rng.standard_normal((seeds, n))
    jac = design / sigma_stated
    estimates = np.linalg.lstsq(design, y.T, rcond=None)[0].T
    chi2 = np.sum(((y - estimates @ design.T) / sigma_stated) ** 2, axis=1)
    return estimates, chi2, jac


def test_band_is_the_allowance_plus_three_widths_of_the_chi2_distribution():
    low, high = noise_band(5000)
    width = 3 * math.sqrt(2 / 5000)
    assert high == pytest.approx(1 + MODEL_ERROR_ALLOWANCE + width)
    assert low == pytest.approx(1 / (1 + MODEL_ERROR_ALLOWANCE) - width)


@pytest.mark.parametrize("stated_over_true", [1.0, 1.5, 0.5])
def test_standard_errors_match_the_scatter_whatever_the_stated_noise(stated_over_true):
    estimates, chi2, jac = _linear_fits(stated_over_true)
    dof = jac.shape[0] - 2
    scale, reason = covariance_choice("auto", float(chi2[0]), dof)
    expected = "noise" if stated_over_true == 1.0 else "residual"
    assert scale == expected, reason
    if expected == "residual":
        assert "outside" in reason
    stderr = covariance_from_jacobian(jac, ["a", "b"], chi2=float(chi2[0]), dof=dof, scale=scale).stderr
    spread = np.std(estimates, axis=0, ddof=1)
    # 400 seeds: the sample sd is good to about 3.5 % (1 sigma)
    np.testing.assert_allclose(stderr / spread, 1.0, atol=0.12)


def test_asked_for_noise_keeps_it_but_says_the_residuals_disagree():
    _, chi2, jac = _linear_fits(1.5, seeds=1)
    scale, reason = covariance_choice("noise", float(chi2[0]), jac.shape[0] - 2)
    assert scale == "noise" and "outside" in reason and "as asked" in reason


def test_correlated_residuals_standard_errors_match_the_scatter_where_white_noise_ones_do_not():
    # y = a + b t with AR(1) noise (rho = 0.6): the white-noise standard errors are too small
    # by about sqrt((1 + rho)/(1 - rho)) = 2; the Newey-West sandwich over the series, with a
    # lag long against the noise's correlation time (1/(1 - rho) = 2.5 samples), matches the
    # scatter of the estimates over seeds.
    from fitting.uncertainty import correlated_score_covariance

    rng = np.random.default_rng(5)
    seeds, n, rho, sigma = 300, 2000, 0.6, 0.3
    t = np.linspace(0.0, 1.0, n)
    design = np.column_stack([np.ones(n), t])
    innovations = rng.standard_normal((seeds, n)) * sigma * math.sqrt(1 - rho**2)
    noise = np.empty((seeds, n))
    noise[:, 0] = rng.standard_normal(seeds) * sigma
    for k in range(1, n):
        noise[:, k] = rho * noise[:, k - 1] + innovations[:, k]
    y = design @ [1.0, 2.0] + noise
    estimates = np.linalg.lstsq(design, y.T, rcond=None)[0].T
    spread = estimates.std(axis=0, ddof=1)
    jac = design / sigma
    white = np.sqrt(np.diag(np.linalg.inv(jac.T @ jac)))
    assert np.all(white / spread < 0.6)
    ratios = []
    for k in range(20):
        residuals = (y[k] - design @ estimates[k]) / sigma
        meat = correlated_score_covariance(jac, residuals, [(np.arange(n), 25)])
        cov = covariance_from_jacobian(jac, ["a", "b"], chi2=float(residuals @ residuals), dof=n - 2,
                                       scale="correlated", score_covariance=meat)
        assert cov.scale == "correlated"
        ratios.append(cov.stderr / spread)
    np.testing.assert_allclose(np.mean(ratios, axis=0), 1.0, atol=0.15)


def test_white_residuals_give_the_correlated_covariance_of_the_noise():
    from fitting.uncertainty import correlated_score_covariance

    estimates, chi2, jac = _linear_fits(1.0, seeds=1)
    rng = np.random.default_rng(8)
    residuals = rng.standard_normal(jac.shape[0])
    meat = correlated_score_covariance(jac, residuals, [(np.arange(jac.shape[0]), 25)])
    noise = covariance_from_jacobian(jac, ["a", "b"], chi2=float(chi2[0]), dof=jac.shape[0] - 2, scale="noise")
    correlated = covariance_from_jacobian(jac, ["a", "b"], chi2=float(chi2[0]), dof=jac.shape[0] - 2,
                                          scale="correlated", score_covariance=meat)
    # the Bartlett estimate's own sampling error: about sqrt(2 x 25 / 2000) = 16 % in variance
    np.testing.assert_allclose(correlated.stderr / noise.stderr, 1.0, atol=0.12)


def test_auto_chooses_the_correlated_covariance_for_sub_dither_channels_and_says_why():
    scale, reason = covariance_choice("auto", 1000.0, 1000, "shot1:wall (0.25 step) recorded below half a step")
    assert scale == "correlated" and "shot1:wall (0.25 step)" in reason
    assert covariance_choice("auto", 1000.0, 1000)[0] == "noise"
    with pytest.raises(ValueError, match="covariance must be one of auto, noise, residual, correlated"):
        covariance_choice("sandwich", 1000.0, 1000)
