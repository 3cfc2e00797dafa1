"""Joint fits of every measurement of a driven experiment, across runs.

An experiment file of `[[measurement]]` tables (`fitting.driven.experiment`) describes runs of
one apparatus: the bead, its contacts and its damping are the same in every run; what the lab
sets anew each time (the precompression, the drive's calibration) need not be. The fit has
**shared** parameters, one value for every run, and **per-run** ones, one value per run, named
in the file's `[fit]` table (default `DEFAULT_SHARED`, `DEFAULT_PER_RUN`):

- a field of `hertzchain.driven.DrivenChain`, addressed by its path (`contact_kappa_n_m1p5`,
  `damping_rate_per_s`, `precompression_n`, or a dotted path into a law object the chain
  holds): fitted as a factor $e^{x}$ on its start value (every entry of an array field
  together, their ratios kept), so any positive field flows through;
- `drive_scale`: the piezo's true amplitude over the run's nominal one (the file's m/V), with
  the calibration's stated uncertainty $u$ as a prior, $\\log s \\sim N(0, \\log(1 + u)^2)$.

Residuals, each whitened by what is known of its noise:

- **bending**: (model - measured) / each curve's peak / `fitting.driven.NOMINAL_SCALE`, on
  the file's fitted frequencies and every drive level (the model `lockin_grid`), times
  $\\sqrt{(1 - \\rho)/(1 + \\rho)}$, $\\rho$ the residuals' lag-1 correlation along frequency at
  the start (so the ~12,000 correlated points count as the ~100 independent ones they are);
- **thresholds** (tongue onsets by frequency, the loop's onset going up): $(\\log(a^*/s) -
  \\log a_{data}) / \\sigma$, $a^*$ the model's period-doubling threshold
  (`hertzchain.driven.thresholds`, its derivative by the implicit function theorem), $s$ the
  run's drive scale. $\\sigma$ is the tongue's own point-to-point scatter (the RMS second
  difference of log onset along frequency over $\\sqrt 6$, floored at the amplitude step's
  quantisation). A frequency without f/2 up to the sweep's top amplitude $T$ is a bound: a
  residual $(\\log T - \\log(a^*/s))/\\sigma$ only where the model doubles below it. Where the
  model does not double within the search (up to 3 × the data's top), its threshold is taken
  there, with no derivative, and the report says so.
- **priors**: $\\log s / \\log(1 + u)$ for each run's drive scale.

The loop's disappearance coming down and the scope records are read and reported, not fitted:
the disappearance is where the period-2 branch ends (a fold the continuation here does not
follow; the report runs the lab's loop on the model by time stepping instead,
`hertzchain.driven.thresholds.emulate_loop`), and the scope records measure the same onset as
the loop's lock-in.

The optimiser is `fitting.fit.least_squares` (Levenberg-Marquardt of optimistix, its test of
an optimum); standard errors `fitting.uncertainty.covariance_from_jacobian` on the whitened
residuals scaled by $\\chi^2/(n_{eff} - p)$: the run-to-run variation of what the runs share
shows in that misfit and in the per-run constants' spread.
"""

from __future__ import annotations

import dataclasses
import math
import time

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from hertzchain.driven import DrivenChain, lockin_grid
from hertzchain.driven.thresholds import onset_tangents, period_doubling_onsets
from hertzchain.progress import Progress

from ..fit import least_squares
from ..uncertainty import ar1_correlation, ar1_inflation, covariance_from_jacobian
from .experiment import DrivenExperiment, DrivenExperimentError
from .lockin_fit import NOMINAL_SCALE, chain_at, fit_driven, lockin_settings

DEFAULT_SHARED = ("contact_kappa_n_m1p5", "damping_rate_per_s")
DEFAULT_PER_RUN = ("precompression_n", "drive_scale")
DRIVE_SCALE = "drive_scale"
# The model's threshold is searched from this fraction of the lowest measured onset to this
# multiple of the sweep's top amplitude (both in the run's true amplitude).
SEARCH_BELOW, SEARCH_ABOVE = 0.05, 3.0
THRESHOLD_KINDS = ("tongue", "loop")
# Every factor stays within [1/LIMIT, LIMIT] of its start (a projected Levenberg-Marquardt): a
# run fitted on one threshold can otherwise leave for constants where the chain does not
# double at all, a plateau of the residuals with no way back.
FACTOR_LIMIT = 30.0


@dataclasses.dataclass(frozen=True)
class JointParameter:
    """One entry of the joint fit's vector: `name` (a chain field's path, or `drive_scale`),
    `run` (None when shared), `label` (`precompression_n[2013-07-03 10:29]`)."""

    name: str
    run: str | None

    @property
    def label(self) -> str:
        return self.name if self.run is None else f"{self.name}[{self.run}]"


def _entries(path: str) -> tuple[str, list[int] | None]:
    """A path and the entries it selects: `contact_kappa_n_m1p5[0,2]` -> (`contact_kappa_n_m1p5`,
    [0, 2]) (the end contacts of two beads); a path without brackets selects the whole field."""
    if not path.endswith("]"):
        return path, None
    field, _, inside = path[:-1].partition("[")
    try:
        return field, [int(part) for part in inside.split(",")]
    except ValueError:
        raise ValueError(f"parameter {path!r}: the entries in brackets must be whole numbers, e.g. "
                         "contact_kappa_n_m1p5[0,2].") from None


def _field(chain, path: str):
    value = chain
    for part in path.split("."):
        value = value[int(part)] if part.isdigit() else getattr(value, part)  # a tuple of laws by index
    return value


def _leaf(chain, path: str):
    """The value a parameter's path addresses (its selected entries for `field[i,j]`)."""
    field, entries = _entries(path)
    value = _field(chain, field)
    return value if entries is None else value[jnp.asarray(entries)]


def chain_fields(chain: DrivenChain) -> list[str]:
    """The paths of `chain`'s positive float fields, the ones a factor can fit."""
    fields = []
    for field in dataclasses.fields(chain):
        value = getattr(chain, field.name)
        if isinstance(value, jax.Array) and jnp.issubdtype(value.dtype, jnp.floating) and bool(jnp.all(value > 0)):
            fields.append(field.name)
    return fields


def scaled_chain(chain: DrivenChain, paths: tuple, log_factors) -> DrivenChain:
    """`chain` with the field at each of `paths` times $e^{x_k}$ (traceable in `log_factors`);
    a path `field[i,j]` scales those entries of an array field only (e.g. the end contacts'
    Hertz constants apart from the bead-bead ones)."""
    for k, path in enumerate(paths):
        field, entries = _entries(path)
        value, factor = _field(chain, field), jnp.exp(log_factors[k])
        if entries is not None:  # the factor on the selected entries, 1 on the others
            factor = jnp.where(jnp.zeros(value.shape, bool).at[jnp.asarray(entries)].set(True), factor, 1.0)
        chain = eqx.tree_at(lambda c, p=field: _field(c, p), chain, value * factor)
    return chain


@dataclasses.dataclass
class RunModel:
    """One run's part of the joint fit: its measurements, the global columns of its chain's
    factors (`chain_columns`, in `paths` order) and of its drive scale (`scale_column` or None)."""

    run: str
    measurements: list
    paths: tuple
    chain_columns: list
    scale_column: int | None
    start_scale: float
    drive_uncertainty: float


def _threshold_data(run: RunModel):
    """(frequencies, measured onset (NaN: censored), top amplitude, step, kind per entry) of a
    run's tongue and loop measurements, nominal amplitudes."""
    rows = []
    for m in run.measurements:
        if m.kind == "tongue":
            top = m.data.drive_amplitudes_m[-1]
            rows += [(f, a, top, m.data.step_m, "tongue") for f, a in zip(m.data.frequencies_hz, m.data.onset_m)]
        elif m.kind == "loop":
            top = m.data.drive_amplitudes_m[m.data.turn]
            rows.append((m.data.frequency_hz, m.data.onset_up_m, top, m.data.step_m, "loop"))
    return rows


def threshold_sigma(measurements) -> float:
    """The log-threshold noise: the tongues' point-to-point scatter (RMS second difference of
    log onset along frequency / sqrt 6), floored at the amplitude step's quantisation."""
    scatter, quantisation = [], [0.0]
    for m in measurements:
        if m.kind in THRESHOLD_KINDS:
            onset = m.data.onset_m if m.kind == "tongue" else np.array([m.data.onset_up_m])
            quantisation.append(m.data.step_m / math.sqrt(12) / np.nanmin(onset))
        if m.kind == "tongue":
            logs = np.log(m.data.onset_m[np.isfinite(m.data.onset_m)])
            if logs.size >= 3:
                scatter.append(np.sqrt(np.mean(np.diff(logs, 2) ** 2) / 6))
    return float(max(max(scatter, default=0.0), max(quantisation)))


class JointModel:
    """The residuals of every measurement and their Jacobian (the `model` of
    `fitting.fit.least_squares`) in the log-factor vector x (see the module docstring)."""

    def __init__(self, experiment: DrivenExperiment, start_chain: DrivenChain, parameters: list, start_scales: dict,
                 bending_weight: float, progress: bool = False):
        self.experiment, self.start_chain, self.parameters = experiment, start_chain, parameters
        self.bending_weight = bending_weight
        self.report = Progress(None, "joint fit") if progress else None
        self.sigma = threshold_sigma(experiment.measurements)
        self.runs = []
        for run in dict.fromkeys(m.run for m in experiment.measurements):
            ms = [m for m in experiment.measurements if m.run == run]
            columns = [i for i, p in enumerate(parameters) if p.name != DRIVE_SCALE and p.run in (None, run)]
            scale = [i for i, p in enumerate(parameters) if p.name == DRIVE_SCALE and p.run in (None, run)]
            self.runs.append(RunModel(run, ms, tuple(parameters[i].name for i in columns), columns,
                                      scale[0] if scale else None, start_scales[run], ms[0].drive_uncertainty))
        self.evaluations = 0
        self.last_onsets = {}

    def run_chain(self, run: RunModel, x) -> DrivenChain:
        return scaled_chain(self.start_chain, run.paths, jnp.asarray(np.asarray(x)[run.chain_columns]))

    def run_scale(self, run: RunModel, x) -> float:
        return run.start_scale * (math.exp(x[run.scale_column]) if run.scale_column is not None else 1.0)

    def clip(self, x) -> np.ndarray:
        bound = math.log(FACTOR_LIMIT)
        return np.clip(np.asarray(x, dtype=float), -bound, bound)

    def residuals(self, x) -> np.ndarray:
        return self.linearize(x, [])[0]

    def linearize(self, x, columns):
        x = self.clip(x)
        blocks, jacobians, priors = [], [], set()
        for run in self.runs:
            for m in run.measurements:
                if m.kind == "bending":
                    r, j = self._bending(run, m, x, columns)
                    blocks.append(r), jacobians.append(j)
            if any(m.kind in THRESHOLD_KINDS for m in run.measurements):
                r, j = self._thresholds(run, x, columns)
                blocks.append(r), jacobians.append(j)
            if run.scale_column is not None and run.drive_uncertainty > 0 and run.scale_column not in priors:
                priors.add(run.scale_column)  # a drive scale shared by runs has one prior
                width = math.log1p(run.drive_uncertainty)
                prior = np.array([math.log(self.run_scale(run, x)) / width])
                j = np.zeros((1, len(columns)))
                if run.scale_column in columns:
                    j[0, list(columns).index(run.scale_column)] = 1.0 / width
                blocks.append(prior), jacobians.append(j)
        r = np.concatenate(blocks)
        self.evaluations += 1
        if self.report is not None and columns:
            self.report.note(f"evaluation {self.evaluations}: chi^2 {r @ r:.4g}")
        return r, np.concatenate(jacobians)

    # --- bending -----------------------------------------------------------------------------
    def bending_curves(self, run: RunModel, m, x, rows=None) -> np.ndarray:
        sweep = m.data.sweep
        rows = np.nonzero(m.fit_mask)[0] if rows is None else rows
        chain = self.run_chain(run, x)
        drives = sweep.drive_amplitudes_m * self.run_scale(run, x)
        return np.asarray(lockin_grid(chain, sweep.frequencies_hz[rows], drives,
                                      **lockin_settings(self.experiment)).rms[0])

    def _bending(self, run: RunModel, m, x, columns):
        sweep = m.data.sweep
        rows = np.nonzero(m.fit_mask)[0]
        measured = sweep.rms_velocity_m_s[rows]
        peaks = sweep.rms_velocity_m_s.max(axis=0)
        scale = self.bending_weight / NOMINAL_SCALE
        local = [c for c in columns if c in run.chain_columns or c == run.scale_column]
        jac = np.zeros((measured.size, len(columns)))
        if not local:
            return ((self.bending_curves(run, m, x, rows) - measured) / peaks).ravel() * scale, jac
        directions = np.zeros((len(local), len(run.chain_columns) + 1))
        for k, c in enumerate(local):
            directions[k, run.chain_columns.index(c) if c != run.scale_column else -1] = 1.0
        factors = np.append(np.asarray(x)[run.chain_columns], 0.0)
        drives = sweep.drive_amplitudes_m * self.run_scale(run, x)
        settings = tuple(sorted(lockin_settings(self.experiment).items()))
        value, tangents = _bending_jvp(self.start_chain, run.paths, settings, jnp.asarray(factors),
                                       jnp.asarray(sweep.frequencies_hz[rows]), jnp.asarray(drives),
                                       jnp.asarray(directions))
        r = ((np.asarray(value) - measured) / peaks).ravel() * scale
        for k, c in enumerate(local):
            jac[:, list(columns).index(c)] = (np.asarray(tangents[k]) / peaks).ravel() * scale
        return r, jac

    # --- thresholds --------------------------------------------------------------------------
    def search_range(self, run: RunModel) -> tuple[float, float]:
        """The amplitudes (true, m) a run's thresholds are searched between: fixed per run (at its
        start drive scale), so that a threshold beyond the search moves only with the drive scale."""
        rows = _threshold_data(run)
        measured = np.array([a for _, a, _, _, _ in rows])
        lowest = SEARCH_BELOW * np.nanmin(measured) if np.isfinite(measured).any() else 1e-9
        return lowest * run.start_scale, SEARCH_ABOVE * max(top for _, _, top, _, _ in rows) * run.start_scale

    def onsets(self, run: RunModel, x):
        """The model's thresholds at the run's threshold frequencies (`DoublingOnsets`, true
        amplitude) and the chain they are of."""
        lowest, highest = self.search_range(run)
        chain = self.run_chain(run, x)
        found = period_doubling_onsets(chain, [row[0] for row in _threshold_data(run)], lowest_amplitude_m=lowest,
                                       highest_amplitude_m=highest, steps_per_period=_steps(self.experiment))
        self.last_onsets[run.run] = found
        return chain, found

    def threshold_residuals(self, run: RunModel, found, scale: float):
        """(residuals, which have a derivative in the chain, which in the drive scale) of a run's
        thresholds `found` at drive scale `scale` (see the module docstring)."""
        rows = _threshold_data(run)
        model = np.where(found.found, found.amplitude_m, self.search_range(run)[1]) / scale
        measured = np.array([row[1] for row in rows])
        top = np.array([row[2] for row in rows])
        censored = ~np.isfinite(measured)
        residual = np.where(censored, np.minimum(np.log(model) - np.log(top), 0.0),
                            np.log(model) - np.log(np.where(censored, 1.0, measured))) / self.sigma
        in_scale = ~censored | (model < top)
        return residual, in_scale & found.found, in_scale

    def _thresholds(self, run: RunModel, x, columns):
        chain, found = self.onsets(run, x)
        residual, in_chain, in_scale = self.threshold_residuals(run, found, self.run_scale(run, x))
        jac = np.zeros((residual.size, len(columns)))
        local = [c for c in columns if c in run.chain_columns]
        if local and in_chain.any():
            directions = np.zeros((len(local), len(run.chain_columns)))
            for k, c in enumerate(local):
                directions[k, run.chain_columns.index(c)] = 1.0
            factors = jnp.asarray(np.asarray(x)[run.chain_columns])
            tangents = jax.vmap(lambda d: jax.jvp(lambda f: scaled_chain(self.start_chain, run.paths, f), (factors,),
                                                  (d,))[1])(jnp.asarray(directions))
            derivative = onset_tangents(chain, found, tangents) / np.where(found.found, found.amplitude_m, 1.0)
            for k, c in enumerate(local):
                jac[:, list(columns).index(c)] = np.where(in_chain, derivative[k], 0.0) / self.sigma
        if run.scale_column in columns:  # log(a*/s): -1 per unit of log s
            jac[:, list(columns).index(run.scale_column)] = np.where(in_scale, -1.0, 0.0) / self.sigma
        return residual, jac


def _steps(experiment) -> int:
    return int(experiment.model["steps_per_period"])


@eqx.filter_jit
def _bending_jvp(start_chain, paths, settings, factors, frequencies, drives, directions):
    def curves(f):
        chain = scaled_chain(start_chain, paths, f[:-1])
        return lockin_grid(chain, frequencies, drives * jnp.exp(f[-1]), **dict(settings)).rms[0]

    return jax.vmap(lambda d: jax.jvp(curves, (factors,), (d,)), out_axes=(None, 0))(directions)


# --- the fit -----------------------------------------------------------------------------------
def joint_parameters(experiment: DrivenExperiment, chain: DrivenChain) -> list[JointParameter]:
    """The fit's vector from the file's `[fit]` table (defaults `DEFAULT_SHARED`, `DEFAULT_PER_RUN`).
    **Raises:** `DrivenExperimentError` for a name that is no positive chain field nor
    `drive_scale`, or one named both shared and per run."""
    shared = tuple(experiment.fit_options.get("shared", DEFAULT_SHARED))
    per_run = tuple(experiment.fit_options.get("per_run", DEFAULT_PER_RUN))
    valid = chain_fields(chain) + [DRIVE_SCALE]
    for name in shared + per_run:
        if name not in valid:
            raise DrivenExperimentError(f"{experiment.path} [fit]: {name!r} is not a fittable constant; valid: "
                                        f"{', '.join(valid)} (a chain field fits as a factor on its start value, "
                                        "so it must be positive there).")
    both = set(shared) & set(per_run)
    if both:
        raise DrivenExperimentError(f"{experiment.path} [fit]: {', '.join(sorted(both))} named both shared and per run.")
    runs = list(dict.fromkeys(m.run for m in experiment.measurements))
    return [JointParameter(n, None) for n in shared] + [JointParameter(n, r) for n in per_run for r in runs]


def start_values(experiment: DrivenExperiment, *, max_steps: int, progress: bool):
    """(start chain, {run: drive scale}, the bending fit): the first bending measurement fitted
    alone (`fitting.driven.fit_driven`), its constants the start of every run.
    **Raises:** `DrivenExperimentError` without a bending measurement."""
    bending = [m for m in experiment.measurements if m.kind == "bending"]
    if not bending:
        raise DrivenExperimentError(f"{experiment.path}: a joint fit starts from a bending measurement's own fit; "
                                    "add a [[measurement]] of kind \"bending\".")
    single = experiment.for_bending(bending[0])
    if progress:
        Progress(None, "joint fit").note(f"start: the bending run {bending[0].run} alone")
    first = fit_driven(single, max_steps=max_steps, progress=progress)
    chain = chain_at(single, first.x)
    chain = DrivenChain(chain.bead_mass_kg, chain.contact_kappa_n_m1p5, chain.precompression_n,
                        chain.damping_rate_per_s)
    scale = float(first.x[first.labels.index(DRIVE_SCALE)])
    return chain, {m.run: (scale if m.run == bending[0].run else 1.0) for m in experiment.measurements}, first


# The start's precompression factors and drive scales tried for a run of thresholds only.
START_PRECOMPRESSIONS = tuple(np.geomspace(0.25, 4.0, 17))
START_SCALES = tuple(np.geomspace(0.2, 5.0, 41))


def scan_threshold_runs(model: JointModel, x, grid=START_PRECOMPRESSIONS, scales=START_SCALES,
                        progress=False) -> np.ndarray:
    """`x` with each run that holds only thresholds at its best precompression factor of `grid`
    and drive scale of `scales` (scored by its threshold residuals and the scale's prior): the
    thresholds move by factors where the bending run's constants leave them, and a model tongue
    too deep or too wide is told from none at all only with both. The thresholds are of the
    chain alone, so each precompression costs one search, each scale none."""
    x = np.array(x, dtype=float)
    report = Progress(None, "joint fit: start") if progress else None
    for run in model.runs:
        if any(m.kind == "bending" for m in run.measurements) or \
                not any(m.kind in THRESHOLD_KINDS for m in run.measurements):
            continue
        column = [c for c, p in zip(run.chain_columns, run.paths)
                  if p == "precompression_n" and model.parameters[c].run == run.run]
        factors = grid if column else [None]
        tried_scales = scales if run.scale_column is not None else [1.0]
        best, best_chi2 = (x[column[0]] if column else None, 0.0), math.inf
        for factor in factors:
            trial = x.copy()
            if column:
                trial[column[0]] = math.log(factor)
            _, found = model.onsets(run, trial)
            for scale in tried_scales:
                r = model.threshold_residuals(run, found, run.start_scale * scale)[0]
                width = math.log1p(run.drive_uncertainty) if run.drive_uncertainty > 0 else math.inf
                chi2 = float(r @ r) + (math.log(run.start_scale * scale) / width) ** 2
                if chi2 < best_chi2:
                    best, best_chi2 = (trial[column[0]] if column else None, math.log(scale)), chi2
            if report is not None:
                report.note(f"run {run.run}, precompression x {factor:.3g}: {int(found.found.sum())} of "
                            f"{found.found.size} thresholds found")
        if column:
            x[column[0]] = best[0]
        if run.scale_column is not None:
            x[run.scale_column] = best[1]
        if report is not None:
            report.note(f"run {run.run}: chi^2 {best_chi2:.4g}")
    return x


@dataclasses.dataclass
class JointFit:
    """A joint fit: `model` (`JointModel`), `x` (p,) log factors, `stderr` (p,) of them,
    `labels`, `converged`, `steps`, `message`, `chi2`, `dof`, `covariance` (the shared
    routine's `Covariance`), `start` (the bending run's own fit), `rho` (its residuals' lag-1
    correlation), `elapsed_s`."""

    model: JointModel
    x: np.ndarray
    stderr: np.ndarray
    labels: tuple
    converged: bool
    steps: int
    message: str
    chi2: float
    dof: int
    covariance: object
    start: object
    rho: float
    elapsed_s: float


def fit_joint(experiment: DrivenExperiment, *, max_steps: int = 100, progress: bool = True) -> JointFit:
    """Fit every measurement of `experiment` together (see the module docstring)."""
    began = time.perf_counter()
    chain, scales, first = start_values(experiment, max_steps=max_steps, progress=progress)
    parameters = joint_parameters(experiment, chain)
    labels = tuple(p.label for p in parameters)
    unit = JointModel(experiment, chain, parameters, scales, 1.0)
    x = np.zeros(len(parameters))
    # the bending residuals' correlation along frequency at the start sets their weight
    rho = 0.0
    for run in unit.runs:
        for m in run.measurements:
            if m.kind == "bending":
                measured = m.data.sweep.rms_velocity_m_s[m.fit_mask]
                resid = (unit.bending_curves(run, m, x) - measured) / m.data.sweep.rms_velocity_m_s.max(axis=0)
                rho = max(rho, ar1_correlation(resid))
    model = JointModel(experiment, chain, parameters, scales, 1.0 / math.sqrt(ar1_inflation(rho)), progress)
    x = scan_threshold_runs(model, x, progress=progress)
    if model.report is not None:
        model.report.note(f"fitting {', '.join(labels)} jointly ...")
    columns = list(range(len(parameters)))
    bound = np.full(len(columns), math.log(FACTOR_LIMIT))
    result = least_squares(model, x, columns, max_steps=max_steps, bounds=(-bound, bound))
    x = model.clip(result.x)
    r, jac = model.linearize(x, columns)
    chi2 = float(r @ r)
    n_bending = sum(int(m.fit_mask.sum()) * m.data.sweep.drive_amplitudes_m.size
                    for m in experiment.measurements if m.kind == "bending")
    n_effective = n_bending * model.bending_weight ** 2 + (r.size - n_bending)
    dof = max(round(n_effective) - len(columns), 1)
    cov = covariance_from_jacobian(jac, list(labels), chi2=chi2, dof=dof, scale="residual")
    message = ("converged: no step lowers chi^2 by the optimum test's tolerance" if result.converged else
               f"not converged in {result.steps} steps (raise --max-steps)")
    return JointFit(model, x, cov.stderr, labels, bool(result.converged), int(result.steps), message, chi2, dof, cov,
                    first, rho, time.perf_counter() - began)
