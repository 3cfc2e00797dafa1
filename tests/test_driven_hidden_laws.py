"""The driven diagnosis on bending data made by a second code path with a law hidden: a NumPy RK4
of one bead between a driven face and a wall (`tests/helpers.driven_bead_lockin`), its contacts
a power law of another exponent than Hertz's, Hertz in series with a spring, or Hertz with
micro-slip friction at the bead's supports (an Iwan element). Fitted on the lower drive levels
at the stated precompression, the protocol (`fitting.driven.diagnosis.diagnose_experiment`,
which runs `fitting.driven.candidates.diagnose_laws`) must name the hidden law by what it
predicts for the top level, and recover its constant.

The setups: a 28 g bead at a stated 0.5 N whose contacts rest at 136 nm, driven by 3 to 18 nm
(the bead swings by up to about half its static overlap, so the laws differ in how the
resonance bends and the peak grows), 17 frequencies about the linear resonance, four drive
levels, the top one held out."""

import math
from pathlib import Path

import numpy as np
import pytest
from helpers import driven_bead_lockin, iwan_support, rerun_at_the_default_xla_level

from fitting.driven.candidates import CANDIDATES, SLOW_CANDIDATES
from fitting.driven.diagnosis import diagnose_experiment
from fitting.driven.experiment import DrivenExperiment
from hertzchain.driven.sweeper_files import LockinSweep

MASS, F0, OVERLAP, GAMMA = 0.028, 0.5, 1.36e-7, 2500.0
DRIVES = np.array([3e-9, 9e-9, 14e-9, 18e-9])
MODEL = {"ramp_periods": 25, "hold_periods": 35, "window_periods": 4, "steps_per_period": 48}
HERTZ_KAPPA = F0 / OVERLAP**1.5


def _experiment(contact_force, stiffness_n_m, support=None, drives_m=DRIVES):
    """A bending-only experiment of the hidden law: 17 frequencies from 0.9 to 1.06 of the linear
    resonance sqrt(stiffness_n_m / m) (`stiffness_n_m`: both contacts' and the support's), the
    file's nominal Hertz constant the setup's."""
    f_lin = math.sqrt(stiffness_n_m / MASS) / (2 * math.pi)
    f = np.round(f_lin * np.linspace(0.9, 1.06, 17), 1)
    velocity = driven_bead_lockin(f, drives_m, mass_kg=MASS, contact_force=contact_force, static_overlap_m=OVERLAP,
                                  damping_rate_per_s=GAMMA, support=support, **MODEL)
    sweep = LockinSweep(f, drives_m, velocity, 6.8e-7, 0.02, "numpy")
    return DrivenExperiment(Path("hidden.toml"), "hidden", np.array([MASS]), np.array([HERTZ_KAPPA, HERTZ_KAPPA]),
                            F0, 6.8e-7, 0.41, 1, "velocity", sweep, np.ones(f.size, bool), MODEL)


def _named(*names):
    known = {c.name: c for c in CANDIDATES + SLOW_CANDIDATES}
    return [known["hertz_viscous"]] + [known[n] for n in names]


def _diagnose(experiment, candidates, max_steps):
    return diagnose_experiment(experiment, candidates, held_out_levels=1, level_stride=1, max_steps=max_steps,
                               progress=False)


def test_numpy_bead_is_the_linear_resonance_at_small_drive():
    """The second code path against the closed form: a weak drive's response at the linearised
    resonance sqrt(2 k / m) (k = 1.5 F0 / delta0 of Hertz) is a*k/(m*gamma) (RMS: / sqrt 2), and
    an Iwan support's stiffness K adds to 2 k while nothing slips."""
    k = 1.5 * F0 / OVERLAP
    for support_k in (0.0, 0.5 * k):
        f_lin = math.sqrt((2 * k + support_k) / MASS) / (2 * math.pi)
        support = None if support_k == 0 else iwan_support(support_k, 1e-6)  # slips beyond 1 um: never here
        rms = driven_bead_lockin([f_lin], [1e-11], mass_kg=MASS, contact_force=lambda d: HERTZ_KAPPA * np.maximum(
            d, 0.0) ** 1.5, static_overlap_m=OVERLAP, damping_rate_per_s=GAMMA, support=support, **MODEL)[0, 0]
        assert rms == pytest.approx(1e-11 * k / (MASS * GAMMA) / math.sqrt(2), rel=2e-3)


def test_protocol_names_a_hidden_contact_exponent():
    """Hidden: F = c delta^2.5 (n = 2.5 instead of Hertz's 1.5): a pair of such contacts hardens
    (the resonance bends up 2 % at the top drive), where Hertz's softens. The base, fitted on the
    three lower levels, misses the held-out top one by 13 % of its peak (measured); the power-law
    candidate predicts it within 1 %, is named, and finds n within 2 % (measured: 2.486).
    Candidates: base, exponent."""
    exponent = 2.5
    c = F0 / OVERLAP**exponent
    experiment = _experiment(lambda d: c * np.maximum(d, 0.0) ** exponent, 2 * exponent * F0 / OVERLAP)
    result = _diagnose(experiment, _named("contact_exponent"), max_steps=12)
    by_name = {e["name"]: e for e in result["candidates"]}
    assert result["verdict"]["named"] == ["contact_exponent"]
    assert by_name["hertz_viscous"]["bending"]["held_out_misfit_median"] > 0.05
    assert by_name["contact_exponent"]["bending"]["held_out_misfit_median"] < 0.01
    fitted = np.asarray(by_name["contact_exponent"]["constants"]["contact_law.exponent"]).ravel()[0]
    assert fitted == pytest.approx(exponent, rel=0.02)
    assert result["converged"]
    assert "Named: contact_exponent" in result["conclusion"]


def _series_force(compliance_m_n):
    """Hertz in series with a spring of compliance C: F with d + C kappa d^1.5 = delta, d by
    Newton from d = delta (h(d) convex and increasing: monotone from the right)."""
    def force(delta):
        delta = np.maximum(delta, 0.0)
        d = delta.copy()
        for _ in range(40):
            h = d + compliance_m_n * HERTZ_SERIES * d**1.5 - delta
            d = np.maximum(d - h / (1 + 1.5 * compliance_m_n * HERTZ_SERIES * np.sqrt(np.maximum(d, 1e-30))), 0.0)
        return HERTZ_SERIES * d**1.5
    return force


# The series setup: the spring's compliance, and the Hertz constant that puts the contact's
# static overlap at OVERLAP with the spring's share C F0 (20 nm of 136) in it.
SERIES_COMPLIANCE = 4e-8
HERTZ_SERIES = F0 / (OVERLAP - SERIES_COMPLIANCE * F0) ** 1.5


@pytest.mark.slow  # ~40 s of CPU; test_protocol_names_a_hidden_contact_exponent runs the protocol by default
def test_protocol_names_a_hidden_series_compliance():
    """Hidden: each contact Hertz in series with a spring of C = 4e-8 m/N, driven three times
    harder than the exponent's setup (9 to 54 nm: the contacts open at the top). At the stated
    preload the series contact's static overlap is smaller than Hertz's at the same stiffness, so
    it opens sooner and the resonance bends more (data -6.0 %, the base -5.0 %). The base misses
    the held-out top level by 5 % of its peak (measured), the series candidate by under 1 %, is
    named best and finds C within 15 % (measured 4.26e-8). Candidates: base, series compliance,
    velocity-squared loss (a loss that grows with amplitude)."""
    k_hertz = 1.5 * F0 / (OVERLAP - SERIES_COMPLIANCE * F0)
    k = 1 / (1 / k_hertz + SERIES_COMPLIANCE)
    experiment = _experiment(_series_force(SERIES_COMPLIANCE), 2 * k, drives_m=3 * DRIVES)
    result = _diagnose(experiment, _named("series_compliance", "velocity_squared_loss"), max_steps=12)
    by_name = {e["name"]: e for e in result["candidates"]}
    assert result["verdict"]["best"] == "series_compliance"
    assert by_name["hertz_viscous"]["bending"]["held_out_misfit_median"] > 0.03
    assert by_name["series_compliance"]["bending"]["held_out_misfit_median"] < 0.01
    fitted = np.asarray(by_name["series_compliance"]["constants"]["contact_law.compliance_m_n"]).ravel()[0]
    assert fitted == pytest.approx(SERIES_COMPLIANCE, rel=0.15)
@pytest.mark.slow  # minutes: the sliders run the JAX kernel; the default suite's protocol check is the exponent's
def test_protocol_names_hidden_micro_slip_at_the_supports():
    """Hidden: Hertz contacts and an Iwan support, K = 20 % of the contacts' 2 k, full slip at
    40 nm (the top drive's swing slips most of it): a loss that grows with amplitude below full
    slip and a softening (data: peak per nm top/lowest 0.77, resonance -4.0 %). The base misses
    the held-out top level by 12 % of its peak, the micro-slip candidate by 3.8 % (measured); it
    is named and finds the slip displacement within 25 % (measured 3.35e-8 m: the RK4 bead's
    sliders move after each step, the library's within it). Candidates: base, micro-slip."""
    k = 1.5 * F0 / OVERLAP
    support_k, slip = 0.4 * k, 4e-8
    experiment = _experiment(lambda d: HERTZ_KAPPA * np.maximum(d, 0.0) ** 1.5, 2 * k + support_k,
                             iwan_support(support_k, slip))
    result = _diagnose(experiment, _named("micro_slip_supports"), max_steps=12)
    by_name = {e["name"]: e for e in result["candidates"]}
    assert result["verdict"]["named"] == ["micro_slip_supports"]
    fitted = np.asarray(by_name["micro_slip_supports"]["constants"]["support_friction.slip_displacement_m"]).ravel()[0]
    assert fitted == pytest.approx(slip, rel=0.25)


@pytest.mark.slow  # minutes: the sliders' thresholds and bending under forward derivatives, stepped sweeps; the
# default suite checks the micro-slip thresholds a joint fit uses in
# test_driven_candidates.test_micro_slip_candidate_predicts_the_floquet_continuations_thresholds
def test_joint_fit_recovers_hidden_micro_slip_from_the_bending_and_the_tongue():
    """Hidden: the bead at 0.2 N (contacts at rest at 73.8 nm), damping 1500 /s, an Iwan support
    of K = 40 % of the contacts' k, full slip at 40 nm. The bending run (3 drive levels, 2 to
    9 nm) by the NumPy RK4 bead; the tongue run (5750, 5900, 6050 Hz, 10 to 90 nm in 4 nm steps)
    and its loop (5800 Hz, up and down) by stepping the lab's sweeps in time (`emulate_loop`:
    the f/2 rule on `lockin_schedule`), its fundamental below onset from the same runs: no
    Floquet model in the data. `fit_candidate_jointly` of the micro-slip candidate, started at
    K = 2e6 N/m and 100 nm, fits both through the tongue's Floquet thresholds: its tip matches
    the stepped one (53.8 against 54 nm at 5750 Hz), the loop it predicts (not fitted) the
    stepped loop's (54.5 against 54 nm), and it finds K, the Hertz constant and the damping
    within 15 %. The slip displacement stays loose (88 nm, measured): the thresholds, weighed at
    the 4 nm step's quantisation (2 %), outweigh the bending (weighted down for its correlated
    residuals), and the stepped onsets lie up to a step above the Floquet thresholds (62 nm
    against 58.0 nm at 5900 Hz), which the fit meets by giving up the bending's loss growth
    (bending misfit 4.3 %, peak per nm top/lowest 0.87 against 0.77). At XLA's default
    optimisation level, which these numbers were measured at (at the suite's level 0 the fit
    ends elsewhere on the loose slip displacement, its predicted loop onset 57.2 nm)."""
    if rerun_at_the_default_xla_level(__file__,
                                      "test_joint_fit_recovers_hidden_micro_slip_from_the_bending_and_the_tongue"):
        return
    from fitting.driven.candidates import fit_candidate_jointly
    from fitting.driven.experiment import Measurement
    from hertzchain import laws
    from hertzchain.driven import DrivenChain
    from hertzchain.driven.measurements import Bending, Loop, Tongue
    from hertzchain.driven.thresholds import emulate_loop

    force, gamma = 0.2, 1500.0
    overlap = (force / HERTZ_KAPPA) ** (2 / 3)
    k = 1.5 * force / overlap
    support_k, slip = 0.4 * k, 4e-8
    f_lin = math.sqrt((2 * k + support_k) / MASS) / (2 * math.pi)
    f = np.round(f_lin * np.linspace(0.9, 1.06, 17), 1)
    drives = np.array([2e-9, 5e-9, 9e-9])
    velocity = driven_bead_lockin(f, drives, mass_kg=MASS, contact_force=lambda d: HERTZ_KAPPA * np.maximum(d, 0.0)
                                  ** 1.5, static_overlap_m=overlap, damping_rate_per_s=gamma,
                                  support=iwan_support(support_k, slip), **MODEL)
    sensor = 0.02
    bending = Bending("bend", LockinSweep(f, drives, velocity, 6.8e-7, sensor, "numpy"))
    hidden = DrivenChain([MASS], [HERTZ_KAPPA, HERTZ_KAPPA], force, gamma,
                         support_friction=laws.IwanSupport(support_k, slip))
    up = np.arange(10e-9, 91e-9, 4e-9)
    tongue_hz = np.array([5750.0, 5900.0, 6050.0])
    sweeps = [emulate_loop(hidden, hz, up) for hz in tongue_hz]
    onsets = np.array([s.onset_up_m for s in sweeps])
    assert np.isfinite(onsets[:2]).all() and np.isnan(onsets[2])  # measured 54, 62 nm, none up to 90 nm
    fundamental = np.stack([s.fundamental_m_s for s in sweeps], axis=1) / sensor
    tongue = Tongue("tongue", tongue_hz, up, fundamental, np.zeros_like(fundamental), onsets, 4e-9, 7.5e-7, "stepped")
    both = np.r_[up, up[-2::-1]]
    run = emulate_loop(hidden, 5800.0, both)
    loop = Loop("tongue", 5800.0, both, run.fundamental_m_s / sensor, run.subharmonic_m_s / sensor, up.size - 1,
                run.onset_up_m, run.last_down_m, run.gone_down_m, 4e-9, 7.5e-7, "stepped")
    measurements = (Measurement("bending", "bend", bending, 6.8e-7, 0.41, np.ones(f.size, bool), ("b",)),
                    Measurement("tongue", "tongue", tongue, 7.5e-7, 0.41, None, ("t",)),
                    Measurement("loop", "tongue", loop, 7.5e-7, 0.41, None, ("l",)))
    experiment = DrivenExperiment(Path("hidden.toml"), "hidden", np.array([MASS]), np.array([HERTZ_KAPPA, HERTZ_KAPPA]),
                                  force, 6.8e-7, 0.41, 1, "velocity", None, None, MODEL, measurements, {})
    fit = fit_candidate_jointly(experiment, _named("micro_slip_supports")[1], max_steps=12)
    constants = fit["constants"]
    assert fit["tongue"]["model_tip_hz"] == 5750.0
    assert abs(fit["tongue"]["amplitude_gap_log"]) < 0.02  # measured -0.004: 53.8 nm against 54 nm
    assert fit["loop"]["model_onset_up_m"] == pytest.approx(run.onset_up_m, rel=0.03)  # measured 54.5 against 54 nm
    assert fit["tongue_fundamental"]["misfit_median"] < 0.005  # measured 0.16 %
    assert fit["bending"]["misfit_median"] < 0.05  # measured 4.3 %
    assert np.ravel(constants["support_friction.stiffness_n_m"])[0] == pytest.approx(support_k, rel=0.2)  # +15 %
    assert np.ravel(constants["contact_kappa_n_m1p5"])[0] == pytest.approx(HERTZ_KAPPA, rel=0.12)  # measured -9 %
    assert np.ravel(constants["damping_rate_per_s"])[0] == pytest.approx(gamma, rel=0.05)  # measured +2.6 %
