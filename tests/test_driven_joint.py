"""Joint driven fits: the vector of shared and per-run constants, its residuals' Jacobian against
finite differences, and the recovery of two runs' constants from synthetic bending, tongue and
loop data made by the model at known constants."""

import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest

from fitting.driven.experiment import DrivenExperiment, DrivenExperimentError, Measurement
from fitting.driven.joint import JointModel, fit_joint, joint_parameters
from hertzchain.driven import DrivenChain, lockin_grid
from hertzchain.driven.measurements import Bending, Loop, Tongue
from hertzchain.driven.sweeper_files import LockinSweep
from hertzchain.driven.thresholds import period_doubling_onsets

MODEL = {"ramp_periods": 25, "hold_periods": 35, "window_periods": 4, "steps_per_period": 48}
KAPPA, GAMMA = 3.8e10, 1750.0


def truth(precompression_n):
    return DrivenChain([0.028], [KAPPA, KAPPA], precompression_n, GAMMA)


def synthetic_experiment(fit_options=None, bending_precompression=0.138, tongue_precompression=0.09,
                         tongue_scale=1.0, tongue_uncertainty=0.41):
    """A bending run (F0 0.138 N) and a tongue and loop run (its own F0, the drive's true
    amplitude `tongue_scale` x nominal), all made by the model at known constants."""
    f = np.arange(3500.0, 4201.0, 10.0)
    drives = np.array([0.7e-9, 2.5e-9, 4.5e-9])  # below the jump on the low-frequency flank
    rms = np.asarray(lockin_grid(truth(bending_precompression), f, drives, harmonics=(1.0,), steps_per_period=48).rms[0])
    bending = Bending("bend", LockinSweep(f, drives, rms, 6.8e-7, 0.02, "synthetic"))
    tongue_f = np.array([7000.0, 7100.0, 7200.0])
    onsets = period_doubling_onsets(truth(tongue_precompression), np.r_[tongue_f, 6900.0], lowest_amplitude_m=1e-9,
                                    highest_amplitude_m=200e-9).amplitude_m / tongue_scale
    amplitudes = np.linspace(1e-9, 100e-9, 20)
    tongue = Tongue("tongue", tongue_f, amplitudes, np.ones((20, 3)), np.zeros((20, 3)), onsets[:3], 2e-9, 7.5e-7, "s")
    loop = Loop("tongue", 6900.0, np.r_[amplitudes, amplitudes[::-1]], np.ones(40), np.zeros(40), 19, onsets[3],
                np.nan, np.nan, 2e-9, 7.5e-7, "s")
    measurements = (Measurement("bending", "bend", bending, 6.8e-7, 0.41, np.ones(f.size, bool), ("b",)),
                    Measurement("tongue", "tongue", tongue, 7.5e-7, tongue_uncertainty, None, ("t",)),
                    Measurement("loop", "tongue", loop, 7.5e-7, tongue_uncertainty, None, ("l",)))
    return DrivenExperiment(Path("synthetic.toml"), "synthetic", np.array([0.028]), np.array([1.4e10, 1.4e10]), 4.5,
                            6.8e-7, 0.41, 1, "velocity", None, None, MODEL, measurements, fit_options or {})


def test_shared_and_per_run_constants_and_their_refusals():
    chain = truth(0.138)
    bare = DrivenExperiment(Path("e.toml"), "e", np.array([0.028]), np.array([1e10, 1e10]), 1.0, 1e-7, 0.4, 1,
                            "velocity", None, None, MODEL,
                            (Measurement("bending", "a", None, 1e-7, 0.4, None, ()),
                             Measurement("tongue", "b", None, 1e-7, 0.4, None, ())), {})
    labels = [p.label for p in joint_parameters(bare, chain)]
    assert labels == ["contact_kappa_n_m1p5", "damping_rate_per_s", "precompression_n[a]", "precompression_n[b]",
                      "drive_scale[a]", "drive_scale[b]"]
    wrong = dataclasses.replace(bare, fit_options={"shared": ["kappa"]})
    with pytest.raises(DrivenExperimentError, match="'kappa' is not a fittable constant; valid: bead_mass_kg, "
                       "contact_kappa_n_m1p5, precompression_n, damping_rate_per_s, drive_scale"):
        joint_parameters(wrong, chain)
    both = dataclasses.replace(bare, fit_options={"shared": ["precompression_n"], "per_run": ["precompression_n"]})
    with pytest.raises(DrivenExperimentError, match="precompression_n named both shared and per run"):
        joint_parameters(both, chain)


@pytest.mark.slow
def test_joint_jacobian_matches_finite_differences():
    experiment = synthetic_experiment()
    chain = truth(0.138)
    parameters = joint_parameters(experiment, chain)
    model = JointModel(experiment, chain, parameters, {"bend": 1.0, "tongue": 1.0}, 0.3)
    x = np.array([0.02, -0.05, 0.01, math.log(0.09 / 0.138), 0.03, -0.02])
    columns = list(range(x.size))
    _, jac = model.linearize(x, columns)
    h = 1e-4  # the thresholds' roots are polished to 1e-6 relative: steps well above that
    for k in columns:
        step = np.zeros(x.size)
        step[k] = h
        difference = (model.residuals(x + step) - model.residuals(x - step)) / (2 * h)
        scale = np.abs(jac[:, k]).max()
        assert np.max(np.abs(jac[:, k] - difference)) < 5e-4 * scale, parameters[k].label


@pytest.mark.slow
def test_joint_fit_recovers_two_runs_constants():
    """Two runs, their own precompression (0.138 / 0.09 N) and drive (1 / 0.8 x nominal), one
    bead and damping: the fit, from the bending run's own fit, recovers every constant (the
    tongue run's calibration without a prior: a prior pulls its scale towards 1, by design)."""
    experiment = synthetic_experiment(tongue_scale=0.8, tongue_uncertainty=0.0)
    fit = fit_joint(experiment, max_steps=40, progress=False)
    assert fit.converged
    model = fit.model
    chains = {run.run: model.run_chain(run, fit.x) for run in model.runs}
    assert float(chains["bend"].precompression_n) == pytest.approx(0.138, rel=0.02)
    assert float(chains["tongue"].precompression_n) == pytest.approx(0.09, rel=0.03)
    assert float(chains["tongue"].contact_kappa_n_m1p5[0]) == pytest.approx(KAPPA, rel=0.03)
    scales = {run.run: model.run_scale(run, fit.x) for run in model.runs}
    assert scales["tongue"] == pytest.approx(0.8, rel=0.03)
