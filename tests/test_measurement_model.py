"""How channels are measured: redundant header keys, per-channel noise, clipped samples,
pre-trigger records and AC-coupled (piezo) sensors that do not see a static preload.

The data of the preload tests come from the diffrax reference solver (not the Verlet
solver the fit uses) on a chain that is not the paper's: 8 brass beads of 5 mm radius
struck by a 3 mm brass ball."""

import math
import warnings

import jax
import numpy as np
import pytest

import fitting
import hertzchain as hc
from hertzchain.acquisition import Acquisition, acquire_trace
from hertzchain.io.tracefile import TraceFile, TraceFileError, read_trace, setup_header, write_trace
from hertzchain.materials import BRASS
from hertzchain.reference import simulate_reference

PRELOAD_N = 2.0


def _header(**extra):
    header = setup_header(hc.ChainSetup(5, striker_mass_kg=0.02))
    return header | extra


def _trace(header, n=50, channels=("wall",)):
    time = 1e-6 * np.arange(-10, n - 10)
    return TraceFile(header=header, time_s=time, channels={c: np.sin(time * 1e4) for c in channels})


def test_redundant_striker_and_bead_keys_that_agree_are_accepted():
    header = _header()
    density = header["bead_density_kg_m3"]
    radius = (3 * header["striker_mass_kg"] / (4 * math.pi * density)) ** (1 / 3)
    bead_mass = 4 / 3 * math.pi * density * header["bead_radius_m"] ** 3
    trace = _trace(header | {"striker_radius_m": radius * (1 + 1e-12), "bead_mass_kg": bead_mass * 1.001})
    setup = trace.setup()
    assert float(setup.striker_mass_kg) == pytest.approx(0.02, rel=1e-9)
    # the density alone still defines the beads (the mass agrees to 0.1 %)
    assert float(setup.bead_mass_kg[0]) == pytest.approx(bead_mass, rel=1e-12)
    # a mass alone defines the density
    only_mass = {k: v for k, v in header.items() if k != "bead_density_kg_m3"} | {"bead_mass_kg": bead_mass}
    assert float(_trace(only_mass).setup().bead_density_kg_m3[0]) == pytest.approx(density, rel=1e-12)


def test_redundant_keys_that_disagree_name_both_values_and_the_implied_one():
    header = _header()
    density = header["bead_density_kg_m3"]
    radius = (3 * header["striker_mass_kg"] / (4 * math.pi * density)) ** (1 / 3)
    with pytest.raises(TraceFileError, match=r"striker_mass_kg = 0\.02 disagrees with striker_radius_m = .* imply 0\.0212"):
        _trace(header | {"striker_radius_m": radius * 1.02})
    bead_mass = 4 / 3 * math.pi * density * header["bead_radius_m"] ** 3
    with pytest.raises(TraceFileError, match=r"bead_mass_kg = .* disagrees with bead_radius_m = 0\.013 and "
                                              r"bead_density_kg_m3 = 7780, which imply 0\.0715976"):
        _trace(header | {"bead_mass_kg": bead_mass * 1.01})
    no_density = {k: v for k, v in header.items() if k != "bead_density_kg_m3"}
    with pytest.raises(TraceFileError, match="bead_density_kg_m3 = ...' \\(or '# bead_mass_kg"):
        _trace(no_density)


def test_measurement_keys_round_trip_and_are_checked(tmp_path):
    header = _header(noise_std_n=0.5, noise_std_n_wall=0.2, ac_channels="wall", clipped_wall="3-5,9")
    trace = _trace(header, channels=("wall", "contact_2"))
    write_trace(tmp_path / "t.csv", trace)
    back = read_trace(tmp_path / "t.csv")
    assert back.channel_noise_std_n("wall") == 0.2 and back.channel_noise_std_n("contact_2") == 0.5
    assert back.ac_channels == ("wall",)
    np.testing.assert_array_equal(np.flatnonzero(back.clipped("wall")), [3, 4, 5, 9])
    assert not back.clipped("contact_2").any()
    assert back.time_s[0] == pytest.approx(-10e-6)  # pre-trigger samples keep negative times
    with pytest.raises(TraceFileError, match="noise_std_n_contact_4 names a channel the table does not have"):
        _trace(_header(noise_std_n_contact_4=0.1))
    with pytest.raises(TraceFileError, match="ac_channels names 'sensor_3'"):
        _trace(_header(ac_channels="sensor_3"))
    with pytest.raises(TraceFileError, match="clipped_wall names row 60, but the table has rows 0..49"):
        _trace(_header(clipped_wall="58-60"))
    with pytest.raises(TraceFileError, match="clipped rows must be numbers or ranges a-b, got 'x'"):
        _trace(_header(clipped_wall="x"))


@pytest.fixture(scope="module")
def preloaded():
    """A preloaded brass chain simulated by the diffrax reference solver, 0.2 us samples."""
    setup = hc.ChainSetup(8, bead_radius_m=5e-3, bead_density_kg_m3=BRASS.density_kg_m3,
                          bead_youngs_pa=BRASS.youngs_pa, bead_poisson=BRASS.poisson,
                          striker_radius_m=3e-3, striker_velocity_m_s=0.3, eta_s=1e-6,
                          precompression_n=PRELOAD_N)
    traces = simulate_reference(setup, t_end_s=0.3e-3, sample_interval_s=0.2e-6, contacts=(3,), rtol=1e-9)
    forces = {name: np.asarray(traces.forces_n[name]) for name in traces.channel_names}
    # the chain rests at the preload before the impact
    assert forces["contact_3"][0] == pytest.approx(PRELOAD_N, rel=1e-6)
    return setup, np.asarray(traces.time_s), forces


def _record(preloaded, coupling, seed=1):
    setup, time, forces = preloaded
    setting = Acquisition(sample_interval_s=1e-6, record_length=300, pre_trigger_samples=40,
                          noise_std_n=0.02, coupling=coupling, dc_offset_v=0.013)
    return acquire_trace(setup, time, forces, setting, seed=seed)


def test_ac_coupled_sensors_do_not_see_the_preload_and_dc_coupled_ones_do(preloaded):
    ac, dc = _record(preloaded, "ac"), _record(preloaded, "dc")
    before = ac.time_s < 0
    assert before.sum() == 40 and ac.time_s[40] == 0.0 and ac.time_s[41] == pytest.approx(1e-6)
    for name in ("contact_3", "wall"):
        assert abs(np.mean(ac.channels[name][before])) < 4 * 0.02 / math.sqrt(40)
        assert np.mean(dc.channels[name][before]) == pytest.approx(PRELOAD_N, abs=4 * 0.02 / math.sqrt(40))
        # after the impact the two differ by the preload alone
        np.testing.assert_allclose(dc.channels[name] - ac.channels[name], PRELOAD_N, atol=0.2)
    assert ac.ac_channels == ("contact_3", "wall") and dc.ac_channels == ()


def test_fit_model_honours_ac_coupling(preloaded):
    """At the true parameters the whitened residuals are unit noise for either coupling, as
    long as the file says which; read as DC, AC data miss by the preload everywhere."""
    for coupling in ("ac", "dc"):
        trace = _record(preloaded, coupling)
        problem = fitting.make_problem([trace], ("eta_s",))
        x = np.array([1e-6])
        r2 = float(np.mean(np.asarray(jax.jit(problem.residuals)(x)) ** 2))
        assert r2 == pytest.approx(1.0, abs=0.15), coupling
    wrong = _record(preloaded, "ac")
    header = {k: v for k, v in wrong.header.items() if k != "ac_channels"}
    misread = fitting.make_problem([TraceFile(header, wrong.time_s, wrong.channels)], ("eta_s",))
    r = np.asarray(misread.residuals(np.array([1e-6])))
    assert np.mean(r[:40]) == pytest.approx(PRELOAD_N / 0.02, rel=0.1)  # the offset it predicts


@pytest.mark.slow  # default-suite time on 2 cores; AC coupling in the fit model stays in the default suite
def test_eta_fitted_to_ac_coupled_preloaded_data_without_an_offset(preloaded):
    trace = _record(preloaded, "ac", seed=4)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", fitting.FitWarning)
        result = fitting.fit([trace], ("eta_s",), start={"eta_s": 0.5e-6}, progress=False)
    assert result.reduced_chi2 == pytest.approx(1.0, abs=0.15)
    assert abs(result.values["eta"] - 1e-6) < 4 * result.stderr["eta"]
    assert result.stderr["eta"] < 0.1e-6


def test_clipped_samples_are_left_out_of_the_fit_with_a_warning(preloaded):
    setup, time, forces = preloaded
    peak = float(np.max(forces["wall"]))
    setting = Acquisition(sample_interval_s=1e-6, record_length=300, pre_trigger_samples=40, noise_std_n=0.02,
                          coupling="ac", bits=12,
                          full_scale_v={"wall": 0.8 * (peak - PRELOAD_N) * 0.1124, "contact_3": 1.0},
                          sensitivity_v_per_n={"wall": 0.1124, "contact_3": 0.01124})
    trace = acquire_trace(setup, time, forces, setting, seed=2)
    clipped = trace.clipped("wall")
    assert clipped.sum() >= 3
    with pytest.warns(fitting.data.DataWarning, match=rf"channel wall has {clipped.sum()} samples at the "
                                                      "digitiser's range limit"):
        experiment = fitting.make_experiment(trace, label="clip")
    problem = fitting.make_problem([experiment], ("eta_s",))
    assert problem.n_fitted == problem.n_residuals - clipped.sum()
    r = np.asarray(problem.residuals(np.array([1e-6])))
    wall = problem.residual_slices()[0]["wall"]
    assert np.all(r[wall][clipped] == 0.0)
    # the rest is unit noise: the clipped samples, far off the model, are not in it
    assert float(np.sum(r**2) / problem.n_fitted) == pytest.approx(1.0, abs=0.15)


@pytest.mark.slow  # default-suite time on 2 cores; `pytest -m slow` runs it
def test_simulate_and_design_plans_read_a_preload_as_the_coupling_says(tmp_path):
    from fitting.design import plan_experiments
    from hertzchain.cli import main

    for coupling, rest in (("dc", PRELOAD_N), ("ac", 0.0)):
        out = tmp_path / coupling
        assert main(["simulate", "--n-beads", "6", "--precompression", "2N", "--t-end", "0.2ms",
                     "--coupling", coupling, "--out", str(out)]) == 0
        trace = read_trace(out / "traces.csv")
        assert trace.channels["wall"][0] == pytest.approx(rest, abs=1e-6)
        assert trace.ac_channels == (() if coupling == "dc" else trace.channel_names)
        setup = hc.ChainSetup(6, precompression_n=PRELOAD_N)
        (plan,) = plan_experiments(setup, [0.2], channels=("wall",), t_end_s=0.3e-3, coupling=coupling)
        assert plan.data("wall")[0] == pytest.approx(rest, abs=1e-6)
        problem = fitting.make_problem([plan], ("eta_s",))
        # the noise-free plan is the model itself, whichever the coupling
        assert float(np.max(np.abs(np.asarray(problem.residuals(np.array([0.0])))))) < 1e-3
