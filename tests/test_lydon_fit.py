"""Driven fits (fitting.driven) on synthetic lock-in sweeps made by a second code path: a
one-bead Hertz chain integrated by scipy's DOP853 with the same drive protocol (quintic
amplitude ramp, hold, lock-in over whole periods), demodulated here; and the experiment-file
and command-line checks."""

import math
from pathlib import Path

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from fitting.driven.experiment import (
    DrivenExperiment,
    DrivenExperimentError,
    load_driven_experiment,
)
from fitting.driven.lockin_fit import DrivenLayout, fit_driven
from fitting.uncertainty import ar1_correlation, ar1_inflation, lag1_autocorrelation
from hertzchain.driven.sweeper_files import LockinSweep

RAMP, HOLD, WINDOW = 12, 28, 4


def _scipy_lockin(mass_kg, kappa, precompression_n, gamma, frequencies_hz, drives_m):
    """RMS velocity at the drive frequency of a lone bead between a driven face and a wall
    (contacts kappa[0], kappa[1], Hertz, separable), every (f, a) run integrated at once."""
    f = np.repeat(frequencies_hz, drives_m.size)
    a = np.tile(drives_m, frequencies_hz.size)
    delta0 = (precompression_n / np.asarray(kappa)) ** (2 / 3)
    runs = f.size
    periods = RAMP + HOLD

    def rhs(s, y):  # time in periods of each run: t = s / f
        x, v = y[:runs], y[runs:]
        ramp = np.clip(s / RAMP, 0, 1)
        u = a * ramp**3 * (10 - 15 * ramp + 6 * ramp**2) * np.cos(2 * np.pi * s)
        front = kappa[0] * np.maximum(delta0[0] + u - x, 0) ** 1.5
        back = kappa[1] * np.maximum(delta0[1] + x, 0) ** 1.5
        accel = (front - back) / mass_kg - gamma * v
        return np.concatenate([v / f, accel / f])  # d/ds = (1/f) d/dt

    samples = np.linspace(periods - WINDOW, periods, 64 * WINDOW + 1)[:-1]
    sol = solve_ivp(rhs, (0, periods), np.zeros(2 * runs), method="DOP853", rtol=1e-9, atol=1e-14,
                    t_eval=samples)
    v = sol.y[runs:]
    c = 2 * np.mean(v * np.exp(-2j * np.pi * samples)[None], axis=1)
    return (np.abs(c) / np.sqrt(2)).reshape(frequencies_hz.size, drives_m.size)


def _experiment(mass_kg, frequencies, drives, velocity, *, drive_m_per_v=1e-7, n_beads=1):
    sweep = LockinSweep(frequencies, drives, velocity, drive_m_per_v, 0.02, "synthetic")
    return DrivenExperiment(
        path=Path("synthetic.toml"), label="synthetic", bead_mass_kg=np.full(n_beads, mass_kg),
        contact_kappa_n_m1p5=np.full(n_beads + 1, 1e10), precompression_n=1.0, drive_m_per_v=drive_m_per_v,
        drive_uncertainty=0.4, sensor_bead=1, quantity="velocity", sweep=sweep,
        fit_mask=np.ones(frequencies.size, bool),
        model={"ramp_periods": RAMP, "hold_periods": HOLD, "window_periods": WINDOW, "steps_per_period": 64},
    )


def test_fit_recovers_constants_of_a_scipy_simulated_bead():
    """A 15 g bead (not the paper's), 2.6 kHz linear resonance, F0 = 0.1 N (static overlap 75
    nm), gamma = 1200/s, true drive 1.15 x nominal, three drives (the bead swinging by up to
    ~30 nm: the resonance softens by less than one 17 Hz bin, yet the curves' shapes change):
    the fit, from the data's own start values and the precompression scan, recovers every
    constant to 2e-3 (measured: 4e-4, 1.0e-3, 8e-4, 1.6e-3). The resonance comes out low by
    velocity-Verlet's (2 pi/64)^2/24 = 4.0e-4 at 64 steps a period. The standard errors
    here reflect only the tiny residuals (the two integrators agree to 3e-5 of a peak), not
    this discretisation bias, so the test compares with the truth, not with them."""
    mass, f_lin, f0, gamma, scale = 0.015, 2600.0, 0.1, 1200.0, 1.15
    k_each = mass * (2 * np.pi * f_lin) ** 2 / 2
    kappa = np.full(2, (k_each / (1.5 * f0 ** (1 / 3))) ** 1.5)
    frequencies = np.linspace(2200.0, 2850.0, 40)
    drives = np.array([0.5e-9, 2.0e-9, 4.0e-9])  # nominal; the chain feels scale x these
    velocity = _scipy_lockin(mass, kappa, f0, gamma, frequencies, scale * drives)
    experiment = _experiment(mass, frequencies, drives, velocity)
    result = fit_driven(experiment, progress=False)
    layout = DrivenLayout.for_beads(1)
    truth = {"linear_resonance_hz": f_lin, "precompression_n": f0, "damping_rate_per_s": gamma, "drive_scale": scale}
    assert result.converged
    assert np.max(result.misfit) < 2e-4
    for name, true in truth.items():
        i = layout.index(name)[0]
        assert result.x[i] == pytest.approx(true, rel=2e-3), name
        assert 0 < result.stderr[i] < np.inf, name
    f = layout.index("linear_resonance_hz")[0]
    assert result.x[f] / f_lin - 1 == pytest.approx(-(2 * np.pi / 64) ** 2 / 24, abs=2e-4)


def test_a_driven_fit_started_at_its_optimum_ends_there_at_once():
    """With 14 drive levels or more `fit_driven` fits a coarse grid first, whose optimum is not
    the one on every point: from a given start it tests the start on every point first, so a
    refit from a fit's own values ends at once (0 steps) with the same values and standard
    errors. Data: the scipy bead of the test above at 14 drives, read through a response that
    ripples by 3 % across the band (a misfit no constant removes, as in measured sweeps, so
    that the coarse grid's optimum lies elsewhere; without the test the refit walks away and
    back: measured, 16 steps)."""
    mass, f_lin, f0, gamma, scale = 0.015, 2600.0, 0.1, 1200.0, 1.15
    kappa = np.full(2, (mass * (2 * np.pi * f_lin) ** 2 / 2 / (1.5 * f0 ** (1 / 3))) ** 1.5)
    frequencies = np.linspace(2300.0, 2800.0, 16)
    drives = np.geomspace(0.5e-9, 4.0e-9, 14)
    velocity = _scipy_lockin(mass, kappa, f0, gamma, frequencies, scale * drives)
    velocity = velocity * (1 + 0.03 * np.sin(2 * np.pi * frequencies / 170.0))[:, None]
    experiment = _experiment(mass, frequencies, drives, velocity)
    first = fit_driven(experiment, progress=False)
    assert first.converged and first.steps > 0
    again = fit_driven(experiment, x_start=first.x, progress=False)
    assert again.converged and again.steps == 0
    np.testing.assert_array_equal(again.x, first.x)
    np.testing.assert_allclose(again.stderr, first.stderr, rtol=1e-9)


def test_lag1_autocorrelation_of_an_ar1_series():
    rng = np.random.default_rng(0)
    e = rng.normal(size=(20000, 3))
    r = np.zeros_like(e)
    for t in range(1, e.shape[0]):
        r[t] = 0.9 * r[t - 1] + e[t]
    assert lag1_autocorrelation(r) == pytest.approx(0.9, abs=0.01)
    # AR(1) of rho 0.9: its 20000 points per column count as 20000 (1 - 0.9)/(1 + 0.9); the
    # variance of a mean over a column is 19 times a white series' (the closed form)
    assert ar1_inflation(ar1_correlation(r)) == pytest.approx(19.0, rel=0.15)
    means = [np.mean(r[k:k + 400, j]) for k in range(0, 20000, 400) for j in range(3)]
    assert np.var(means) * 400 == pytest.approx(ar1_inflation(0.9) * np.var(e) / (1 - 0.81), rel=0.5)
    # anticorrelated residuals are taken as white; rho = 1 stays finite
    assert ar1_correlation(np.array([1.0, -1.0, 1.0, -1.0, 1.0])) == 0.0
    assert ar1_inflation(-0.5) == 1.0 and ar1_inflation(1.0) == pytest.approx(1999.0)


def _write(tmp_path, text):
    path = tmp_path / "e.toml"
    path.write_text(text)
    return path


GOOD = """kind = "driven"
[chain]
n_beads = 1
bead_mass_kg = 0.028
contact_kappa_n_m1p5 = [1.38e10, 1.38e10]
precompression_n = "4.5N"
[drive]
calibration_m_per_v = 6.834e-7
calibration_uncertainty = 0.41
[sensor]
calibration_m_s_per_v = 0.02125
[sweep]
amplitude_file = "run Signal Amplitude_02013Jul3_10h29m15s.txt"
exclude_hz = [[3004, 3006]]
"""


def test_experiment_file_reads_a_sweep_from_the_data_dir(tmp_path):
    data = tmp_path / "data"
    data.mkdir()
    rows = ["Frequency (Hz)\t0.001V\t0.002V"] + [f"{3000 + 5 * i}\t{i * 1e-3:g}\t{i * 2e-3:g}" for i in range(20)]
    (data / "run Signal Amplitude_02013Jul3_10h29m15s.txt").write_text("\n".join(rows) + "\n")
    experiment = load_driven_experiment(_write(tmp_path, GOOD), data)
    np.testing.assert_allclose(experiment.sweep.drive_amplitudes_m, [6.834e-10, 1.3668e-9])
    np.testing.assert_allclose(experiment.sweep.rms_velocity_m_s[3], [3e-3 * 0.02125, 6e-3 * 0.02125])
    assert experiment.fit_mask.sum() == 19 and not experiment.fit_mask[1]
    assert experiment.model["steps_per_period"] == 48


@pytest.mark.parametrize(
    ("change", "message"),
    [
        (("kind = \"driven\"", "kind = \"impact\""), "kind = 'impact'"),
        (("n_beads = 1", "n_beads = 1\ncolour = 3"), "unknown key 'colour'"),
        (("[1.38e10, 1.38e10]", "[1.38e10]"), "n_beads \\+ 1 = 2"),
        (("calibration_uncertainty = 0.41", "calibration_uncertainty = 41"), "relative"),
        (("[sensor]", "[sensor]\nbead = 2"), "bead = 2"),
        (("exclude_hz = [[3004, 3006]]", "exclude_hz = [[3005, 3000]]"), "low < high"),
        (("Amplitude_02013", "Amplitude_02014"), "no such file"),
    ],
)
def test_experiment_file_errors_name_key_and_fix(tmp_path, change, message):
    data = tmp_path / "data"
    data.mkdir()
    rows = ["Frequency (Hz)\t0.001V"] + [f"{3000 + 5 * i}\t1e-3" for i in range(20)]
    (data / "run Signal Amplitude_02013Jul3_10h29m15s.txt").write_text("\n".join(rows) + "\n")
    with pytest.raises(DrivenExperimentError, match=message):
        load_driven_experiment(_write(tmp_path, GOOD.replace(*change)), data)


def test_experiment_file_needs_the_data_dir(tmp_path):
    with pytest.raises(DrivenExperimentError, match="--data-dir"):
        load_driven_experiment(_write(tmp_path, GOOD), None)


def _driven_and_trace_files(tmp_path):
    """(a driven experiment file, its data folder, a trace file) for the command-line checks."""
    data = tmp_path / "data"
    data.mkdir()
    rows = ["Frequency (Hz)\t0.001V"] + [f"{3000 + 5 * i}\t1e-3" for i in range(20)]
    (data / "run Signal Amplitude_02013Jul3_10h29m15s.txt").write_text("\n".join(rows) + "\n")
    trace = tmp_path / "trace.csv"
    trace.write_text("# format = hertzchain-trace/1\ntime_s,wall\n0,0\n")
    return _write(tmp_path, GOOD), data, trace


def test_command_line_refuses_what_a_driven_fit_cannot_use(tmp_path, capsys):
    """`hertzchain fit/diagnose` dispatch on the file's kind; trace-fit options given for a
    driven file, a driven file mixed with a trace file, and --data-dir for trace files are
    refused by name (exit status 2), nothing silently dropped."""
    from hertzchain.cli import main

    toml, data, trace = _driven_and_trace_files(tmp_path)
    cases = [
        (["fit", str(toml), "--data-dir", str(data), "--posterior"], "--posterior"),
        (["fit", str(toml), "--data-dir", str(data), "--params", "eta"], "not driven parameters"),
        (["diagnose", str(toml), "--data-dir", str(data), "--free", "C"], "--free"),
        (["fit", str(toml), str(trace), "--data-dir", str(data)], "cannot be mixed"),
        (["fit", str(trace), "--data-dir", str(data)], "--data-dir is for driven"),
        (["fit", str(toml)], "give --data-dir"),
    ]
    for argv, message in cases:
        assert main(argv + ["--out", str(tmp_path / "out")]) == 2, argv
        assert message in capsys.readouterr().err, argv


def _candidate(name, *, held_out, median, converged=True, tongue_tip=None):
    """A `fit_candidate` result with the numbers the verdict and the conclusion read (no
    simulation): bending measures, the held-out levels' misfit, optionally a tongue tip."""
    entry = {"name": name, "mechanism": f"the law {name}", "converged": converged, "steps": 7,
             "bending": {"misfit_median": median, "shift": -0.06, "measured_shift": -0.074, "peak_ratio": 0.88,
                         "measured_peak_ratio": 0.70, "held_out_misfit_median": held_out, "held_out_levels": 4}}
    if tongue_tip is not None:
        entry["tongue"] = {"amplitude_gap_log": math.log(tongue_tip), "frequency_gap": 0.01}
    return entry


def test_driven_diagnosis_conclusion_says_what_each_candidate_explains_in_numbers():
    """The conclusion of the candidate protocol (`fitting.driven.diagnosis.finished`) on hand-made
    entries: the named candidate and why, every candidate's measurements with their numbers
    and targets, measurements the experiment does not hold left out (a bending-only file has
    no tongue), and an unconverged fit and a failed one named, `converged` False."""
    from fitting.driven.candidates import verdict
    from fitting.driven.diagnosis import finished

    entries = [_candidate("hertz_viscous", held_out=0.10, median=0.05),
               _candidate("fits_better", held_out=0.095, median=0.01),
               _candidate("predicts", held_out=0.02, median=0.04, converged=False)]
    result = {"experiment": "e.toml", "candidates": entries, "verdict": verdict(entries), "elapsed_s": 1.0,
              "failed": [{"name": "rough_contact", "mechanism": "asperities", "error": "kappa must be > 0"}]}
    done = finished(result, ["bending"], {"held_out_levels": 4, "level_stride": 4, "max_steps": 20})
    text = done["conclusion"]
    assert "Named: predicts (closest to the data on the predicted measurements: predicts)" in text
    assert "the bending run's top 4 drive levels." in text
    line = next(t for t in text.splitlines() if t.startswith("predicts "))
    assert "NOT CONVERGED after 7 steps" in line
    assert "explains held-out drive levels' misfit (median, predicted) 2.00 % of each curve's peak (target <= 3 %)" \
        in line
    assert "Does not explain bending misfit (median over drive levels) 4.00 % of each curve's peak (target <= 3 %)" \
        in line and "peak velocity per nm of drive, top over lowest 0.880 (target within 0.07" in line
    assert "Better than the base on: held_out_bending_misfit" in line
    assert "tongue" not in text.split("drive levels.", 1)[1]  # no tongue in the file: not listed as missed
    assert not done["converged"]
    assert done["unconverged_fits"] == ["the fit of predicts (7 steps)",
                                        "the fit of rough_contact (stopped: kappa must be > 0)"]
    assert text.splitlines()[-1].startswith("NOT CONVERGED: the fit of predicts (7 steps); the fit of rough_contact")
    # a tongue the experiment holds and a candidate predicts no period doubling for: said so
    entries = [_candidate("hertz_viscous", held_out=0.10, median=0.05, tongue_tip=0.31)]
    entries[0]["tongue"]["amplitude_gap_log"] = None
    result = {"experiment": "e.toml", "candidates": entries, "verdict": verdict(entries), "elapsed_s": 1.0,
              "failed": []}
    text = finished(result, ["bending", "tongue"], {"held_out_levels": 4})["conclusion"]
    assert "No mechanism named" in text
    assert "tongue tip amplitude, model / data: none predicted" in text


def test_driven_diagnosis_options_are_refused_where_they_do_not_apply(tmp_path, capsys):
    """`hertzchain diagnose` on a driven file refuses the trace diagnosis's options and an unknown
    candidate law by name; on trace files it refuses the driven protocol's knobs (exit 2)."""
    from hertzchain.cli import main

    toml, data, trace = _driven_and_trace_files(tmp_path)
    cases = [
        (["diagnose", str(toml), "--data-dir", str(data), "--min-share", "0.5"], "--min-share"),
        (["diagnose", str(toml), "--data-dir", str(data), "--candidates", "magic"], "not driven candidate laws"),
        (["diagnose", str(toml), "--data-dir", str(data), "--held-out-levels", "0"], "--held-out-levels 0"),
        (["diagnose", str(trace), "--level-stride", "2"], "--level-stride: not available for trace files"),
    ]
    for argv, message in cases:
        assert main(argv + ["--out", str(tmp_path / "out")]) == 2, argv
        assert message in capsys.readouterr().err, argv
