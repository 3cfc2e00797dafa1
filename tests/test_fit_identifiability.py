"""Identifiability warnings, and failures that must be loud rather than silent."""

import numpy as np
import pytest

import fitting
from fitting.synthetic import paper_setups, synthetic_traces
from fitting.uncertainty import covariance_from_jacobian, identifiability_warnings


@pytest.fixture(scope="module")
def one_file():
    """Dissipationless chain at 0.3 m/s, contact 5 and the wall, 1.3 ms, small noise."""
    setups = paper_setups([0.3], eta_s=0.0, mu=0.0)
    return synthetic_traces(setups, contacts=(5,), t_end_s=1.3e-3, noise_std_n=0.05, seed=5)


def _warnings_for(files, params):
    problem = fitting.make_problem(files, params)
    x = fitting.initial_values(problem)
    r, jac = fitting.residuals_and_jacobian(problem, x)
    cov = covariance_from_jacobian(jac, problem.labels, chi2=float(r @ r),
                                   dof=problem.n_residuals - len(x), scale="noise")
    return cov, identifiability_warnings(problem.instances, x, cov, problem.experiments)


def test_stiffness_velocity_gain_degeneracy_is_named(one_file):
    # F(t; lambda kappa, V0) = lambda^-2 F(t; kappa, lambda^2 V0) exactly without dissipation
    cov, messages = _warnings_for(one_file, ("C", "striker_velocity_m_s", "gain"))
    text = "\n".join(messages)
    assert "C is not identifiable with striker_velocity[trace0]" in text
    # the Jacobian itself shows it: a singular value at round-off level, naming C
    assert cov.singular_values[-1] / cov.singular_values[0] < 1e-6
    assert any("C" in components for _, components in cov.weak_directions)
    assert not np.isfinite(cov.stderr[0])


def test_holding_one_gain_restores_identifiability(one_file):
    problem = fitting.make_problem(one_file, ("C", "striker_velocity_m_s", "gain"))
    # drop the wall's gain: the stiffness scale is then determined
    instances = [inst for inst in problem.instances if inst.label != "gain[trace0:wall]"]
    reduced = fitting.Problem(problem.experiments, instances, problem.base_setups, problem.forward)
    x = fitting.initial_values(reduced)
    r, jac = fitting.residuals_and_jacobian(reduced, x)
    cov = covariance_from_jacobian(jac, reduced.labels, chi2=float(r @ r),
                                   dof=reduced.n_residuals - len(x), scale="noise")
    assert cov.singular_values[-1] / cov.singular_values[0] > 1e-5
    assert np.all(np.isfinite(cov.stderr))
    messages = identifiability_warnings(reduced.instances, x, cov, reduced.experiments)
    assert not any("not identifiable" in m for m in messages)


def test_friction_from_a_high_amplitude_trace_alone_is_flagged(one_file):
    # no friction in the data and one fast impact: mu is not determined
    setups = paper_setups([0.4], eta_s=2e-6, mu=0.0)
    files = synthetic_traces(setups, contacts=(5,), t_end_s=0.5e-3, noise_std_n=2.0, seed=2)
    experiments = [fitting.make_experiment(files[0], channels=("contact_5",))]
    cov, messages = _warnings_for(experiments, ("eta_s", "mu"))
    assert cov.stderr[1] > 0.5 * 0.05  # far larger than the start value of mu
    assert any("mu is practically not identifiable" in m for m in messages)


def test_unknown_parameter_and_bad_start_are_refused(one_file):
    with pytest.raises(ValueError, match="Fittable parameters: eta_s, mu, C"):
        fitting.fit(one_file, ("eta_s", "viscosity"))
    with pytest.raises(ValueError, match="outside its bounds"):
        fitting.fit(one_file, ("mu",), start={"mu": -0.1}, progress=False)
    with pytest.raises(ValueError, match="not a fitted parameter"):
        fitting.fit(one_file, ("eta_s",), start={"mu": 0.1}, progress=False)


def test_a_fit_that_cannot_converge_says_so(one_file):
    with pytest.raises(fitting.FitError, match="no start reached an optimum within 1 steps"):
        fitting.fit(one_file, ("eta_s",), start={"eta_s": 5e-5}, max_steps=1, progress=False)
