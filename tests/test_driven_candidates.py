"""The driven candidates' protocol on bending data made by a second code path: a fixed-step
NumPy RK4 of one bead between a driven face and a wall, written here, with a law hidden. Fitted
on the lower drive levels, the protocol must name the hidden law by what it predicts for the
highest level."""

import math
from pathlib import Path

import numpy as np
import pytest

from fitting.driven.candidates import CANDIDATES, diagnose_laws, verdict
from fitting.driven.experiment import DrivenExperiment, Measurement
from hertzchain.driven.measurements import Bending
from hertzchain.driven.sweeper_files import LockinSweep

MASS, KAPPA, F0, GAMMA = 0.028, 1.0e10, 4.5, 2500.0
MODEL = {"ramp_periods": 25, "hold_periods": 35, "window_periods": 4, "steps_per_period": 48}


def numpy_lockin(frequencies_hz, drives_m, c_n_s2_m2):
    """RMS bead velocity at the drive frequency, (F, A): Hertz contacts at static force F0,
    viscous drag m*gamma*v, a loss c|d'|d' in each contact (the sum clipped at 0); the drive
    ramped linearly over 25 periods, held 35, the fundamental read over the last 4."""
    f = np.asarray(frequencies_hz, float)[:, None]
    a = np.asarray(drives_m, float)[None, :]
    omega = 2 * np.pi * f
    d0 = (F0 / KAPPA) ** (2 / 3)
    steps, periods = 48, 64
    dt = 1.0 / (f * steps)

    def force(delta, rate):
        return np.maximum(KAPPA * np.maximum(delta, 0.0) ** 1.5 + c_n_s2_m2 * np.abs(rate) * rate, 0.0) * (delta > 0)

    def rhs(t, x, v):
        ramp = np.minimum(t * f / 25.0, 1.0)
        u, du = ramp * a * np.cos(omega * t), ramp * a * (-omega) * np.sin(omega * t)
        du = du + np.where(t * f < 25.0, a * f / 25.0 * np.cos(omega * t), 0.0)
        acc = (force(d0 + u - x, du - v) - force(d0 + x, v)) / MASS - GAMMA * v
        return v, acc

    x = np.zeros(f.shape[0:1] + a.shape[1:])
    v = np.zeros_like(x)
    t = np.zeros_like(f)
    cos_sum, sin_sum = np.zeros_like(x), np.zeros_like(x)
    window = 4 * steps
    for step in range(periods * steps):
        k1 = rhs(t, x, v)
        k2 = rhs(t + dt / 2, x + dt / 2 * k1[0], v + dt / 2 * k1[1])
        k3 = rhs(t + dt / 2, x + dt / 2 * k2[0], v + dt / 2 * k2[1])
        k4 = rhs(t + dt, x + dt * k3[0], v + dt * k3[1])
        x = x + dt / 6 * (k1[0] + 2 * k2[0] + 2 * k3[0] + k4[0])
        v = v + dt / 6 * (k1[1] + 2 * k2[1] + 2 * k3[1] + k4[1])
        t = t + dt
        if step >= periods * steps - window:
            cos_sum += v * np.cos(omega * t)
            sin_sum += v * np.sin(omega * t)
    return np.hypot(cos_sum, sin_sum) * 2 / window / math.sqrt(2)


def experiment_with(c_n_s2_m2):
    f = np.arange(4300.0, 4801.0, 25.0)
    drives = np.array([2e-9, 6e-9, 18e-9])
    sweep = LockinSweep(f, drives, numpy_lockin(f, drives, c_n_s2_m2), 6.8e-7, 0.02, "numpy")
    measurement = Measurement("bending", "bend", Bending("bend", sweep), 6.8e-7, 0.41, np.ones(f.size, bool), ("b",))
    return DrivenExperiment(Path("synthetic.toml"), "synthetic", np.array([MASS]), np.array([1.4e10, 1.4e10]), F0,
                            6.8e-7, 0.41, 1, "velocity", None, None, MODEL, (measurement,), {})


def test_numpy_reference_is_the_linear_resonance_at_small_drive():
    """The second code path against the closed form: a weak drive's peak at the linearised
    resonance sqrt(2 k / m), k = 1.5 kappa^(2/3) F0^(1/3), and its height a*k/(m*gamma) (RMS)."""
    k = 1.5 * KAPPA ** (2 / 3) * F0 ** (1 / 3)
    f_lin = math.sqrt(2 * k / MASS) / (2 * math.pi)
    f = np.array([f_lin])
    rms = numpy_lockin(f, [1e-10], 0.0)[0, 0]
    assert rms == pytest.approx(1e-10 * k / (MASS * GAMMA) / math.sqrt(2), rel=2e-3)


@pytest.mark.slow
def test_protocol_names_a_hidden_velocity_squared_loss():
    """Hidden: c = 8000 N s^2/m^2 (the top drive's peak per nm drops 25 %, the middle one's 9 %). The base and the
    exponent, fitted on the two lower levels, miss the top one; the velocity-squared loss
    predicts it and is named best. The candidates: base, contact exponent, velocity-squared."""
    experiment = experiment_with(8000.0)
    chosen = [c for c in CANDIDATES if c.name in ("hertz_viscous", "contact_exponent", "velocity_squared_loss")]
    result = diagnose_laws(experiment, chosen, held_out_levels=1, max_steps=15, progress=False)
    by_name = {e["name"]: e for e in result["candidates"]}
    assert result["verdict"]["best"] == "velocity_squared_loss"
    assert by_name["velocity_squared_loss"]["bending"]["held_out_misfit_median"] < 0.01
    assert by_name["hertz_viscous"]["bending"]["held_out_misfit_median"] > 0.03
    fitted = by_name["velocity_squared_loss"]["constants"]["dissipation.0.c_n_s2_m2"]
    assert np.asarray(fitted).ravel()[0] == pytest.approx(8000.0, rel=0.15)


def test_verdict_names_only_what_improves_unfitted_measurements():
    """The verdict on hand-made entries: a candidate that fits the bending better but predicts
    the held-out level no better is not named; one that predicts it 2x better is."""
    def entry(name, held_out, median):
        return {"name": name, "bending": {"misfit_median": median, "shift": 0.0, "measured_shift": 0.0,
                                          "peak_ratio": 1.0, "measured_peak_ratio": 1.0,
                                          "held_out_misfit_median": held_out}}
    result = verdict([entry("base", 0.10, 0.05), entry("fits_better", 0.095, 0.01), entry("predicts", 0.04, 0.04)])
    assert result["named"] == ["predicts"]
    assert result["best"] == "predicts"
    assert "held_out_bending_misfit" in result["per_candidate"]["predicts"]["improves_unfitted_over_base"]


def test_verdict_does_not_name_a_candidate_for_a_measurement_it_was_fitted_on():
    """A candidate fitted on the tongue that lands on its tip is not named for it; the same
    tip predicted (not fitted) is."""
    def entry(name, tip_gap, fitted_on=("bending",)):
        return {"name": name, "fitted_on": list(fitted_on),
                "bending": {"misfit_median": 0.05, "shift": 0.0, "measured_shift": 0.0, "peak_ratio": 1.0,
                            "measured_peak_ratio": 1.0, "held_out_misfit_median": None},
                "tongue": {"amplitude_gap_log": tip_gap, "frequency_gap": 0.0}}
    result = verdict([entry("base", None), entry("fitted", 0.01, ("bending", "tongue")), entry("predicted", 0.01)])
    assert result["named"] == ["predicted"]
    assert result["per_candidate"]["fitted"]["improves_unfitted_over_base"] == []


def test_tongue_fundamental_is_a_sweep_of_the_levels_below_every_onset():
    from hertzchain.driven.measurements import Tongue, tongue_fundamental

    frequencies = np.array([6300.0, 7200.0, 8000.0])
    drives = np.array([15e-9, 17e-9, 20e-9, 40e-9])
    volts = np.arange(12.0).reshape(4, 3) * 1e-3
    tongue = Tongue("run", frequencies, drives, volts, 0 * volts, np.array([np.nan, 40e-9, 45e-9]), 2.3e-9,
                    7.5e-7, "file")
    sweep = tongue_fundamental(tongue, sensor_m_s_per_v=0.02125, levels=3).sweep
    np.testing.assert_array_equal(sweep.drive_amplitudes_m, drives[:3])
    np.testing.assert_allclose(sweep.rms_velocity_m_s, volts[:3].T * 0.02125)  # (F, A), m/s
    with pytest.raises(ValueError, match="at or above its lowest onset"):
        tongue_fundamental(tongue, sensor_m_s_per_v=0.02125, levels=4)


@pytest.mark.slow  # default-suite time on 2 cores; the Floquet thresholds stay in the default suite (tests/test_driven_floquet.py)
def test_micro_slip_candidate_predicts_the_floquet_continuations_thresholds():
    """A micro-slip chain's predicted tongue and loop onsets (`predict_thresholds`) are the
    Floquet continuation's (`period_doubling_onsets`, the sliders as state) over the same
    search range; `test_driven_thresholds.test_micro_slip_onset_and_its_derivative` checks that
    continuation against a scan of the multipliers."""
    from fitting.driven.candidates import predict_thresholds
    from fitting.driven.joint import SEARCH_ABOVE, SEARCH_BELOW
    from hertzchain import laws
    from hertzchain.driven import DrivenChain
    from hertzchain.driven.measurements import Loop, Tongue
    from hertzchain.driven.thresholds import period_doubling_onsets

    kappa = 3.8016e10  # the bending fit's single bead, F0 0.138 N, with micro-slip supports
    chain = DrivenChain([0.028], [kappa, kappa], 0.137979, 1751.8,
                        support_friction=laws.IwanSupport(1e6, 10e-9, elements=8))
    drives = np.linspace(5e-9, 30e-9, 11)
    tongue = Tongue("t", np.array([7900.0]), drives, np.ones((11, 1)), np.zeros((11, 1)), np.array([14e-9]), 2.5e-9,
                    7.5e-7, "s")
    loop = Loop("t", 7600.0, np.r_[drives, drives[-2::-1]], np.ones(21), np.zeros(21), 10, 20e-9, np.nan, np.nan,
                2.5e-9, 7.5e-7, "s")
    measurements = (Measurement("tongue", "t", tongue, 7.5e-7, 0.41, None, ("t",)),
                    Measurement("loop", "t", loop, 7.5e-7, 0.41, None, ("l",)))
    experiment = DrivenExperiment(Path("s.toml"), "s", np.array([0.028]), np.array([kappa, kappa]), 0.138, 7.5e-7,
                                  0.41, 1, "velocity", None, None, MODEL, measurements, {})
    predicted = predict_thresholds(experiment, chain, False, drive_scale=0.8)
    found = period_doubling_onsets(chain, [7900.0, 7600.0], lowest_amplitude_m=SEARCH_BELOW * 14e-9,
                                   highest_amplitude_m=SEARCH_ABOVE * 30e-9, steps_per_period=48)
    assert found.reasons == ("crossed", "crossed")
    assert predicted["tongue"]["model_tip_m"] == pytest.approx(found.amplitude_m[0] / 0.8, rel=1e-12)
    assert predicted["tongue"]["model_tip_m"] * 0.8 == pytest.approx(14.37e-9, rel=2e-3)  # measured 1.4371e-8 m
    assert predicted["loop"]["model_onset_up_m"] == pytest.approx(found.amplitude_m[1] / 0.8, rel=1e-12)
    assert predicted["tongue"]["how"] == predicted["loop"]["how"] == "Floquet threshold (continuation)"
