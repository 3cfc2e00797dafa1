"""Candidate laws for a driven experiment, each fitted on its bending run and judged on what it
predicts for the measurements it was not fitted on.

A **candidate** is the base chain (Hertz contacts, viscous drag on the bead) with one law
added or replaced (`DrivenCandidate`: a name, the law it adds, the paths of the chain's fields
it frees, in `fitting.driven.joint`'s addressing). Every candidate is held to the apparatus as
the lab describes it:

- the **precompression is fixed** at the file's stated value (Lydon: 4.5 N) in every run,
  unless the candidate frees it (`precompression_n` in `free`): then the rest of the stated
  force is carried by a load path in parallel with the bead (the fixture), which a
  prescribed face motion does not feel;
- each run's **drive scale** keeps its calibration prior ($\\log s \\sim N(0, \\log(1+u)^2)$,
  `fitting.driven.joint`); a run that is only predicted is predicted at its calibration
  (s = 1), and the report gives the scale that would have matched it.

Protocol (`diagnose_laws`): each candidate is fitted (`fitting.fit.least_squares`) on the
experiment's first bending measurement alone, its free fields plus the contacts' Hertz
constant, the bead's viscous damping and the bending run's drive scale, the Hertz constant
started where the chain's linear resonance is the lowest drive's measured peak. Its constants
then **predict** the tongue (its tip: the lowest period-doubling threshold and its frequency,
by `hertzchain.driven.thresholds`) and the loop's onset going up. Each measurement is scored
against `TARGETS`; a candidate is **named** a mechanism only when it meets a target on a
measurement it was not fitted on that the base does not meet, or moves a predicted
measurement's gap (`log(model / measured)`) at least `NAMED_GAIN` closer than the base. The
bending run's highest drive levels can be held out too (`held_out_levels`): fitted on the
lower ones, the candidate predicts them (their median misfit a measurement not fitted on).

`fit_candidate_jointly` fits a candidate on the bending and the tongue together (the tongue's
thresholds and its fundamental below every onset, which measures that run's true drive) and
predicts the loop; the verdict names no candidate for a measurement it was fitted on.

`CANDIDATES` run by default; `SLOW_CANDIDATES` (micro-slip at the supports alone, with
Segalman's power-law spread of its slip, and in pairs with a free static force, a
velocity-squared loss, a Rayleigh piezo or an actuator mode; their
sliders are state of the period map, `hertzchain.driven.floquet`, and their thresholds come from
the same continuation as every other candidate's) only when named; `FREE_PRELOAD_CANDIDATES` for
the joint fit.
"""

from __future__ import annotations

import dataclasses
import math
import time

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from hertzchain import laws
from hertzchain.driven import ActuatorMode, DrivenChain, RayleighStroke
from hertzchain.driven.linear import normal_modes
from hertzchain.driven.measurements import tongue_fundamental
from hertzchain.progress import Progress

from ..fit import least_squares
from ..uncertainty import ar1_correlation, ar1_inflation
from .joint import DRIVE_SCALE, JointModel, JointParameter, _leaf, _threshold_data
from .lockin_fit import NOMINAL_SCALE
from .report import bending

# The targets on the single bead: bending misfit (median over drive levels, fraction of
# each curve's peak), resonance shift (points), peak velocity per nm top/lowest, and the
# predicted tongue tip (amplitude, frequency) and loop onset going up (relative).
TARGETS = {"bending_misfit_median": 0.03, "shift_points": 0.005, "peak_ratio": 0.07,
           "tongue_tip_amplitude": 0.25, "tongue_tip_frequency": 0.02, "loop_onset_up": 0.25,
           "held_out_bending_misfit": 0.03}
PREDICTED = ("tongue_tip_amplitude", "tongue_tip_frequency", "loop_onset_up", "held_out_bending_misfit")
# The measurement each predicted target is of (a candidate fitted on it does not predict it).
MEASURED_BY = {"tongue_tip_amplitude": "tongue", "tongue_tip_frequency": "tongue", "loop_onset_up": "loop",
               "held_out_bending_misfit": "held-out bending levels"}
# A candidate is named when a predicted gap |log(model/measured)| shrinks by this much on the base's.
NAMED_GAIN = math.log(1.25)
# Where the base predicts nothing (no period doubling), a candidate improves on it when its
# prediction is within this (log units: a factor 2) of the data.
BASE_SILENT_WITHIN = math.log(2.0)
# Every factor stays within this of its start ...
FACTOR_LIMIT = 100.0
# ... the contacts' Hertz constant within this (the start puts the resonance on the data's; a
# trial step far outside stiffens the chain past what the time step resolves).
KAPPA_LIMITS = (0.1, 10.0)


@dataclasses.dataclass(frozen=True)
class DrivenCandidate:
    """One candidate: `name`, `mechanism` (plain words), `add(chain) -> chain` (the base chain
    with the law in), `free` (paths of the chain's fields it frees, besides the base's),
    `factor_limits` ({path: (lowest, highest)} factors on its start where the law's range is
    narrower than `FACTOR_LIMIT`)."""

    name: str
    mechanism: str
    add: object
    free: tuple = ()
    factor_limits: dict = dataclasses.field(default_factory=dict)


def _replace(chain: DrivenChain, **changes) -> DrivenChain:
    fields = {"contact_law": chain.contact_law, "dissipation": chain.dissipation,
              "support_friction": chain.support_friction, "drive_stroke": chain.drive_stroke}
    fields.update(changes)
    return DrivenChain(chain.bead_mass_kg, chain.contact_kappa_n_m1p5, chain.precompression_n,
                       chain.damping_rate_per_s, **fields)


CANDIDATES = (
    DrivenCandidate("hertz_viscous", "the base: Hertz contacts, viscous drag", lambda c: c),
    DrivenCandidate("contact_exponent", "a power-law contact F = c delta^n (n free)",
                    lambda c: _replace(c, contact_law=laws.PowerLaw(1.5, 1e-6)), ("contact_law.exponent",),
                    {"contact_law.exponent": (1.0 / 1.5, 3.0 / 1.5)}),  # n in [1, 3]
    DrivenCandidate("series_compliance", "a linear compliance in series with each contact (piezo cap, fixture)",
                    lambda c: _replace(c, contact_law=laws.SeriesCompliance(laws.Hertz(), 2e-8)),
                    ("contact_law.compliance_m_n",)),
    DrivenCandidate("rough_contact", "a Greenwood-Williamson asperity layer in series (roughness, touch force)",
                    lambda c: _replace(c, contact_law=laws.RoughContact(laws.Hertz(), 3e-8, 0.5)),
                    ("contact_law.roughness_m", "contact_law.touch_force_n")),
    DrivenCandidate("velocity_squared_loss", "a contact loss c |v| v (Vergara) besides the viscous drag",
                    lambda c: _replace(c, dissipation=(laws.VelocitySquared(3000.0),)),
                    ("dissipation.0.c_n_s2_m2",)),
    DrivenCandidate("rayleigh_piezo", "a piezo whose stroke grows with its amplitude (Rayleigh law)",
                    lambda c: _replace(c, drive_stroke=RayleighStroke(1e6)), ("drive_stroke.rayleigh_per_m",)),
)
# Candidates whose contacts' static force is free (`fit_candidate_jointly`: fitted on the
# bending and the tongue together, one static force for both runs): the rest of the stated
# 4.5 N carried by a load path in parallel with the bead (the fixture), which a prescribed
# face motion does not feel.
FREE_PRELOAD_START_N = 0.15  # near the bending run fitted alone (single_bead_joint/fit.json#start.bending_alone)
FREE_PRELOAD_CANDIDATES = (
    DrivenCandidate("free_preload", "Hertz contacts and viscous drag, the contacts' static force free",
                    lambda c: c, ("precompression_n",)),
    DrivenCandidate("free_preload_velocity_squared", "free static force and a contact loss c |v| v",
                    lambda c: _replace(c, dissipation=(laws.VelocitySquared(3000.0),)),
                    ("precompression_n", "dissipation.0.c_n_s2_m2")),
    DrivenCandidate("free_preload_contact_exponent", "free static force and a power-law contact (n free)",
                    lambda c: _replace(c, contact_law=laws.PowerLaw(1.5, 1e-7)),
                    ("precompression_n", "contact_law.exponent"), {"contact_law.exponent": (1.0 / 1.5, 3.0 / 1.5)}),
    DrivenCandidate("free_preload_rayleigh_piezo", "free static force and a Rayleigh piezo",
                    lambda c: _replace(c, drive_stroke=RayleighStroke(1e6)),
                    ("precompression_n", "drive_stroke.rayleigh_per_m")),
)
# Candidates whose bending fit runs the sliders' JAX kernel under forward derivatives: one
# Levenberg-Marquardt step of the single bead's 36 levels takes minutes on 2 cores, so they
# are run only when named (`diagnose_laws(..., candidates=...)`).
MICRO_SLIP = ("support_friction.stiffness_n_m", "support_friction.slip_displacement_m")


def _micro_slip(chain: DrivenChain, **changes) -> DrivenChain:
    """`chain` with micro-slip supports at the single-law fit's constants (K = 2.8e6 N/m,
    phi = 22.5 nm: `single_bead_diagnosis_laws/micro_slip.json`), the start of every pair."""
    return _replace(chain, support_friction=laws.IwanSupport(2.8e6, 2.25e-8), **changes)


SLOW_CANDIDATES = (
    DrivenCandidate("micro_slip_supports", "micro-slip friction at the bead's supports (Iwan element)",
                    lambda c: _replace(c, support_friction=laws.IwanSupport(2e6, 1e-7)), MICRO_SLIP),
    # Micro-slip with Segalman's power-law spread of the supports' slip (a loss per cycle as
    # A^(2+p) rather than A^3, and more softening for the energy taken where p < 1), started at
    # the single-law fit's constants with the uniform spread (p = 1).
    DrivenCandidate("micro_slip_segalman",
                    "micro-slip supports with a power-law spread of their slip (Segalman; p free: loss per cycle "
                    "as A^(2+p))",
                    lambda c: _replace(c, support_friction=laws.IwanSupport(2.8e6, 2.25e-8, slip_power=1.0)),
                    MICRO_SLIP + ("support_friction.slip_power",), {"support_friction.slip_power": (0.1, 2.0)}),
    # Pairs: micro-slip with a second law, the pair's constants freed together.
    DrivenCandidate("micro_slip_free_preload",
                    "micro-slip supports, the contacts' static force free: the rest of the stated 4.5 N carried "
                    "by a load path in parallel with the bead (the fixture), which a prescribed face motion "
                    "does not feel", _micro_slip, MICRO_SLIP + ("precompression_n",)),
    DrivenCandidate("micro_slip_velocity_squared", "micro-slip supports and a contact loss c |v| v (Vergara)",
                    lambda c: _micro_slip(c, dissipation=(laws.VelocitySquared(3000.0),)),
                    MICRO_SLIP + ("dissipation.0.c_n_s2_m2",)),
    DrivenCandidate("micro_slip_rayleigh_piezo", "micro-slip supports and a piezo whose stroke grows with amplitude",
                    lambda c: _micro_slip(c, drive_stroke=RayleighStroke(1e6)),
                    MICRO_SLIP + ("drive_stroke.rayleigh_per_m",)),
    DrivenCandidate("micro_slip_actuator_mode",
                    "micro-slip supports and a drive that reaches its stroke through one actuator/fixture mode",
                    lambda c: _micro_slip(c, drive_stroke=ActuatorMode(9000.0, 0.3)),
                    MICRO_SLIP + ("drive_stroke.mode_hz", "drive_stroke.damping_ratio"),
                    {"drive_stroke.mode_hz": (0.5, 3.0)}),  # 4.5-27 kHz: above the bending sweep's 4.7 kHz
)


def base_chain(experiment, damping_rate_per_s: float = 1500.0) -> DrivenChain:
    """The file's chain at its stated precompression: masses, Hertz constants, viscous drag."""
    return DrivenChain(experiment.bead_mass_kg, experiment.contact_kappa_n_m1p5, experiment.precompression_n,
                       damping_rate_per_s)


def _tuned(chain: DrivenChain, resonance_hz: float) -> DrivenChain:
    """`chain` with its Hertz constants scaled so that its linear resonance is `resonance_hz`."""
    for _ in range(6):
        ratio = resonance_hz / float(normal_modes(chain)[0][0])
        chain = _with_kappa(chain, chain.contact_kappa_n_m1p5 * ratio ** 3)
    return chain


def _with_kappa(chain, kappa):
    return eqx.tree_at(lambda c: c.contact_kappa_n_m1p5, chain, kappa)


def _gap(model, measured):
    return None if model is None or measured is None else float(math.log(model / measured))


def _tip(frequencies, onsets):
    if not np.isfinite(onsets).any():
        return None, None
    i = int(np.nanargmin(onsets))
    return float(onsets[i]), float(frequencies[i])


class BoundedJointModel(JointModel):
    """`JointModel` clipping its log factors to a candidate's `bounds` (lower, upper); the
    bending blocks of the runs in `weights` ({run: weight}) weighted by their own `weight` per
    (model - measured) / peak instead of the bending run's."""

    def __init__(self, *args, bounds, weights=None, **kwargs):
        super().__init__(*args, **kwargs)
        self.bounds = bounds
        self.weights = weights or {}

    def clip(self, x) -> np.ndarray:
        return np.clip(np.asarray(x, dtype=float), *self.bounds)

    def _bending(self, run, m, x, columns):
        r, j = super()._bending(run, m, x, columns)
        if run.run not in self.weights:
            return r, j
        factor = self.weights[run.run] * NOMINAL_SCALE / self.bending_weight
        return r * factor, j * factor


def _bounded_model(experiment, chain, parameters, scales, candidate, progress, weights=None) -> BoundedJointModel:
    """The candidate's model of `experiment` (its first measurement the bending run's): the
    bending weighted by $\\sqrt{(1 - \\rho)/(1 + \\rho)}$, $\\rho$ its residuals' lag-1 correlation
    at the start, every factor within `FACTOR_LIMIT` (the Hertz constant `KAPPA_LIMITS`, the
    candidate's `factor_limits`) of its start."""
    unit = JointModel(experiment, chain, parameters, scales, 1.0)
    run, bend = unit.runs[0], experiment.measurements[0]
    measured = bend.data.sweep.rms_velocity_m_s[bend.fit_mask]
    x0 = np.zeros(len(parameters))
    resid = (unit.bending_curves(run, bend, x0) - measured) / bend.data.sweep.rms_velocity_m_s.max(axis=0)
    weight = 1.0 / math.sqrt(ar1_inflation(ar1_correlation(resid)))
    low, high = np.full(len(parameters), -math.log(FACTOR_LIMIT)), np.full(len(parameters), math.log(FACTOR_LIMIT))
    limits = {"contact_kappa_n_m1p5": KAPPA_LIMITS, **candidate.factor_limits}
    for k, p in enumerate(parameters):
        if p.name in limits:
            low[k], high[k] = (math.log(v) for v in limits[p.name])
    return BoundedJointModel(experiment, chain, parameters, scales, weight, progress,
                             bounds=(low, high), weights=weights)


def fitted_levels(m, held_out_levels: int, level_stride: int):
    """The bending measurement `m` on the drive levels a fit uses: without its `held_out_levels`
    highest, then every `level_stride`-th of the rest (its highest kept)."""
    sweep = m.data.sweep
    keep = sweep.drive_amplitudes_m.size - held_out_levels
    if keep < 2:
        raise ValueError(f"held_out_levels={held_out_levels} leaves {keep} of the bending run's "
                         f"{sweep.drive_amplitudes_m.size} drive levels to fit; keep at least 2.")
    if level_stride < 1:
        raise ValueError(f"level_stride must be a whole number >= 1, got {level_stride}.")
    levels = np.unique(np.r_[np.arange(0, keep, level_stride), keep - 1])
    if levels.size == sweep.drive_amplitudes_m.size:
        return m
    lower = dataclasses.replace(sweep, drive_amplitudes_m=sweep.drive_amplitudes_m[levels],
                                rms_velocity_m_s=sweep.rms_velocity_m_s[:, levels])
    return dataclasses.replace(m, data=dataclasses.replace(m.data, sweep=lower))


def fit_candidate(experiment, candidate: DrivenCandidate, *, held_out_levels: int = 0, level_stride: int = 1,
                  max_steps: int = 20, progress: bool = False) -> dict:
    """Fit `candidate` on the experiment's first bending measurement (less its
    `held_out_levels` highest drive levels, then predicted; every `level_stride`-th level of
    the rest) and predict the rest (see the module docstring); the bending's measures are
    of every level. **Returns:** a dict of its constants, each measurement's numbers and
    gaps, and `elapsed_s`."""
    began = time.perf_counter()
    bending_m = next(m for m in experiment.measurements if m.kind == "bending")
    alone = dataclasses.replace(experiment, measurements=(fitted_levels(bending_m, held_out_levels, level_stride),))
    measured_bend = bending(experiment.for_bending(bending_m), bending_m.data.sweep.rms_velocity_m_s)[0]
    chain = _tuned(candidate.add(base_chain(experiment)), measured_bend["lowest_drive_peak_hz"])
    shared = ("contact_kappa_n_m1p5", "damping_rate_per_s") + tuple(candidate.free)
    parameters = [JointParameter(n, None) for n in shared] + [JointParameter(DRIVE_SCALE, bending_m.run)]
    fitted_m = alone.measurements[0]
    model = _bounded_model(alone, chain, parameters, {bending_m.run: 1.0}, candidate, progress)
    x0 = np.zeros(len(parameters))
    run = model.runs[0]
    result = least_squares(model, x0, list(range(len(parameters))), max_steps=max_steps, bounds=model.bounds)
    x = model.clip(result.x)
    fitted = model.run_chain(run, x)
    out = {"name": candidate.name, "mechanism": candidate.mechanism, "free": list(shared) + [DRIVE_SCALE],
           "converged": bool(result.converged), "steps": int(result.steps),
           "constants": _constants(fitted, shared, model.run_scale(run, x)),
           "bending": bending_summary(experiment, model, run, bending_m, x, held_out_levels,
                                       int(fitted_m.data.sweep.drive_amplitudes_m.size))}
    out.update(predict_thresholds(experiment, fitted, progress))
    out["elapsed_s"] = time.perf_counter() - began
    return out


# The tongue run's fundamental below every onset (`tongue_fundamental`) is fitted on its smooth
# part: two narrow dip-and-peak features (factors 0.5 and 1.6 on a smooth linear response,
# `single_bead_diagnosis_laws/drive_response.json`) that no chain model here has, a fixture's,
# are left out.
TONGUE_FIXTURE_FEATURES_HZ = ((6325.0, 6425.0), (7125.0, 7225.0))
TONGUE_FUNDAMENTAL_LEVELS = 3  # 15.0, 17.3, 19.5 nm: below the lowest onset, 39.8 nm
# Its weight: it measures the tongue run's drive to about 10 % (the measured over the linear
# response's spread outside the two features, drive_response.json), its frequency structure
# smooth over the band, so the block counts as one measurement per drive level.
TONGUE_FUNDAMENTAL_SIGMA = 0.1


def _tongue_fundamental_measurement(tongue_m, sensor_m_s_per_v: float):
    """The tongue run's fundamental below its onsets as a bending `Measurement` of that run."""
    data = tongue_fundamental(tongue_m.data, sensor_m_s_per_v=sensor_m_s_per_v, levels=TONGUE_FUNDAMENTAL_LEVELS)
    f = data.sweep.frequencies_hz
    mask = np.ones(f.size, dtype=bool)
    for low, high in TONGUE_FIXTURE_FEATURES_HZ:
        mask &= ~((f >= low) & (f <= high))
    return dataclasses.replace(tongue_m, kind="bending", data=data, fit_mask=mask)


def fit_candidate_jointly(experiment, candidate: DrivenCandidate, *, held_out_levels: int = 0, level_stride: int = 1,
                          max_steps: int = 20, progress: bool = False,
                          start_precompression_n: float = FREE_PRELOAD_START_N) -> dict:
    """Fit `candidate` on the bending run and the tongue run together, then predict the loop.

    The tongue run enters by its thresholds (Floquet, support sliders as state,
    `fitting.driven.joint.JointModel`) and by
    its fundamental below every onset (`hertzchain.driven.measurements.tongue_fundamental`),
    which measures that run's true drive: each run has its own drive scale (calibration prior);
    everything else is shared, a freed `precompression_n` too (started at
    `start_precompression_n`, N, default `FREE_PRELOAD_START_N`): the same apparatus an hour apart, stated at the same 4.5 N. (Free
    per run, the fit escapes to a tongue run of resonance ~2.2 kHz and drive scale ~4, where the
    fundamental's drive scale and resonance trade off and the model has no tongue at all.) The loop (the next day, the tongue's
    calibration) is predicted at the tongue run's constants and drive scale. **Returns:** `fit_candidate`'s dict with
    `fitted_on` (["bending", "tongue"]), `tongue_run` (its constants) and `tongue_fundamental`
    (its median misfit)."""
    began = time.perf_counter()
    bending_m = next(m for m in experiment.measurements if m.kind == "bending")
    tongue_m = next((m for m in experiment.measurements if m.kind == "tongue"), None)
    if tongue_m is None:
        raise ValueError(f"{experiment.path}: fitting on the tongue needs a [[measurement]] of kind \"tongue\".")
    start = candidate.add(base_chain(experiment))
    if "precompression_n" in candidate.free:
        start = eqx.tree_at(lambda c: c.precompression_n, start, jnp.asarray(float(start_precompression_n)))
    measured_bend = bending(experiment.for_bending(bending_m), bending_m.data.sweep.rms_velocity_m_s)[0]
    chain = _tuned(start, measured_bend["lowest_drive_peak_hz"])
    fundamental = _tongue_fundamental_measurement(tongue_m, bending_m.data.sweep.sensor_m_s_per_v)
    fitted_bend = fitted_levels(bending_m, held_out_levels, level_stride)
    joint = dataclasses.replace(experiment, measurements=(fitted_bend, tongue_m, fundamental))
    shared = ("contact_kappa_n_m1p5", "damping_rate_per_s") + tuple(candidate.free)
    runs = (bending_m.run, tongue_m.run)
    parameters = [JointParameter(n, None) for n in shared] + [JointParameter(DRIVE_SCALE, r) for r in runs]
    scales = dict.fromkeys(runs, 1.0)
    points = int(fundamental.fit_mask.sum()) * TONGUE_FUNDAMENTAL_LEVELS
    weight = 1.0 / (TONGUE_FUNDAMENTAL_SIGMA * math.sqrt(points / TONGUE_FUNDAMENTAL_LEVELS))
    model = _bounded_model(joint, chain, parameters, scales, candidate, progress, {tongue_m.run: weight})
    x0 = np.zeros(len(parameters))
    result = least_squares(model, x0, list(range(len(parameters))), max_steps=max_steps, bounds=model.bounds)
    x = model.clip(result.x)
    bend_run, tongue_run = model.runs
    out = {"name": candidate.name, "mechanism": candidate.mechanism, "fitted_on": ["bending", "tongue"],
           "free": [p.label for p in parameters], "converged": bool(result.converged), "steps": int(result.steps),
           "constants": _constants(model.run_chain(bend_run, x), shared, model.run_scale(bend_run, x)),
           "tongue_run": _constants(model.run_chain(tongue_run, x), shared, model.run_scale(tongue_run, x)),
           "bending": bending_summary(experiment, model, bend_run, bending_m, x, held_out_levels,
                                       int(fitted_bend.data.sweep.drive_amplitudes_m.size))}
    out["tongue_run"]["resonance_hz"] = float(normal_modes(model.run_chain(tongue_run, x))[0][0])
    fund = bending_summary(joint, model, tongue_run, fundamental, x, 0, TONGUE_FUNDAMENTAL_LEVELS)
    out["tongue_fundamental"] = {"misfit_median": fund["misfit_median"], "misfit_max": fund["misfit_max"],
                                 "excluded_hz": [list(b) for b in TONGUE_FIXTURE_FEATURES_HZ]}
    out.update(predict_thresholds(experiment, model.run_chain(tongue_run, x), progress, model.run_scale(tongue_run, x)))
    out["tongue"]["how"] += "; fitted (thresholds and sub-threshold fundamental), at the fitted drive scale"
    out["loop"]["how"] += "; predicted at the tongue run's constants and drive scale"
    out["elapsed_s"] = time.perf_counter() - began
    return out


def bending_summary(experiment, model, run, bending_m, x, held_out_levels: int, fitted_level_count: int) -> dict:
    """The bending measurement `bending_m` of `model`'s `run` at `x`, every frequency and drive
    level: misfit (median, max, fraction of each curve's peak), shift, peak per nm top/lowest,
    each beside the data's, the linear resonance, the held-out levels' median misfit."""
    rows = np.arange(bending_m.data.sweep.frequencies_hz.size)
    curves = model.bending_curves(run, bending_m, x, rows)
    data = bending_m.data.sweep.rms_velocity_m_s
    misfit = np.sqrt(np.mean((curves[bending_m.fit_mask] - data[bending_m.fit_mask]) ** 2, axis=0)) / data.max(axis=0)
    mine = bending(experiment.for_bending(bending_m), curves)[0]
    measured = bending(experiment.for_bending(bending_m), data)[0]
    return {"misfit_median": float(np.median(misfit)), "misfit_max": float(misfit.max()),
            "shift": mine["shift"], "measured_shift": measured["shift"],
            "peak_ratio": mine["peak_per_drive_top_over_lowest"],
            "measured_peak_ratio": measured["peak_per_drive_top_over_lowest"],
            "resonance_hz": float(normal_modes(model.run_chain(run, x))[0][0]), "held_out_levels": held_out_levels,
            "fitted_levels": fitted_level_count,
            "held_out_misfit_median": float(np.median(misfit[misfit.size - held_out_levels:]))
            if held_out_levels else None}


def _constants(chain, shared, drive_scale) -> dict:
    values = {path: np.asarray(_leaf(chain, path)).tolist() for path in shared}
    values["precompression_n"] = float(chain.precompression_n)
    values["static_overlap_m"] = np.asarray(chain.static_overlap_m()).tolist()
    values[DRIVE_SCALE] = float(drive_scale)
    return values


def floquet_onsets(predict: JointModel, run) -> tuple[np.ndarray, str]:
    """(the true-amplitude thresholds of `predict`'s `run` at each of its threshold entries, NaN
    where none was found; how): the Floquet continuation, support sliders included."""
    _, found = predict.onsets(run, np.zeros(0))
    return np.where(found.found, found.amplitude_m, np.nan), "Floquet threshold (continuation)"


def predict_thresholds(experiment, chain, progress, drive_scale: float = 1.0, kinds=("tongue", "loop"),
                       onsets=floquet_onsets) -> dict:
    """The tongue tip and the loop's onset going up of `chain` (the measurements of `kinds`) at
    each run's calibration times `drive_scale`, in nominal amplitude. `onsets(predict, run) ->
    (amplitudes, how)` finds each run's thresholds (default `floquet_onsets`; `predict` the
    `JointModel` of `chain` on those measurements)."""
    others = [m for m in experiment.measurements if m.kind in kinds]
    rest = dataclasses.replace(experiment, measurements=tuple(others))
    predict = JointModel(rest, chain, [], {m.run: 1.0 for m in others}, 1.0)
    out = {}
    report = Progress(None, "candidate laws: predictions") if progress else None
    for run in predict.runs:
        if report is not None:
            report.note(f"run {run.run}")
        rows = _threshold_data(run)
        model, how = onsets(predict, run)
        model = model / drive_scale
        for kind in ("tongue", "loop"):
            picked = [i for i, row in enumerate(rows) if row[4] == kind]
            if not picked:
                continue
            f = np.array([rows[i][0] for i in picked])
            data = np.array([rows[i][1] for i in picked])
            if kind == "tongue":
                (ma, mf), (da, df) = _tip(f, model[picked]), _tip(f, data)
                out["tongue"] = {"run": run.run, "measured_tip_m": da, "measured_tip_hz": df, "model_tip_m": ma,
                                 "model_tip_hz": mf, "frequencies_hz": f.tolist(), "model_onset_m": model[picked].tolist(),
                                 "amplitude_gap_log": _gap(ma, da), "frequency_gap": None if mf is None else mf / df - 1,
                                 "how": how}
            else:
                ma = float(model[picked][0]) if np.isfinite(model[picked][0]) else None
                out["loop"] = {"run": run.run, "frequency_hz": float(f[0]), "measured_onset_up_m": float(data[0]),
                               "model_onset_up_m": ma, "gap_log": _gap(ma, float(data[0])), "how": how}
    return out


def scores(entry: dict) -> dict:
    """Each target's measurement of `entry` (a `fit_candidate` result): {name: (value, met)}."""
    b, t, loop = entry["bending"], entry.get("tongue", {}), entry.get("loop", {})

    def within(gap, tol):
        return gap is not None and abs(gap) <= tol

    tip = t.get("amplitude_gap_log")
    onset = loop.get("gap_log")
    return {
        "bending_misfit_median": (b["misfit_median"], b["misfit_median"] <= TARGETS["bending_misfit_median"]),
        "shift_points": (b["shift"] - b["measured_shift"],
                         abs(b["shift"] - b["measured_shift"]) <= TARGETS["shift_points"]),
        "peak_ratio": (b["peak_ratio"], abs(b["peak_ratio"] - b["measured_peak_ratio"]) <= TARGETS["peak_ratio"]),
        "tongue_tip_amplitude": (None if tip is None else math.exp(tip),
                                 within(None if tip is None else math.expm1(tip), TARGETS["tongue_tip_amplitude"])),
        "tongue_tip_frequency": (t.get("frequency_gap"), within(t.get("frequency_gap"), TARGETS["tongue_tip_frequency"])),
        "loop_onset_up": (None if onset is None else math.exp(onset),
                          within(None if onset is None else math.expm1(onset), TARGETS["loop_onset_up"])),
        "held_out_bending_misfit": (b.get("held_out_misfit_median"), b.get("held_out_misfit_median") is not None
                                    and b["held_out_misfit_median"] <= TARGETS["held_out_bending_misfit"]),
    }


def _distances(entry) -> dict:
    """How far each predicted measurement of `entry` is from its data, >= 0 and in log units
    (|log(model / measured)|; the held-out bending's log misfit), None where nothing was
    predicted (no period doubling found, no held-out levels)."""
    t, loop, b = entry.get("tongue", {}), entry.get("loop", {}), entry["bending"]

    def size(gap):
        return None if gap is None else abs(gap)

    return {"tongue_tip_amplitude": size(t.get("amplitude_gap_log")), "loop_onset_up": size(loop.get("gap_log")),
            "tongue_tip_frequency": None if t.get("frequency_gap") is None else abs(math.log1p(t["frequency_gap"])),
            "held_out_bending_misfit": None if b.get("held_out_misfit_median") is None
            else math.log(b["held_out_misfit_median"])}


def verdict(entries: list[dict]) -> dict:
    """Which candidates are named (see the module docstring), and per candidate which targets it
    meets and which not, against the base (the first entry). `best`: of the named, the one
    whose predicted measurements lie closest to the data in all (sum of `_distances`)."""
    base = entries[0]
    base_scores, base_distance = scores(base), _distances(base)
    per, named, closeness = {}, [], {}
    for entry in entries:
        s, distance = scores(entry), _distances(entry)
        explains = [k for k, (_, met) in s.items() if met]
        improves = []
        for k in PREDICTED:
            d, d0 = distance.get(k), base_distance.get(k)
            if d is None or MEASURED_BY[k] in entry.get("fitted_on", ("bending",)):
                continue
            newly_met = s[k][1] and not base_scores[k][1]
            if newly_met or (d0 is None and d <= BASE_SILENT_WITHIN) or (d0 is not None and d0 - d >= NAMED_GAIN):
                improves.append(k)
        per[entry["name"]] = {"explains": explains, "does_not_explain": [k for k in s if k not in explains],
                              "improves_unfitted_over_base": improves,
                              "values": {k: v for k, (v, _) in s.items()}}
        if entry is not base and improves:
            named.append(entry["name"])
            closeness[entry["name"]] = sum(d for d in distance.values() if d is not None)
    return {"named": named, "best": min(closeness, key=closeness.get) if closeness else None,
            "per_candidate": per, "targets": TARGETS}


def diagnose_laws(experiment, candidates=CANDIDATES, *, held_out_levels: int = 0, level_stride: int = 1,
                  max_steps: int = 20, progress: bool = True, fit=fit_candidate) -> dict:
    """Fit every candidate on the bending run (`fit`: `fit_candidate`; `fit_candidate_jointly`:
    on the bending and the tongue), predict the rest, and judge (see the module
    docstring). **Returns:** `candidates` (each `fit_candidate`'s dict), `failed` (name and error
    of each candidate whose fit stopped on a refusal of the chain), `verdict`, `elapsed_s`."""
    began = time.perf_counter()
    entries, failed = [], []
    report = Progress(None, "candidate laws") if progress else None
    for candidate in candidates:
        if report is not None:
            report.note(f"candidate {candidate.name}")
        try:
            entries.append(fit(experiment, candidate, held_out_levels=held_out_levels,
                               level_stride=level_stride, max_steps=max_steps, progress=progress))
        except ValueError as error:  # a law the chain refuses at some trial constants: said, not hidden
            failed.append({"name": candidate.name, "mechanism": candidate.mechanism, "error": str(error)})
            if report is not None:
                report.note(f"{candidate.name} failed: {error}")
    return {"experiment": str(experiment.path), "candidates": entries, "failed": failed, "verdict": verdict(entries),
            "elapsed_s": time.perf_counter() - began}
