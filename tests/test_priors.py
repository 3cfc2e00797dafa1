"""Priors as a lab writes them: parsing, binding to a problem, and their residual rows."""

import numpy as np
import pytest

from fitting.fit import make_problem
from fitting.priors import PriorError, parse_prior, parse_priors
from fitting.synthetic import paper_setups, synthetic_traces


@pytest.fixture(scope="module")
def traces():
    return synthetic_traces(paper_setups([0.15, 0.3]), contacts=(6,), t_end_s=1.5e-3)


def test_parse_forms():
    p = parse_prior("bead_youngs_pa=203GPa+-4GPa")
    assert (p.kind, p.centre, p.sd) == ("normal", 203e9, 4e9)
    p = parse_prior("sensor_gain=+-2%")
    assert (p.centre, p.relative_sd) == (None, pytest.approx(0.02))
    p = parse_prior("bead_radius_m = 13mm +- 62.5um")
    assert (p.centre, p.sd) == (pytest.approx(0.013), pytest.approx(62.5e-6))
    p = parse_prior("eta_s=0..10us")
    assert (p.kind, p.low, p.high) == ("uniform", 0.0, pytest.approx(1e-5))
    assert parse_prior("striker_velocity_m_s[run1]=0.3+-0.003").name == "striker_velocity"


@pytest.mark.parametrize("text, match", [
    ("bead_youngs_pa", "expected name=VALUE"),
    ("bead_youngs_pa=203GPa", "no width"),
    ("bead_youngs_pa=203GPa+-4mm", "unit"),
    ("sensor_gain=1+--2%", "positive"),
    ("eta_s=5us..1us", "LOW < HIGH"),
    ("youngs=1+-0.1", "Unknown parameter 'youngs'"),
])
def test_bad_priors_name_the_field(text, match):
    with pytest.raises(ValueError, match=match):
        parse_prior(text)


def test_twice_the_same_key_is_refused():
    with pytest.raises(PriorError, match="two priors for gain"):
        parse_priors(["gain=+-2%", "gain=1+-0.01"])


def test_priors_free_their_parameters_and_add_rows(traces):
    problem = make_problem(traces, ("eta_s",), priors=["striker_velocity_m_s=+-1%",
                                                     "striker_velocity_m_s[trace1]=0.31+-0.002",
                                                     "sensor_gain=1+-0.02"])
    assert problem.labels == ("eta", "striker_velocity[trace0]", "striker_velocity[trace1]",
                              "sensor_gain[contact_6]", "sensor_gain[wall]")
    rows = {problem.labels[r.index]: (r.centre, r.sd) for r in problem.priors}
    assert rows["striker_velocity[trace0]"] == pytest.approx((0.15, 0.0015))  # header value, 1 %
    assert rows["striker_velocity[trace1]"] == pytest.approx((0.31, 0.002))  # the label wins
    assert rows["sensor_gain[wall]"] == pytest.approx((1.0, 0.02))
    x = np.array([1e-6, 0.15, 0.31 + 0.004, 1.0, 1.0 - 0.01])
    r = np.asarray(problem.residuals(x))
    assert r.shape == (problem.n_residuals,)
    np.testing.assert_allclose(r[-4:], [0.0, 2.0, 0.0, -0.5], atol=1e-12)
    assert problem.n_fitted == sum(e.n_fitted for e in problem.experiments) + 4


def test_uniform_narrows_the_bounds_and_unknown_labels_fail(traces):
    problem = make_problem(traces, ("eta_s", "mu"), priors=["eta_s=0..10us"])
    assert problem.instances[0].spec.upper == pytest.approx(1e-5)
    assert problem.priors == ()
    with pytest.raises(PriorError, match="must start at 0"):
        make_problem(traces, ("eta_s",), priors=["eta_s=1us..10us"])
    with pytest.raises(PriorError, match="no fitted parameter.*gain\\[nowhere\\]|no fitted parameter"):
        make_problem(traces, ("eta_s",), priors=["gain[nowhere]=1+-0.1"])
