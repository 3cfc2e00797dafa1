"""The rate and record terms of `hertzchain contact`: a Kuwabara-Kono damping time fitted per
material, a time shift between the force and approach records and a linear drift of the
approach record fitted per curve, recovered from curves this test writes with its own
arithmetic (analytic approach and speed, the force evaluated at the shifted time itself, no
interpolation; the drift added to the written approach; the law from the independent NumPy
implementation in `tests/helpers.py`), and their gradients against finite
differences."""

import csv
import json
import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from helpers import jackson_green_force

from fitting.contact_calibration import ContactGeometry, _Residuals, time_shifted
from hertzchain import contact
from hertzchain.cli import main

RADIUS_M, YOUNGS_PA, NU = 2e-3, 200e9, 0.3
PERIOD_S, DEPTH_M = 100e-6, 60e-6


def _approach(t):
    return DEPTH_M * np.sin(np.pi * np.clip(t, 0.0, None) / PERIOD_S)


def _write(path, sigma_pa, eta_s=0.0, shift_s=0.0, drift_m_s=0.0, noise_n=0.0):
    """A sphere on a flat loaded and unloaded along delta(t) = D sin(pi t / T) over 0.8 T; the force
    is the law at the approach a time `shift_s` later plus the Kuwabara-Kono force of `eta_s`,
    with white noise of `noise_n` (N, seeded); the approach written drifts by `drift_m_s` t."""
    time = np.linspace(0.0, 80e-6, 801)
    approach = _approach(time + shift_s)
    speed = np.where(time + shift_s > 0, DEPTH_M * np.pi / PERIOD_S * np.cos(np.pi * (time + shift_s) / PERIOD_S), 0)
    kappa = float(contact.kappa_sphere_flat(RADIUS_M, YOUNGS_PA, NU, YOUNGS_PA, NU))
    elastic = jackson_green_force(approach, np.maximum.accumulate(approach), kappa, RADIUS_M, sigma_pa, NU,
                             contact.JG_HARDNESS_RATIO)
    force = np.maximum(elastic + 1.5 * eta_s * kappa * np.sqrt(approach) * speed, 0.0)
    force = force + noise_n * np.random.default_rng(7).standard_normal(time.size)
    with open(path, "w", newline="") as handle:
        writer = csv.writer(handle)
        writer.writerow(["time_s", "approach_m", "force_n"])
        writer.writerows(zip(time, _approach(time) + drift_m_s * time, force))


def _run(tmp_path, *flags):
    out = tmp_path / "out"
    rc = main(["contact", str(tmp_path / "curve.csv"), "--youngs", "200GPa", "--poisson", "0.3",
               "--yield-stress", "500MPa", "--rate-constant", "0", "--geometry", "sphere-flat",
               "--radius", "2mm", "--out", str(out), *flags])
    assert rc == 0
    return json.loads((out / "contact.json").read_text())


@pytest.mark.slow  # default-suite time on 2 cores; the residuals' gradients against finite differences stay in the default suite
def test_damping_time_and_yield_stress_are_recovered(tmp_path):
    _write(tmp_path / "curve.csv", 700e6, eta_s=2e-6)
    report = _run(tmp_path, "--damping")
    fitted = report["materials"]["given"]["fitted"]
    # the command differentiates the approach averaged over 1 us (11 samples), the test uses the exact speed
    assert fitted["eta_s"] == pytest.approx(2e-6, rel=2e-3)
    assert fitted["yield_stress_pa"] == pytest.approx(700e6, rel=1e-3)
    assert report["curves"][0]["rms_over_peak_fitted"] < 1e-3
    # without the damping term the same curve is missed by more (and nothing compiled is kept)
    plain = _run(tmp_path, "--no-compile-cache")
    assert plain["curves"][0]["rms_over_peak_fitted"] > 10 * report["curves"][0]["rms_over_peak_fitted"]


@pytest.mark.slow  # 7 s; the shift's gradient is checked by default in the finite-difference test
def test_time_shift_is_recovered_with_an_honest_sigma(tmp_path):
    _write(tmp_path / "curve.csv", 700e6, shift_s=2.37e-6)
    report = _run(tmp_path, "--time-shift")
    curve = report["curves"][0]
    # linear interpolation between samples 0.1 us apart
    assert curve["time_shift_s"] == pytest.approx(2.37e-6, abs=2e-9)
    assert report["materials"]["given"]["fitted"]["yield_stress_pa"] == pytest.approx(700e6, rel=1e-3)
    assert curve["time_shift_stderr_s"] is not None and 0 < curve["time_shift_stderr_s"] < 1e-8
    # a bound below the true shift stops the fit there and reports no sigma
    report = _run(tmp_path, "--time-shift", "--max-shift", "1us")
    assert 0.99e-6 < report["curves"][0]["time_shift_s"] <= 1e-6
    assert report["curves"][0]["time_shift_stderr_s"] is None


def test_approach_drift_and_yield_stress_are_recovered(tmp_path):
    # 0.2 m/s over the 80 us record: 16 um on an approach of 60 um, the size fitted on the
    # Caltech curves (benchmarks/results/contact_burgoyne/approach_drift.md)
    _write(tmp_path / "curve.csv", 700e6, drift_m_s=0.2)
    report = _run(tmp_path, "--approach-drift")
    curve = report["curves"][0]
    assert curve["approach_drift_m_s"] == pytest.approx(0.2, rel=1e-6)
    assert curve["approach_drift_over_record_m"] == pytest.approx(0.2 * 80e-6, rel=1e-6)
    assert report["materials"]["given"]["fitted"]["yield_stress_pa"] == pytest.approx(700e6, rel=1e-6)
    assert curve["rms_over_peak_fitted"] < 1e-6
    # the law without the drift misses the same curve
    assert _run(tmp_path)["curves"][0]["rms_over_peak_fitted"] > 0.05


@pytest.mark.slow  # 8 s; the noiseless recovery above runs by default
def test_approach_drift_sigma_is_honest_under_noise(tmp_path):
    # with noise of 1 % of the peak (1.36 kN), the drift lies within 3 sigma, and sigma is no
    # bound of a noiseless fit: about what 801 samples of that noise allow (over 6 noise draws
    # the z-scores scattered by 0.66)
    _write(tmp_path / "curve.csv", 700e6, drift_m_s=0.2, noise_n=0.01 * 1.36e3)
    curve = _run(tmp_path, "--approach-drift")["curves"][0]
    assert abs(curve["approach_drift_m_s"] - 0.2) < 3 * curve["approach_drift_stderr_m_s"]
    assert 1e-4 < curve["approach_drift_stderr_m_s"] < 2e-2


def test_bad_max_shift_names_the_flag(tmp_path, capsys):
    _write(tmp_path / "curve.csv", 700e6)
    rc = main(["contact", str(tmp_path / "curve.csv"), "--material", "steel_440C", "--radius", "2mm",
               "--time-shift", "--max-shift", "soon", "--out", str(tmp_path / "out")])
    assert rc == 2
    assert "--max-shift" in capsys.readouterr().err
    assert not (tmp_path / "out" / "contact.json").exists()


def test_time_columns_that_do_not_increase_or_are_not_uniform_are_refused(tmp_path, capsys):
    _write(tmp_path / "curve.csv", 700e6)
    rows = (tmp_path / "curve.csv").read_text().splitlines()
    # two rows swapped: the time goes back
    (tmp_path / "swapped.csv").write_text("\n".join(rows[:5] + [rows[6], rows[5]] + rows[7:]) + "\n")
    rc = main(["contact", str(tmp_path / "swapped.csv"), "--material", "steel_440C", "--radius", "2mm",
               "--out", str(tmp_path / "out")])
    assert rc == 2 and "the time column must increase" in capsys.readouterr().err
    # every other sample left out of the first half: the terms read on a uniform grid refuse
    # it, naming what to do (the law alone needs no grid)
    kept = [rows[0]] + [row for k, row in enumerate(rows[1:]) if k > 400 or k % 2 == 0]
    (tmp_path / "uneven.csv").write_text("\n".join(kept) + "\n")
    rc = main(["contact", str(tmp_path / "uneven.csv"), "--material", "steel_440C", "--radius", "2mm",
               "--approach-drift", "--out", str(tmp_path / "out")])
    said = capsys.readouterr().err
    assert rc == 2 and "not uniformly sampled" in said and "resample it" in said
    assert not (tmp_path / "out" / "contact.json").exists()


def test_time_shifted_reads_between_samples_and_beyond_the_ends():
    values = np.array([1.0, 2.0, 4.0, 8.0])
    np.testing.assert_allclose(np.asarray(time_shifted(values, 0.5, 0.25)), [1.5, 3.0, 6.0, 10.0])
    np.testing.assert_allclose(np.asarray(time_shifted(values, 0.5, -0.75)), [1.0, 1.0, 1.5, 3.0])


def test_residual_gradients_in_damping_shift_drift_and_hardness_ratio_equal_finite_differences():
    time = np.linspace(0.0, 80e-6, 401)
    step = float(time[1] - time[0])
    approach = _approach(time)
    speed = np.gradient(approach, step)
    kappa = float(contact.kappa_sphere_flat(RADIUS_M, YOUNGS_PA, NU, YOUNGS_PA, NU))
    force = 1e3 * np.sin(np.pi * time / PERIOD_S) ** 2  # any measured force: the residuals' gradients do not use it
    geometry = ContactGeometry("sphere-flat", RADIUS_M)
    problem = _Residuals([(approach, speed, step, force, float(force.max()), 1e-3)], kappa, geometry, NU, 13e-6)
    # off the sample grid (a shift of 0.3 steps), with the damping on, sigma_Y in the plastic range,
    # the hardness ratio away from its default, an approach drift of 0.1 m/s
    x = np.array([math.log(600e6), 0.0, 1.5e-6, math.log(3.3), 0.3 * step, 0.1])  # shift: tanh 3e-4 % less
    columns = [0, 2, 3, 4, 5]
    r, jac = problem.linearize(x, columns)
    assert np.all(np.isfinite(jac)) and np.all(np.abs(jac).max(axis=0) > 0)
    for column, h in enumerate((1e-6, 1e-9, 1e-6, 1e-10, 1e-5)):
        index = columns[column]
        up, down = x.copy(), x.copy()
        up[index] += h
        down[index] -= h
        numeric = (problem.residuals(up) - problem.residuals(down)) / (2 * h)
        np.testing.assert_allclose(jac[:, column], numeric, rtol=1e-4, atol=1e-6 * np.abs(numeric).max())
    # jax's derivative of the interpolation in the shift: the slope of the segment it reads
    derivative = jax.grad(lambda s: jnp.sum(time_shifted(jnp.asarray(approach), step, s)))(0.3 * step)
    left = np.arange(approach.size).clip(0, approach.size - 2)
    assert float(derivative) == pytest.approx(float(np.sum((approach[left + 1] - approach[left]) / step)), rel=1e-9)


DATA = __import__("pathlib").Path(__file__).resolve().parents[2] / "shared/data/real/burgoyne-2014/ExperimentalData"


@pytest.mark.slow
@pytest.mark.skipif(not DATA.is_dir(), reason="Burgoyne & Daraio data folder absent")
def test_damping_takes_the_measured_force_lead_on_302_curves(tmp_path):
    """Two measured 302 curves: a damping time fitted with sigma_Y lowers the misfit of each, and
    with it fitted, a time shift of the records is no longer needed (the finding of
    benchmarks/results/contact_burgoyne/rate_terms.md on all four 302 curves). Slow (59 s under load):
    `python -m pytest -m slow tests/test_contact_rate_terms.py`."""
    files = [str(DATA / "s302_10.mat"), str(DATA / "s302_15.mat")]
    reports = {}
    for label, flags in (("alone", []), ("damping", ["--damping"]), ("both", ["--damping", "--time-shift"])):
        assert main(["contact", *files, "--material", "steel_302", "--radius", "3.175mm",
                     "--out", str(tmp_path / label), *flags]) == 0
        reports[label] = json.loads((tmp_path / label / "contact.json").read_text())
    assert reports["damping"]["materials"]["steel_302"]["fitted"]["eta_s"] > 0
    for alone, damped, both in zip(*(reports[k]["curves"] for k in ("alone", "damping", "both"))):
        assert damped["rms_over_peak_fitted"] < alone["rms_over_peak_fitted"]
        # consistent with no shift at 3 sigma
        assert abs(both["time_shift_s"]) < 3 * both["time_shift_stderr_s"]


@pytest.mark.slow
@pytest.mark.skipif(not DATA.is_dir(), reason="Burgoyne & Daraio data folder absent")
def test_the_fitted_drifts_of_two_processings_of_one_shot_differ_as_their_approaches_do(tmp_path):
    """`al_12` and `force_alum` are two processings of one aluminium shot: their forces agree once
    aligned, their approaches differ by a drift (benchmarks/results/contact_burgoyne/
    approach_drift.md). Fitted together with the damping and a drift each, both are within 8 %
    of their peak, and the difference of the fitted drifts is the one their approach records
    show. Slow (about a minute): `python -m pytest -m slow tests/test_contact_rate_terms.py`."""
    from benchmarks.contact_approach_drift import processing_drift
    from fitting.contact_calibration import read_curve
    from hertzchain.materials import material

    files = [DATA / "al_12.mat", DATA / "force_alum.mat"]
    assert main(["contact", *map(str, files), "--material", "Al_2017", "--radius", "3.175mm", "--damping",
                 "--approach-drift", "--out", str(tmp_path / "out")]) == 0
    report = json.loads((tmp_path / "out" / "contact.json").read_text())
    first, second = report["curves"]
    assert max(first["rms_over_peak_fitted"], second["rms_over_peak_fitted"]) < 0.08
    fitted = second["approach_drift_m_s"] - first["approach_drift_m_s"]
    sigma = math.hypot(first["approach_drift_stderr_m_s"], second["approach_drift_stderr_m_s"])
    measured = processing_drift(*(read_curve(f, material("Al_2017")) for f in files))[0]
    assert abs(fitted - measured) < 3 * sigma
