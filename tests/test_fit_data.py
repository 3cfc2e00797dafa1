"""Checks on the data a fit accepts: NaN, short records, coarse sampling, noise estimate."""

import dataclasses

import numpy as np
import pytest

import fitting
import hertzchain as hc
from fitting.data import FitInputError, estimate_noise_std, make_experiment
from fitting.synthetic import paper_setups, synthetic_traces
from hertzchain.io.tracefile import TraceFile, setup_header


def _trace(interval_s=1e-6, t_end_s=1.2e-3, noise=0.05, seed=0, velocity=0.2):
    """A clean-enough pulse train from the simulator with white noise."""
    setup = hc.ChainSetup(striker_velocity_m_s=velocity)
    traces = hc.simulate(setup, t_end_s=t_end_s, sample_interval_s=interval_s, contacts=(5,))
    rng = np.random.default_rng(seed)
    channels = {
        name: np.asarray(traces.forces_n[name]) + noise * rng.standard_normal(traces.time_s.shape)
        for name in traces.channel_names
    }
    header = setup_header(setup) | {"noise_std_n": noise}
    return TraceFile(header=header, time_s=np.asarray(traces.time_s), channels=channels)


def test_noise_estimate_from_second_differences():
    trace = _trace(noise=0.3, t_end_s=2e-3)
    sigma = estimate_noise_std(trace.channels["contact_5"])
    # 2000 samples: the robust estimate scatters by a few percent
    assert sigma == pytest.approx(0.3, rel=0.06)


def test_header_noise_is_used_and_estimate_otherwise():
    trace = _trace(noise=0.2)
    assert make_experiment(trace).noise_source == "header"
    header = {k: v for k, v in trace.header.items() if k != "noise_std_n"}
    estimated = make_experiment(dataclasses.replace(trace, header=header))
    assert estimated.noise_source == "estimated"
    assert estimated.noise_std_n["contact_5"] == pytest.approx(0.2, rel=0.1)


def test_nan_in_a_channel_is_refused():
    trace = _trace()
    bad = dict(trace.channels)
    bad["wall"] = bad["wall"].copy()
    bad["wall"][10] = np.nan
    # TraceFile itself refuses NaN; an Experiment built around such arrays must too
    with pytest.raises(ValueError, match="NaN"):
        make_experiment(dataclasses.replace(trace, channels=bad))


def test_record_too_short_for_the_pulse():
    # 0.25 ms: the pulse has not reached the wall yet
    trace = _trace(t_end_s=0.25e-3)
    with pytest.raises(FitInputError, match="too short"):
        make_experiment(trace)
    # fitting only the contact that the pulse did reach is fine
    assert make_experiment(trace, channels=("contact_5",)).channels == ("contact_5",)


def test_sampling_too_coarse_for_the_pulse():
    trace = _trace(interval_s=20e-6, t_end_s=2e-3, velocity=0.3)
    with pytest.raises(FitInputError, match="too coarsely"):
        make_experiment(trace)


def test_unknown_channel():
    with pytest.raises(FitInputError, match="no channel 'contact_9'"):
        make_experiment(_trace(), channels=("contact_9",))


def test_sub_dither_channels_make_the_fit_expect_correlated_residuals():
    # the importer writes x_import_<channel>_analogue_noise_steps; below half a converter step
    # the fit's covariance accounts for sample-to-sample correlation, with lags of the
    # striker's collision time in samples
    import importlib

    from hertzchain import contact

    fit_module = importlib.import_module("fitting.fit")
    setups = paper_setups([0.2], eta_s=2e-6, mu=0.19, mu_star=0.02, n_beads=8)
    trace = synthetic_traces(setups, contacts=(3,), t_end_s=4e-4, noise_std_n=0.05, seed=2)[0]
    quiet, coarse = dataclasses.replace(trace, header=dict(trace.header)), dataclasses.replace(
        trace, header={**trace.header, "x_import_wall_analogue_noise_steps": "0.25",
                       "x_import_contact_3_analogue_noise_steps": "1.1"})
    problem = fitting.make_problem([make_experiment(quiet, label="a"), make_experiment(coarse, label="b")],
                                   ("eta_s", "mu", "C"))
    series, reason = fit_module._correlated_series(problem)
    setup = quiet.setup()
    striker, bead = float(setup.striker_mass_kg), float(setup.bead_mass_kg[0])
    duration = float(contact.collision_time(striker * bead / (striker + bead), float(setup.contact_kappa()[0]), 0.2))
    assert {lags for _, lags in series} == {round(duration / float(quiet.time_s[1] - quiet.time_s[0]))}
    assert len(series) == 4 and sum(len(rows) for rows, _ in series) == problem.n_fitted
    assert reason is not None and "b:wall (0.25 step)" in reason and "contact_3" not in reason
    assert fit_module._correlated_series(fitting.make_problem([make_experiment(quiet)], ("eta_s",)))[1] is None
