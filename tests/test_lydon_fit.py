"""Driven fits (fitting.driven) on synthetic lock-in sweeps made by a second code path: a
one-bead Hertz chain integrated by scipy's DOP853 with the same drive protocol (quintic
amplitude ramp, hold, lock-in over whole periods), demodulated here; and the experiment-file
and command-line checks."""

from pathlib import Path

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from hertzchain.driven.sweeper_files import LockinSweep

from fitting.driven import DrivenLayout, fit_driven, lag1_autocorrelation
from fitting.driven_experiment import DrivenExperiment, DrivenExperimentError, load_driven_experiment

RAMP, HOLD, WINDOW = 12, 28, 4


def _scipy_lockin(mass_kg, kappa, precompression_n, gamma, frequencies_hz, drives_m):
    """RMS velocity at the drive frequency of a lone bead between a driven face and a wall
    (contacts kappa[0], kappa[1], Hertz, separable), every (f, a) run integrated at once."""
    f = np.repeat(frequencies_hz, drives_m.size)
    a = np.tile(drives_m, frequencies_hz.size)
    w = 2 * np.pi * f
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


def test_command_line_refuses_what_a_driven_fit_cannot_use(tmp_path, capsys):
    """`hertzchain fit/diagnose` dispatch on the file's kind; trace-fit options given for a
    driven file, a driven file mixed with a trace file, and --data-dir for trace files are
    refused by name (exit status 2), nothing silently dropped."""
    from hertzchain.cli import main

    data = tmp_path / "data"
    data.mkdir()
    rows = ["Frequency (Hz)\t0.001V"] + [f"{3000 + 5 * i}\t1e-3" for i in range(20)]
    (data / "run Signal Amplitude_02013Jul3_10h29m15s.txt").write_text("\n".join(rows) + "\n")
    toml = _write(tmp_path, GOOD)
    trace = tmp_path / "trace.csv"
    trace.write_text("# format = hertzchain-trace/1\ntime_s,wall\n0,0\n")
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


def test_diagnosis_names_what_a_scipy_simulated_bead_hides():
    """The driven diagnosis (`fitting.driven_diagnosis`) on the scipy bead above: its contacts
    are 2.6 kHz at F0 = 0.1 N where the file says Hertz 1e10 N/m^1.5 at 1 N (3.4 kHz), and the
    drive is 1.15 x its calibration; there is no contact loss. It must name the contacts and
    preload first, then the drive calibration (whose fit must leave the valley where the first
    round's stiffness and preload compensated it: measured 13.2 % -> 0.4 % of a peak), and not
    the Kuwabara-Kono loss, with the resonance, damping and drive scale near the truth. The
    precompression is not asserted: with these drives the bead bends the resonance by less
    than a frequency bin, and the diagnosis's short fits (25 steps on the lock-in grid) leave it
    where the curves no longer tell (`fit_driven` recovers it, the test above)."""
    from fitting.driven_diagnosis import diagnose_driven

    mass, f_lin, f0, gamma, scale = 0.015, 2600.0, 0.1, 1200.0, 1.15
    k_each = mass * (2 * np.pi * f_lin) ** 2 / 2
    kappa = np.full(2, (k_each / (1.5 * f0 ** (1 / 3))) ** 1.5)
    frequencies = np.linspace(2200.0, 2850.0, 40)
    drives = np.array([0.5e-9, 2.0e-9, 4.0e-9])
    experiment = _experiment(mass, frequencies, drives, _scipy_lockin(mass, kappa, f0, gamma, frequencies,
                                                                       scale * drives))
    result = diagnose_driven(experiment, level_stride=1, progress=False)
    assert result["missing_effects"] == ["contact_stiffness_and_preload", "drive_calibration"]
    first, second = result["steps"][:2]
    assert first["share_of_chi2_removed"] > 0.9 and second["share_of_chi2_removed"] > 0.9
    assert not result["steps"][2]["accepted"]
    final = second["after"]["x"]
    assert final["linear_resonance_hz"] == pytest.approx(f_lin, rel=3e-3)
    assert final["damping_rate_per_s"] == pytest.approx(gamma, rel=2e-2)
    assert final["drive_scale"] == pytest.approx(scale, rel=1e-2)
    assert second["after"]["gap_median"] < 0.01


def _diagnosis_result(measured_ratio, step_ratios, precompression_after_n, model_ratio, probe_ratio):
    """A `diagnose_driven` result with the numbers the conclusion reads (no simulation): one
    step freeing the contacts, its top-over-lowest peak-per-drive ratio going
    step_ratios[0] -> step_ratios[1]; the file's precompression 3 N."""
    nominal = {"x": {"linear_resonance_hz": 3000.0, "precompression_n": 3.0, "eta_s": 0.0},
               "gap_median": 0.2, "shift": [0.0], "peak_per_drive_top_over_lowest": [step_ratios[0]]}
    after = {"x": {"linear_resonance_hz": 2500.0, "precompression_n": precompression_after_n, "eta_s": 0.0},
             "gap_median": 0.05, "shift": [-0.05], "peak_per_drive_top_over_lowest": [step_ratios[1]]}
    step = {"effect": "contact_stiffness_and_preload", "parameters": ["linear_resonance_hz", "precompression_n"],
            "accepted": True, "share_of_chi2_removed": 0.8, "gap_before": 0.2, "gap_after": 0.05,
            "before": nominal, "after": after, "converged": True}
    final = dict(after, peak_per_drive_top_over_lowest=[model_ratio])
    return {"nominal": nominal, "steps": [step], "final": final, "eta_on_final": None,
            "converged": True, "unconverged_fits": [],
            "eta_probe": {"x": {"eta_s": 1e-6}, "peak_per_drive_top_over_lowest": [probe_ratio]},
            "contact_opening": {"static_overlap_m": 50e-9, "bead_amplitude_at_top_drive_peak_m": 110e-9},
            "measured": {"shift": [-0.06], "peak_per_drive_top_over_lowest": [measured_ratio]}}


def test_diagnosis_conclusion_states_the_datas_direction_and_values_far_from_the_file():
    """The conclusion names a fitted constant 10 times or more from the file's value with both
    values, a step that moves the amplitude dependence away from the data, and says which way
    the measured response per nm of drive goes: a gain (ratio > 1) is not called a loss."""
    from fitting.driven_diagnosis import FAR_FROM_FILE, conclusion

    # data whose response per nm grows with the drive (Lydon's two beads: 1.13); the step takes
    # the preload to 8.7e5 times the file's and the ratio from 1.00 to 0.76
    text = conclusion(_diagnosis_result(1.13, (1.0, 0.76), 2.6e6, 0.70, 0.78))
    assert "precompression_n = 2.6e+06 is 8.7e+05 times the file's 3" in text
    assert "linear_resonance_hz = 2500 is" not in text  # 0.83 times the file's: not named
    assert "from 1.00 to 0.76, away from the measured 1.13" in text
    assert "0.70 in the final model (it falls with the drive) against 1.13 measured (it grows)" in text
    assert "measured loss" not in text and "needs another mechanism" not in text
    assert "contacts open for part of each cycle, while the measured response per nm of drive grows" in text
    # a loss in the data (the single bead: 0.70) that contact damping pushes away from
    text = conclusion(_diagnosis_result(0.70, (1.0, 0.88), 3.0 / (FAR_FROM_FILE * 1.01), 0.88, 0.92))
    assert "is 0.099 times the file's 3" in text
    assert "away from the measured" not in text  # 1.00 -> 0.88 goes towards 0.70
    assert "(it falls)" in text and "needs another mechanism" in text
    # a preload just inside the factor is not named; an explained dependence says so
    text = conclusion(_diagnosis_result(0.90, (1.0, 0.91), 3.0 / (0.99 * FAR_FROM_FILE), 0.91, 0.95))
    assert "Far from the file" not in text
    assert text.splitlines()[-1].startswith("The amplitude dependence of the response is explained")
    # a preload fitted to zero is 0 times the file's, not of the other sign
    text = conclusion(_diagnosis_result(0.90, (1.0, 0.91), 0.0, 0.91, 0.95))
    assert "precompression_n = 0 is 0 times the file's 3" in text and "other sign" not in text


def test_diagnosis_conclusion_names_a_step_whose_fit_reached_no_optimum():
    """A named step on a fit without an optimum is named so (its share a lower bound, the naming
    standing), and the conclusion ends the steps with the unconverged fits; converged ones are
    not mentioned."""
    from fitting.driven_diagnosis import conclusion

    result = _diagnosis_result(0.90, (1.0, 0.91), 3.0, 0.91, 0.95)
    assert "converge" not in conclusion(result) and "optimum" not in conclusion(result)
    result["steps"][0]["converged"] = False
    result["converged"], result["unconverged_fits"] = False, ["the fit of contact_stiffness_and_preload"]
    text = conclusion(result)
    assert ("contact_stiffness_and_preload (linear_resonance_hz, precompression_n): named on a fit that reached no "
            "optimum within the step limit (judged at its last iterate: the share removed is a lower bound, the "
            "naming stands); it removes 80 %") in text
    assert "NOT CONVERGED: the fit of contact_stiffness_and_preload reached no optimum" in text
