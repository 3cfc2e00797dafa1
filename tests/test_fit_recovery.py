"""Fits recover the truth of synthetic data within their reported uncertainty.

Data: the paper's chain (eta = 2 us, mu = 0.19, mu* = 0.02) at three impact velocities,
recorded by a sensor embedded in bead 6 (split-bead model of Eq. 4), contact 11 and the
wall, 1 us sampling, white noise of 0.5 % of each file's largest force. The data are
simulated with twice finer time steps than the fit uses. Fits start far from the truth:
eta and mu a factor 3 off.
"""

import numpy as np
import pytest

import fitting
from fitting.parameters import bare_speed_constant
from fitting.synthetic import paper_setups, synthetic_traces

VELOCITIES = (0.08, 0.2, 0.4)
TRUTH = {"eta": 2e-6, "mu": 0.19, "mu_star": 0.02}
FAR_START = {"eta_s": 6e-6, "mu": 0.19 / 3}


def _data(velocities=VELOCITIES, t_end_s=1.5e-3):
    setups = paper_setups(velocities, eta_s=TRUTH["eta"], mu=TRUTH["mu"], mu_star=TRUTH["mu_star"],
                          sensor_beads=(6,))
    clean = synthetic_traces(setups, contacts=(11,), t_end_s=t_end_s)
    sigma = [0.005 * max(np.max(v) for v in f.channels.values()) for f in clean]
    noisy = synthetic_traces(setups, contacts=(11,), t_end_s=t_end_s, noise_std_n=sigma, seed=100)
    truth = np.array([TRUTH["eta"], TRUTH["mu"],
                      float(bare_speed_constant(setups[0])) * (1 + TRUTH["mu_star"]) ** (1 / 3)])
    return clean, noisy, truth


@pytest.fixture(scope="module")
def recovery():
    clean, noisy, truth = _data()
    problem = fitting.make_problem(noisy, ("eta_s", "mu", "C"))
    clean_vector = np.concatenate([f.channels[c] for f in clean for c in f.channels])
    sigma = problem.sigma_vector()
    rng = np.random.default_rng(7)
    datasets = clean_vector + sigma * rng.standard_normal((3, clean_vector.size))
    result = fitting.fit_datasets(problem, datasets, start=FAR_START)
    return result, truth


@pytest.mark.slow
def test_fits_converge_from_a_far_start(recovery):
    result, _ = recovery
    assert result["labels"] == ("eta", "mu", "C")
    assert np.all(result["converged"])
    # chi^2 per degree of freedom of a correct model with the true noise
    dof = 3 * 3 * 1500 - 3
    np.testing.assert_allclose(result["chi2"] / dof, 1.0, atol=0.06)


@pytest.mark.slow
def test_estimates_are_within_their_reported_errors(recovery):
    result, truth = recovery
    z = (result["values"] - truth) / result["stderr"]
    # fixed seeds: every estimate within 3 sigma, and the z-scores of size ~1 on average
    assert np.all(np.abs(z) < 3), z
    assert np.mean(z**2) < 2.5, z
    # the reported errors are small: the data do determine all three
    relative = result["stderr"] / truth
    assert np.all(relative < [0.01, 0.02, 1e-4]), relative


@pytest.mark.slow
def test_two_sigma_coverage_over_many_seeds():
    """The 2-sigma interval covers the truth about 95 % of the time (120 seeds, one batch)."""
    clean, noisy, truth = _data()
    problem = fitting.make_problem(noisy, ("eta_s", "mu", "C"))
    clean_vector = np.concatenate([f.channels[c] for f in clean for c in f.channels])
    rng = np.random.default_rng(2024)
    datasets = clean_vector + problem.sigma_vector() * rng.standard_normal((120, clean_vector.size))
    result = fitting.fit_datasets(problem, datasets)
    assert np.all(result["converged"])
    z = (result["values"] - truth) / result["stderr"]
    coverage = np.mean(np.abs(z) < 2, axis=0)
    # binomial scatter of a 95 % rate over 120 seeds: sd 2 %
    assert np.all(coverage > 0.89) and np.all(coverage <= 1.0), coverage
    # unbiased: mean z within 3 standard errors of 0, spread about 1
    assert np.all(np.abs(np.mean(z, axis=0)) < 3 / np.sqrt(120)), np.mean(z, axis=0)
    assert np.all(np.abs(np.std(z, axis=0) - 1) < 0.2), np.std(z, axis=0)
