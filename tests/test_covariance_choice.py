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
