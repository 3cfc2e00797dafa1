"""Least-squares fits of chain parameters to trace files with optimistix.

`fit(experiments, params=("eta_s", "mu", "C"))` minimises the sum of squared whitened
residuals (`fitting.model`) with Levenberg-Marquardt (`optimistix.LevenbergMarquardt`,
Jacobian by forward-mode differentiation of the solver), in the bounded transformed
coordinates of `fitting.parameters`. Several starts run as one `vmap`ped batch; the best
is kept and disagreement between starts is reported. Every fit -- `fit`, `fit_datasets`,
profiles and the host-driven `least_squares` of the diagnosis -- ends by one test of an
optimum (`fitting.optimum`: `_worth_testing`, `_at_optimum`, `OPTIMUM_TOLERANCE`): no step
moves chi^2 by a statistically meaningful amount. Standard errors, correlations,
identifiability warnings and the choice of covariance come from `fitting.uncertainty`;
profile likelihoods on request.

The fit's units, one concept a module: this one builds the problem and runs the fits;
`fitting.batched_search` is the compiled optimistix loop over a batch of starts or data
sets, `fitting.least_squares` the host-driven least squares (`least_squares`,
`LeastSquares`, importable from here too), `fitting.optimum` the stopping rule,
`fitting.fit_result` the result (`FitResult`) and what is derived from it.
"""

from __future__ import annotations

import math
import time
import warnings

import jax.numpy as jnp
import numpy as np

from hertzchain.progress import Progress

from . import start as start_values
from .batched_search import _make_solver, _multistart_points, _physical_values, _run_least_squares
from .data import FitInputError, as_experiments
from .fit_result import FitResult, _correlated_series, _residual_rms, _speed_constant
from .least_squares import LeastSquares, least_squares  # noqa: F401  (importable from here too)
from .model import ForwardModel, Problem
from .optimum import OPTIMUM_TOLERANCE
from .parameters import (
    LabelledValues,
    bare_speed_constant,
    build_instances,
    checked_keys,
    get_spec,
    parse_parameter_list,
    public_label,
    resolve_label,
    resolve_name,
    to_unbounded,
    transform_arrays,
)
from .priors import apply_priors, parse_priors, prior_names
from .uncertainty import (
    COVARIANCES,
    Covariance,
    correlated_score_covariance,
    covariance_choice,
    covariance_from_jacobian,
    identifiability_warnings,
    noise_band,
    profile_interval,
)


class FitError(RuntimeError):
    """The fit did not converge; the message says how far it got and what to try."""


class FitWarning(UserWarning):
    """Something about a fit the user should know (identifiability, multistart disagreement)."""


# --- building a problem ------------------------------------------------------------------------
def make_problem(experiments, params=("eta_s", "mu", "C"), *, fixed=None,
                 forward: ForwardModel | None = None, priors=()) -> Problem:
    """Build the least-squares `Problem` for `params` on `experiments`.

    **Arguments:**

    - `experiments`: `Experiment`s (see `fitting.data`), `TraceFile`s or paths.
    - `params`: names from the registry (`fitting.parameters.REGISTRY`, public names; a
      previous name warns); experiment-scoped ones get one value per file, `gain` one per
      channel.
    - `fixed`: name -> value (SI) of global setup parameters held fixed at a value other than
      the header's (e.g. `{"mu": 0.19}`; a previous name warns).
    - `forward`: a `ForwardModel` (custom solver / model switches, time-step choice).
    - `priors`: `fitting.priors` texts or `Prior`s (`"bead_youngs_pa=203GPa+-4GPa"`); a
      parameter with a prior is fitted; a normal prior adds a residual row.
    """
    experiments = as_experiments(experiments)
    priors = parse_priors(priors, source="priors")
    names = checked_keys(parse_parameter_list(params, where="params") + prior_names(priors))
    forward = forward or ForwardModel()
    fixed = {resolve_name(name, where="fixed"): value for name, value in dict(fixed or {}).items()}
    base = []
    for experiment in experiments:
        trace = experiment.trace
        overrides = {}
        if trace.striker_velocity_m_s is None:
            if "striker_velocity" not in names:
                raise FitInputError(
                    f"{experiment.label}: the file has no striker_velocity_m_s; add it to the header "
                    "or fit it (params ... ,striker_velocity_m_s)."
                )
            overrides["striker_velocity_m_s"] = start_values.estimate_striker_velocity(trace)
        setup = trace.setup(**overrides)
        for name, value in fixed.items():
            spec = get_spec(name)
            shown = public_label(name)
            if spec.kind != "setup" or spec.scope != "global":
                raise ValueError(f"fixed: {shown} is not a global setup parameter.")
            if name in names:
                raise ValueError(f"{shown} is both fitted and fixed; choose one.")
            if not spec.in_bounds(float(value)):
                raise ValueError(f"fixed {shown} = {float(value):g} {spec.unit}".rstrip() + " is outside its range "
                                 f"({spec.lower:g} to {spec.upper:g} {spec.unit}".rstrip() + f"); give {shown} a "
                                 "value in that range, in SI units or with a unit (e.g. 2us, 5GPa).")
            setup = spec.apply(setup, float(value))
        if fixed:
            setup.__check_init__()  # the setup's own checks of its values, which the updates above skip
        base.append(setup)
    if "C" in names:
        bare = [float(bare_speed_constant(s)) for s in base]
        if max(bare) - min(bare) > 1e-9 * max(bare):
            raise ValueError(
                "C is shared by all files but their beads differ (bare C from "
                f"{min(bare):.6g} to {max(bare):.6g}); fit mu_star instead, or one bead kind at a time."
            )
    instances = build_instances(names, experiments)
    nominal = [
        inst.spec.read(base[inst.experiment or 0]) if inst.spec.read is not None else inst.spec.default
        for inst in instances
    ]
    instances, rows = apply_priors(priors, instances, nominal)
    return Problem(experiments, instances, base, forward, rows)


def _problem_label(label: str, where: str) -> str:
    """A label written in argument `where` with a public or a previous parameter name (which
    warns), as the problem labels it (`eta_s` -> `eta`, `striker_velocity_m_s[run1]` ->
    `striker_velocity[run1]`); a label that names no parameter is kept, for the check that
    names it."""
    try:
        return resolve_label(label, where=where)
    except ValueError:
        return label


def initial_values(problem: Problem, start=None) -> np.ndarray:
    """Start values (SI) of the problem's parameters.

    From `start` (a dict keyed by parameter name, which sets every instance of it, or by
    instance label, a previous name warning; or a fit's `values`) where given; else eta, mu,
    C from the data (`fitting.start`); else the header's value (`spec.read`) or the spec's
    default.
    """
    if isinstance(start, LabelledValues):  # a fit's values: labelled by the library, in registry spelling
        start = dict(start)
    else:
        start = {_problem_label(key, "start"): value for key, value in dict(start or {}).items()}
    for key in start:
        if key not in problem.labels and key not in {inst.name for inst in problem.instances}:
            raise ValueError(
                f"start: {public_label(key)!r} is not a fitted parameter; fitted: "
                f"{', '.join(public_label(label) for label in problem.labels)}."
            )
    estimates = None  # from the data, only when a start value is needed from them
    values = []
    for inst in problem.instances:
        setup = problem.base_setups[inst.experiment if inst.experiment is not None else 0]
        if inst.label in start:
            value = start[inst.label]
        elif inst.name in start:
            value = start[inst.name]
        elif inst.name in ("eta", "mu", "C"):
            if estimates is None:
                estimates = start_values.data_estimates(
                    [e.trace for e in problem.experiments], problem.base_setups
                )
            value = estimates[inst.name]
        elif inst.spec.read is not None:
            value = inst.spec.read(setup)
        else:
            value = inst.spec.default
        values.append(float(value))
    return np.asarray(values)


# --- the optimisation ---------------------------------------------------------------------------
class _IterationReport:
    """Host-side progress of the optimiser: a `hertzchain.progress.Progress` note per iteration
    (at most every 0.5 s; none when `progress` is None), and the times of the first and the
    last iteration (`first`, `latest`: `time.perf_counter()`) for the fit's timings. Called
    with the iteration and the chi^2 of every row of the batch at its last accepted point."""

    def __init__(self, progress: Progress | None):
        self.progress = progress
        self.first = self.latest = None

    def __call__(self, step: int, chi2):
        self.latest = time.perf_counter()
        self.first = self.first or self.latest
        finite = np.asarray(chi2)[np.isfinite(chi2)]
        if self.progress is not None and finite.size:
            self.progress.note(f"iteration {step}, best chi^2 = {float(np.min(finite)):.6g}", throttle=True)


def fit(experiments, params=("eta_s", "mu", "C"), *, start=None, fixed=None, multistart: int = 1,
        seed: int = 0, max_steps: int = 100, tolerance: float = OPTIMUM_TOLERANCE,
        covariance: str = "auto", profile=(), profile_points: int = 13,
        forward: ForwardModel | None = None, progress: bool = True, throw: bool = True,
        priors=()) -> FitResult:
    """Fit chain parameters to trace files by Levenberg-Marquardt.

    **Arguments:**

    - `experiments`: trace file paths, `TraceFile`s or `Experiment`s (`fitting.data`).
    - `params`: parameter names (see `fitting.parameters.REGISTRY`): e.g. `("eta_s", "mu",
      "C")`, plus nuisances `striker_velocity_m_s`, `time_offset_s` (per file), `gain` (per
      channel). Here and in `start`, `fixed`, `profile` and `priors`, a previous name
      (`eta`) warns once (`fitting.parameters.ParameterNameWarning`).
    - `start`: name or label -> start value (SI); default: estimated from the data.
    - `fixed`: name -> value (SI) of global setup parameters held fixed.
    - `multistart`: number of starts run as one batch (the first is the data-derived one).
    - `seed`: random seed of the spread starts.
    - `max_steps`: optimiser iterations per start.
    - `tolerance`: the change of chi^2, in units of max(1, chi^2/dof), that counts (default
      `OPTIMUM_TOLERANCE`, 0.01: a move of 0.1 standard error). The optimiser tests for an
      optimum whenever an accepted step lowered chi^2 by less than that (or steps keep
      being rejected); a start has converged, and stops, when neither the Gauss-Newton step's
      prediction nor any fraction of that step (a kink of the stick-slip loss) lowers chi^2
      by as much (`_at_optimum`).
    - `covariance`: "auto", "noise", "residual" or "correlated" (see `fitting.uncertainty`).
    - `profile`: labels to compute profile-likelihood intervals for.
    - `forward`: a `ForwardModel` (custom simulator, model switches, time step).
    - `progress`: report iterations on stderr.
    - `throw`: raise `FitError` when no start converged (else return with `converged=False`).
    - `priors`: tolerances of parameters (`fitting.priors`, e.g. `"bead_youngs_pa=203GPa+-4GPa"`);
      each frees its parameter, and a normal one makes the optimum the maximum a posteriori
      point and the covariance the Laplace approximation with the prior included.

    **Returns:** `FitResult`.
    """
    began = time.perf_counter()
    if multistart < 1:
        raise ValueError(f"multistart must be >= 1, got {multistart}.")
    problem = make_problem(experiments, params, fixed=fixed, forward=forward, priors=priors)
    if covariance not in COVARIANCES:
        raise ValueError(f"covariance must be one of {', '.join(COVARIANCES)}; got {covariance!r}.")
    profile = tuple(_problem_label(label, "profile") for label in profile)
    for label in profile:
        if label not in problem.labels:
            raise ValueError(f"profile: {public_label(label)!r} is not fitted; fitted: "
                             f"{', '.join(map(public_label, problem.labels))}.")
    x0 = initial_values(problem, start)
    constants = tuple(jnp.asarray(a) for a in transform_arrays(problem.instances))
    z0 = to_unbounded(problem.instances, x0)
    points = _multistart_points(problem, z0, multistart, seed)
    p = len(problem.instances)
    report = _IterationReport(Progress(None, "fit", min_interval_s=0.5) if progress else None)
    solver = _make_solver()
    set_up = time.perf_counter()

    for attempt in range(2):
        z, ok, steps, chi2, best, residuals, jacobian = (np.asarray(a) for a in _run_least_squares(
            problem, constants, points, np.ones(points.shape, bool), points,
            max_steps=max_steps, solver=solver, tolerance=tolerance, report=report,
        ))
        best = int(best)
        x = np.asarray(_physical_values(constants, jnp.asarray(z[best])))
        coarse = problem.check_resolution(x)
        if not coarse or attempt == 1:
            break
        # the fitted setups need a finer time step than the one chosen at the start
        problem = problem.with_setups([problem.setup_at(x, e) for e in range(len(problem.experiments))])
        points = np.vstack([z[best][None], points[1:]])

    solved = time.perf_counter()
    converged = bool(ok[best])
    chi2_best = float(residuals @ residuals)
    dof = problem.n_fitted - p
    series, correlated = _correlated_series(problem)
    scale, covariance_reason = covariance_choice(covariance, chi2_best, dof, correlated)
    cov = covariance_from_jacobian(
        jacobian, problem.labels, chi2=chi2_best, dof=dof, scale=scale,
        score_covariance=correlated_score_covariance(jacobian, residuals, series) if scale == "correlated" else None)
    messages = identifiability_warnings(problem.instances, x, cov, problem.experiments)
    if coarse:
        messages.append(
            f"the fitted setups of {', '.join(coarse)} are resolved by fewer than half the asked "
            "steps per contact; results may carry time-step bias."
        )
    low, high = noise_band(dof)
    if dof > 0 and not low <= chi2_best / dof <= high:
        messages.append(covariance_reason + (
            " Look for a missing effect (hertzchain diagnose) or a wrong noise estimate."
            if chi2_best / dof > high else " Check the noise estimate (noise_std_n in the header)."))

    starts = []
    x_all = np.asarray(_physical_values(constants, jnp.asarray(z)))
    x_start = np.asarray(_physical_values(constants, jnp.asarray(points)))
    tolerance_chi2 = max(1.0, cov.variance_factor)
    for k in range(len(points)):
        with np.errstate(invalid="ignore", divide="ignore"):
            distance = np.abs(x_all[k] - x) / cov.stderr
        distance = np.where(np.isfinite(distance), distance, 0.0)
        agrees = bool(ok[k]) and chi2[k] - chi2[best] <= tolerance_chi2 and float(np.max(distance, initial=0)) < 2
        starts.append({
            "start": dict(zip(problem.labels, x_start[k])),
            "final": dict(zip(problem.labels, x_all[k])),
            "chi2": float(chi2[k]), "converged": bool(ok[k]), "steps": int(steps[k]),
            "agrees_with_best": agrees, "max_distance_sigma": float(np.max(distance, initial=0)),
        })
    others = [k for k in range(len(points)) if k != best and ok[k] and not starts[k]["agrees_with_best"]]
    if others:
        worst = max(others, key=lambda k: chi2[k])
        messages.append(
            f"{len(others)} of {len(points)} starts converged to other local minima (worst: chi^2 "
            f"{chi2[worst]:.6g} against the best {chi2[best]:.6g}, parameters up to "
            f"{starts[worst]['max_distance_sigma']:.3g} sigma away): the misfit has several minima "
            "(e.g. a pulse matched one period off); the best is kept."
        )
    failed = int(np.sum(~ok))
    if failed and converged:
        messages.append(f"{failed} of {len(points)} starts did not converge (ignored).")

    message = "converged" if converged else (
        f"no start reached an optimum within {max_steps} steps (best chi^2 = {chi2[best]:.6g} "
        f"after {int(steps[best])} steps, and a step still lowers it by more than "
        f"{tolerance:g} max(1, chi^2/dof)); raise max_steps, give better start values, or fit fewer parameters."
    )
    rms, whitened = _residual_rms(problem, residuals)
    profiles = {}
    for label in profile:
        profiles[label] = profile_likelihood(
            problem, x, label, cov, points=profile_points, max_steps=max_steps,
            chi2_min=chi2_best, batch=len(points), solver=solver, tolerance=tolerance,
        )
        failed_points = int(np.sum(~np.asarray(profiles[label]["converged"])))
        if failed_points:
            messages.append(f"profile of {label}: {failed_points} of {profile_points} re-fits did not reach "
                            "an optimum within max_steps; its intervals may be too wide there.")
    result = FitResult(
        labels=problem.labels,
        values=dict(zip(problem.labels, map(float, x))),
        stderr=dict(zip(problem.labels, map(float, cov.stderr))),
        units={inst.label: inst.spec.unit for inst in problem.instances},
        correlation=cov.correlation,
        covariance=cov.covariance,
        covariance_scale=scale,
        covariance_reason=covariance_reason,
        chi2=chi2_best,
        dof=dof,
        reduced_chi2=chi2_best / dof if dof > 0 else math.nan,
        residual_rms=rms,
        residual_rms_whitened=whitened,
        speed_constant=_speed_constant(problem, x, cov),
        converged=converged,
        message=message,
        n_steps=int(steps[best]),
        starts=starts,
        warnings=messages,
        identifiability={
            "singular_values": cov.singular_values,
            "condition_number": float(cov.singular_values[0] / cov.singular_values[-1])
            if cov.singular_values.size and cov.singular_values[-1] > 0 else math.inf,
            "weak_directions": cov.weak_directions,
        },
        profiles=profiles,
        problem=problem,
        x=x,
        residuals=np.asarray(residuals),
        elapsed_s=time.perf_counter() - began,
        stderr_stated_noise=dict(zip(problem.labels, map(float, (cov if scale == "noise" else covariance_from_jacobian(
            jacobian, problem.labels, chi2=chi2_best, dof=dof, scale="noise")).stderr))),
        timings={
            "set_up_s": set_up - began,
            # the optimiser's first step comes after the compilation and the start's evaluation
            "to_first_iteration_s": (report.first or solved) - set_up,
            "iterations_s": (report.latest or solved) - (report.first or solved),
            "final_jacobian_and_test_s": solved - (report.latest or solved),
            "covariance_and_profiles_s": time.perf_counter() - solved,
        },
    )
    if not converged and throw:
        raise FitError(message)
    for text in messages:
        warnings.warn(text, FitWarning, stacklevel=2)
    return result


def profile_likelihood(problem: Problem, x, label: str, cov: Covariance, *, points: int = 13,
                       span_sigma: float = 4.0, max_steps: int = 100, tolerance: float = OPTIMUM_TOLERANCE,
                       chi2_min: float | None = None, batch: int | None = None,
                       solver=None) -> dict:
    """Profile of chi^2 over one parameter, all others re-fitted at each value (one batch).

    The grid spans +-`span_sigma` standard errors (+-50 % when the standard error is not
    finite), clipped to the parameter's bounds. Intervals are where
    $\\Delta\\chi^2/s^2$ crosses 1 (68 %) and 3.84 (95 %), $s^2$ the covariance's
    variance factor. The re-fits run `batch` at a time (default: all at once), with
    `solver` (default: the fit's Levenberg-Marquardt for `tolerance`).
    """
    labels = list(problem.labels)
    i = labels.index(label)
    inst = problem.instances[i]
    constants = tuple(jnp.asarray(a) for a in transform_arrays(problem.instances))
    z_hat = to_unbounded(problem.instances, x)
    error = float(cov.stderr[i])
    value = float(x[i])
    width = error if np.isfinite(error) and error > 0 else 0.5 * max(abs(value), inst.spec.scale) / span_sigma
    grid = value + np.linspace(-span_sigma, span_sigma, points) * width
    low = inst.spec.lower + 1e-9 * (abs(inst.spec.lower) + inst.spec.scale * (inst.spec.space == "linear"))
    grid = np.clip(grid, low, inst.spec.upper * (1 - 1e-9))
    templates = np.repeat(z_hat[None], points, axis=0)
    for k, g in enumerate(grid):
        x_k = x.copy()
        x_k[i] = g
        templates[k] = to_unbounded(problem.instances, x_k)
    masks = np.ones(templates.shape, bool)
    masks[:, i] = False
    # run in batches of the fit's own batch size, so the compiled solver is reused
    batch = max(1, int(batch or points))
    chi2, ok = np.empty(points), np.empty(points, bool)
    for first in range(0, points, batch):
        rows = np.arange(first, first + batch) % points
        _, ok_k, _, chi2_k, _, _, _ = (np.asarray(a) for a in _run_least_squares(
            problem, constants, templates[rows], masks[rows], templates[rows], max_steps=max_steps,
            solver=solver or _make_solver(), tolerance=tolerance,
        ))
        count = min(batch, points - first)
        chi2[first:first + count], ok[first:first + count] = chi2_k[:count], ok_k[:count]
    chi2_min = float(np.min(chi2)) if chi2_min is None else min(chi2_min, float(np.min(chi2)))
    delta = chi2 - chi2_min
    return {
        "values": grid,
        "delta_chi2": delta,
        "converged": ok,
        "interval_68": profile_interval(grid, delta, cov.variance_factor, 1.0),
        "interval_95": profile_interval(grid, delta, cov.variance_factor, 3.84),
    }


def fit_datasets(problem: Problem, datasets, *, start=None, max_steps: int = 100,
                 tolerance: float = OPTIMUM_TOLERANCE, covariance: str = "noise") -> dict:
    """Fit the same problem to many data sets in one vmapped, once-compiled batch.

    For coverage studies (many noise seeds of one synthetic experiment) and for
    bootstrap-like checks. `datasets` is (B, n) in `Problem.data_vector` layout. Every
    data set starts from the same values (`start` dict, else `initial_values(problem)`).

    **Returns:** dict with `values` (B, p), `stderr` (B, p), `chi2` (B,), `converged` (B,)
    and `labels`.
    """
    datasets = np.asarray(datasets, dtype=float)
    if datasets.ndim != 2 or datasets.shape[1] != problem.n_residuals:
        raise ValueError(
            f"datasets must have shape (B, {problem.n_residuals}), got {datasets.shape}."
        )
    x0 = initial_values(problem, start)
    constants = tuple(jnp.asarray(a) for a in transform_arrays(problem.instances))
    z0 = np.repeat(to_unbounded(problem.instances, x0)[None], len(datasets), axis=0)
    z, ok, _, chi2, _, _, jacobians = (np.asarray(a) for a in _run_least_squares(
        problem, constants, z0, np.ones(z0.shape, bool), z0, max_steps=max_steps,
        solver=_make_solver(), tolerance=tolerance, data=datasets,
        batched_data=True,
    ))
    values = np.asarray(_physical_values(constants, jnp.asarray(z)))
    dof = problem.n_fitted - len(problem.instances)
    stderr = np.stack([
        covariance_from_jacobian(j, problem.labels, chi2=float(c), dof=dof, scale=covariance).stderr
        for j, c in zip(jacobians, chi2)
    ])
    return {"labels": problem.labels, "values": values, "stderr": stderr, "chi2": chi2, "converged": ok}
