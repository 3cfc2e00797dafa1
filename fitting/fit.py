"""Least-squares fits of chain parameters to trace files with optimistix.

`fit(experiments, params=("eta", "mu", "C"))` minimises the sum of squared whitened
residuals (`fitting.model`) with Levenberg-Marquardt (`optimistix.LevenbergMarquardt`,
Jacobian by forward-mode differentiation of the solver), in the bounded transformed
coordinates of `fitting.parameters`. Several starts run as one `vmap`ped batch; the best
is kept and disagreement between starts is reported. Every fit -- `fit`, `fit_datasets`,
profiles and the host-driven `least_squares` of the diagnosis -- ends by one test of an
optimum (`_worth_testing`, `_at_optimum`, `OPTIMUM_TOLERANCE`): no step moves chi^2 by a
statistically meaningful amount. Standard errors, correlations, identifiability warnings and
the choice of covariance come from `fitting.uncertainty`; profile likelihoods on request.
"""

from __future__ import annotations

import dataclasses
import functools
import math
import sys
import time
import warnings

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx

from hertzchain import contact
from hertzchain.atomic import json_ready
from hertzchain.importer import DITHER_STEPS

from . import start as start_values
from .data import FitInputError, as_experiments
from .model import ForwardModel, Problem
from hertzchain.theory import DISCRETE_SPEED_FACTOR

from .parameters import (
    CONTINUUM_SPEED_FACTOR,
    bare_speed_constant,
    build_instances,
    from_unbounded,
    get_spec,
    parse_parameter_list,
    to_unbounded,
    transform_arrays,
)
from .priors import apply_priors, parse_priors, prior_names
from .uncertainty import (
    Covariance,
    COVARIANCES,
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
def make_problem(experiments, params=("eta", "mu", "C"), *, fixed=None,
                 forward: ForwardModel | None = None, priors=()) -> Problem:
    """Build the least-squares `Problem` for `params` on `experiments`.

    **Arguments:**

    - `experiments`: `Experiment`s (see `fitting.data`), `TraceFile`s or paths.
    - `params`: names from the registry (`fitting.parameters.REGISTRY`); experiment-scoped
      ones get one value per file, `gain` one per channel.
    - `fixed`: name -> value (SI) of global setup parameters held fixed at a value other than
      the header's (e.g. `{"mu": 0.19}`).
    - `forward`: a `ForwardModel` (custom solver / model switches, time-step choice).
    - `priors`: `fitting.priors` texts or `Prior`s (`"bead_youngs=203GPa+-4GPa"`); a
      parameter with a prior is fitted; a normal prior adds a residual row.
    """
    experiments = as_experiments(experiments)
    priors = parse_priors(priors)
    names = parse_parameter_list(tuple(parse_parameter_list(params)) + prior_names(priors))
    forward = forward or ForwardModel()
    fixed = dict(fixed or {})
    base = []
    for experiment in experiments:
        trace = experiment.trace
        overrides = {}
        if trace.striker_velocity_m_s is None:
            if "striker_velocity" not in names:
                raise FitInputError(
                    f"{experiment.label}: the file has no striker_velocity_m_s; add it to the header "
                    "or fit it (params ... ,striker_velocity)."
                )
            overrides["striker_velocity_m_s"] = start_values.estimate_striker_velocity(trace)
        setup = trace.setup(**overrides)
        for name, value in fixed.items():
            spec = get_spec(name)
            if spec.kind != "setup" or spec.scope != "global":
                raise ValueError(f"fixed: {name} is not a global setup parameter.")
            if name in names:
                raise ValueError(f"{name} is both fitted and fixed; choose one.")
            if not spec.in_bounds(float(value)):
                raise ValueError(f"fixed {name} = {float(value):g} {spec.unit}".rstrip() + " is outside its range "
                                 f"({spec.lower:g} to {spec.upper:g} {spec.unit}".rstrip() + f"); give {name} a value "
                                 "in that range, in SI units or with a unit (e.g. 2us, 5GPa).")
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


def initial_values(problem: Problem, start=None) -> np.ndarray:
    """Start values (SI) of the problem's parameters.

    From `start` (a dict keyed by parameter name, which sets every instance of it, or by
    instance label) where given; else eta, mu, C from the data (`fitting.start`); else the
    header's value (`spec.read`) or the spec's default.
    """
    start = dict(start or {})
    for key in start:
        if key not in problem.labels and key not in {inst.name for inst in problem.instances}:
            raise ValueError(
                f"start: {key!r} is not a fitted parameter; fitted: {', '.join(problem.labels)}."
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
    """Host-side progress of the optimiser: one line per iteration (at most every 0.5 s; none
    when `quiet`), and the times of the first and the last iteration (`first`, `latest`:
    `time.perf_counter()`) for the fit's timings. Called with the iteration and the chi^2 of
    every row of the batch at its last accepted point."""

    def __init__(self, label: str, stream=None, min_interval_s: float = 0.5, quiet: bool = False):
        self.label = label
        self.stream = sys.stderr if stream is None else stream
        self.min_interval_s = min_interval_s
        self.quiet = quiet
        self.start = time.perf_counter()
        self.last = -math.inf
        self.first = self.latest = None

    def __call__(self, step: int, chi2):
        self.latest = time.perf_counter()
        self.first = self.first or self.latest
        finite = np.asarray(chi2)[np.isfinite(chi2)]
        if self.quiet or self.latest - self.last < self.min_interval_s or not finite.size:
            return
        self.last = self.latest
        self.stream.write(f"{self.label}: iteration {step}, best chi^2 = {float(np.min(finite)):.6g}, "
                          f"{self.latest - self.start:.1f} s\n")
        self.stream.flush()


# --- the test of an optimum (one rule for every fit: `fit`, `fit_datasets`, profiles, `least_squares`)
# A fit with known noise is done when no step can move chi^2 by a statistically meaningful amount.
# At an optimum, moving the parameters by d standard errors (in the covariance's metric) raises
# chi^2 by d^2; so a change of chi^2 below OPTIMUM_TOLERANCE = 0.01 is a move of at most 0.1
# standard error of any parameter or combination, and a hundredth of the chi^2 distribution's own
# width for one degree of freedom (sqrt 2) -- nothing a standard error, an interval or a model
# comparison can see. Where the residuals are larger than the noise (chi^2/dof = s^2 > 1) the
# meaningful unit is s^2 (`_chi2_threshold`).
OPTIMUM_TOLERANCE = 0.01
# Fractions of the Gauss-Newton step tried by the test (`_at_optimum`): where the loss is only
# piecewise smooth (stick-slip friction) the step's prediction can promise a decrease no step delivers.
_LINE_FRACTIONS = np.asarray([1.0, 0.5, 0.25, 0.125, 0.0625, 0.03125])


def _chi2_threshold(chi2, dof, tolerance):
    """The change of chi^2 (dimensionless) that counts: `tolerance` s^2, with s^2 =
    max(1, chi^2/dof) the variance factor the residuals ask for when they exceed the noise."""
    return tolerance * jnp.maximum(1.0, chi2 / jnp.maximum(dof, 1))


def _worth_testing(previous, chi2, since_acceptance, threshold):
    """Whether to test for an optimum after an optimiser step: the step was accepted and
    lowered chi^2 from `previous` to `chi2` by less than `threshold`, or the last
    `_REJECTIONS` (2 x, ...) steps were rejected (at a kink of the loss every nearby step
    can be, while the trust region shrinks)."""
    accepted_small = (since_acceptance == 0) & (previous - chi2 < threshold)
    return accepted_small | ((since_acceptance > 0) & (since_acceptance % _REJECTIONS == 0))


# Rejected steps in a row after which `_worth_testing` asks for a test: each shrinks the
# optimiser's trust region by a factor 4 or more, so after 6 its steps are 4^-6 ~ 2e-4 as long.
_REJECTIONS = 6


def _gauss_newton_decrement(r, jac, mask):
    """Gauss-Newton's step on the free (`mask`) columns at residuals `r`, Jacobian `jac`, and
    the decrease of chi^2 it predicts."""
    free_jac = jnp.where(mask[None, :], jac, 0.0)
    step = jnp.linalg.lstsq(free_jac, r)[0]
    return step, jnp.sum((free_jac @ step) ** 2)


def _at_optimum(chi2, decrement, chi2_line, proposal, threshold):
    """The test of an optimum: chi^2 is finite and no step moves it by `threshold`. Either the
    Gauss-Newton step predicts less (`decrement`); or, on a loss with kinks where that
    prediction can promise what no step delivers, none of the fractions `_LINE_FRACTIONS` of
    that step lowers chi^2 by `threshold` (their chi^2: `chi2_line`) and the optimiser itself
    only proposes moves smaller than that (`proposal`: the chi^2 change its next step makes in
    the linear model, |J dz|^2; its trust region has shrunk to below a meaningful move, where
    far from an optimum a rugged loss can defeat the line of the Gauss-Newton step alone)."""
    best = jnp.min(jnp.where(jnp.isfinite(chi2_line), chi2_line, jnp.inf))
    kink = (chi2 - best < threshold) & (proposal < threshold)
    return jnp.isfinite(chi2) & ((decrement < threshold) | kink)


def _make_solver():
    """Levenberg-Marquardt; its own (Cauchy) termination is not used: every fit ends by
    `_worth_testing` and `_at_optimum` (or `max_steps`)."""
    return optx.LevenbergMarquardt(rtol=0.0, atol=0.0, norm=optx.rms_norm)


def _run_least_squares(problem: Problem, constants, templates, masks, starts, *, max_steps: int,
                       solver, tolerance: float, data=None, batched_data: bool = False, report=None):
    """Batch of LM solves over the rows of `starts` (B, p) in transformed coordinates.

    Coordinates where `masks` (B, p) is False are held at `templates` (their Jacobian
    columns are zero, so the damped steps leave them alone): this fixes a parameter for a
    profile without recompiling. Each row ends at an optimum (`_at_optimum`, `tolerance`
    as `fit`'s) or after `max_steps`. The host drives the loop, one compiled optimiser step
    of every row per call (`_advance_batch`), the test of an optimum compiled apart
    (`_test_batch`) and run when a row asks for it: no host callback inside a compiled
    program, so JAX's persistent compilation cache can keep them (`fitting.compilation_cache`),
    and `report` (`_IterationReport`) sees every iteration. Returns (z (B, p), success (B,),
    steps (B,), chi2 (B,), index of the kept start, its residuals (n,) and Jacobian (n, p)
    with respect to the physical values). `data`: measured samples in `Problem.data_vector`
    layout, one set for all rows or (with `batched_data`) one per row; then the Jacobians of
    all rows (B, n, p) are returned.
    """
    data = jnp.asarray(problem.data_vector() if data is None else data)
    common = (problem, constants, solver, int(max_steps), bool(batched_data), jnp.asarray(float(tolerance)),
              jnp.asarray(templates), jnp.asarray(masks, dtype=bool), data)
    init_batch, advance_batch, test_batch = _compiled_steps(problem.simulates_natively())
    carry = init_batch(*common, jnp.asarray(starts))
    while True:
        carry = advance_batch(*common, carry)
        worth, done = np.asarray(carry.worth), np.asarray(carry.done)
        if report is not None:
            report(int(np.max(np.asarray(carry.steps))), np.asarray(carry.chi2))
        if np.any(worth & ~done):
            carry = test_batch(*common, carry)
            done = np.asarray(carry.done)
        if np.all(done):
            break
    z, ok, steps, r, jac = (np.asarray(a) for a in (carry.z, carry.ok, carry.steps, carry.r, carry.jac))
    z = np.where(np.asarray(masks, dtype=bool), z, np.asarray(templates))
    chi2 = np.sum(r**2, axis=1)
    # the kept row: the best converged one (the best finite one if none converged)
    finite = np.where(np.isfinite(chi2), chi2, np.inf)
    best = int(np.argmin(np.where(ok, finite, np.inf) if np.any(ok) else finite))
    if batched_data:  # one Jacobian per data set
        return z, ok, steps, chi2, best, r[best], jac
    return z, ok, steps, chi2, best, r[best], jac[best]


# physical values of optimiser coordinates, (p,) or (rows, p): one compiled program, where
# `from_unbounded` run op by op compiles each of its operations apart (seconds of a cold start)
_physical_values = jax.jit(from_unbounded)

_OPTIONS = {"jac": "fwd"}
_NO_TAGS = frozenset()


class _Row(eqx.Module):
    """One row's optimisation between compiled calls: the point `z` (transformed
    coordinates), the optimiser's `state` (its arrays), `steps` taken, `chi2` of the last
    accepted point, whether it is `worth` testing, `done`,
    `ok` (at an optimum), and the residuals `r` and Jacobian `jac` (with respect to the
    physical values) where it was last tested."""

    z: jax.Array
    state: object
    steps: jax.Array
    chi2: jax.Array
    worth: jax.Array
    done: jax.Array
    ok: jax.Array
    r: jax.Array
    jac: jax.Array


def _row_functions(problem, constants, solver, template, mask, y):
    """The residuals in the optimiser's coordinates, the physical values and the solver's
    state of one row (`template`, `mask`: held coordinates; `y`: its data)."""
    args = (template, mask, y)
    f_struct = jax.ShapeDtypeStruct((problem.n_residuals,), jnp.float64)

    def residual_fn(z, args):
        template, mask, y = args
        return problem.residuals(from_unbounded(constants, jnp.where(mask, z, template)), y), None

    def physical(z):
        return from_unbounded(constants, jnp.where(mask, z, template))

    def fresh_state(z):
        """The solver's state at `z`: its arrays and its static part (the Jacobian's linear
        function, the same at every step)."""
        return eqx.partition(solver.init(residual_fn, z, args, _OPTIONS, f_struct, None, _NO_TAGS), eqx.is_array)

    return args, residual_fn, physical, fresh_state


def _batched(function, batched_data):
    def run(templates, masks, data, *rows):
        if templates.shape[0] == 1 and not batched_data:
            # one start: no vmap, whose batching of the optimiser's while loop costs seconds of tracing
            out = function(templates[0], masks[0], data, *(jax.tree_util.tree_map(lambda a: a[0], r) for r in rows))
            return jax.tree_util.tree_map(lambda a: a[None], out)
        return jax.vmap(function, in_axes=(0, 0, 0 if batched_data else None) + (0,) * len(rows))(
            templates, masks, data, *rows)
    return run


def _init_batch(problem, constants, solver, max_steps, batched_data, tolerance, templates, masks, data, starts):
    def one(template, mask, y, z0):
        _, _, _, fresh_state = _row_functions(problem, constants, solver, template, mask, y)
        z = jnp.where(mask, z0, template)
        state, _ = fresh_state(z)
        n, p = problem.n_residuals, z.size
        false = jnp.asarray(False)
        # typed as `_advance_batch` returns them (a weakly typed chi2 would retrace and recompile it)
        return _Row(z, state, jnp.asarray(0), jnp.asarray(jnp.inf, dtype=jnp.float64), false, false, false,
                    jnp.zeros(n), jnp.zeros((n, p)))

    return _batched(one, batched_data)(templates, masks, data, starts)


def _advance_batch(problem, constants, solver, max_steps, batched_data, tolerance, templates, masks, data, rows):
    """One optimiser step of every row that is not done and not waiting for its test."""
    def one(template, mask, y, row):
        args, residual_fn, _, fresh_state = _row_functions(problem, constants, solver, template, mask, y)
        dof = problem.n_fitted - jnp.sum(mask)
        _, static = fresh_state(row.z)

        def step(row):
            z, state, _ = solver.step(residual_fn, row.z, args, _OPTIONS, eqx.combine(row.state, static), _NO_TAGS)
            state = eqx.filter(state, eqx.is_array)
            chi2 = jnp.sum(state.f_info.residual**2)
            since = state.num_steps_since_acceptance
            steps = row.steps + 1
            worth = (_worth_testing(row.chi2, chi2, since, _chi2_threshold(chi2, dof, tolerance))
                     | ~jnp.all(jnp.isfinite(z)) | (steps >= max_steps))
            accepted = since == 0
            return dataclasses.replace(row, z=z, state=state, steps=steps, chi2=jnp.where(accepted, chi2, row.chi2),
                                       worth=worth)

        return jax.lax.cond(row.done | row.worth, lambda row: row, step, row)

    return _batched(one, batched_data)(templates, masks, data, rows)


def _test_batch(problem, constants, solver, max_steps, batched_data, tolerance, templates, masks, data, rows):
    """The test of an optimum (`_at_optimum`) of every row that asks for it (`worth`)."""
    def one(template, mask, y, row):
        _, _, physical, fresh_state = _row_functions(problem, constants, solver, template, mask, y)
        dof = problem.n_fitted - jnp.sum(mask)

        def test(row):
            z = row.z
            x = physical(z)
            r = problem.residuals(x, y)
            jac = jax.jacfwd(problem.residuals)(x, y)  # with respect to the physical values
            chi2 = jnp.sum(r**2)
            threshold = _chi2_threshold(chi2, dof, tolerance)
            jac_z = jnp.where(mask[None, :], jac @ jax.jacfwd(physical)(z), 0.0)
            step, decrement = _gauss_newton_decrement(r, jac_z, mask)
            # the chi^2 change of the optimiser's next step in the linear model
            proposal = jnp.sum((jac_z @ (row.state.y_eval - z)) ** 2)
            chi2_line = jax.lax.cond(
                decrement < threshold, lambda: jnp.full(_LINE_FRACTIONS.shape, chi2),
                lambda: jax.vmap(lambda t: jnp.sum(problem.residuals(physical(z - t * step), y) ** 2))(
                    _LINE_FRACTIONS))
            ok = _at_optimum(chi2, decrement, chi2_line, proposal, threshold)
            done = ok | (row.steps >= max_steps) | ~jnp.all(jnp.isfinite(z))
            # the optimiser only proposes moves too small to count, and a step of the test lowers
            # chi^2 by more (a kink): go on from there, the optimiser restarted
            finite = jnp.where(jnp.isfinite(chi2_line), chi2_line, jnp.inf)
            better = z - jnp.asarray(_LINE_FRACTIONS)[jnp.argmin(finite)] * step
            restart = ~done & (chi2 - jnp.min(finite) >= threshold) & (proposal < threshold)
            state = jax.tree_util.tree_map(lambda a, b: jnp.where(restart, a, b), fresh_state(better)[0], row.state)
            return dataclasses.replace(
                row, z=jnp.where(restart, better, z), state=state, worth=jnp.asarray(False), done=done, ok=ok,
                chi2=jnp.where(restart, jnp.inf, row.chi2), r=r, jac=jac)

        return jax.lax.cond(row.worth & ~row.done, test, lambda row: row, row)

    return _batched(one, batched_data)(templates, masks, data, rows)


# XLA's optimisation passes take most of the compilation of the steps above (seconds, each run
# of a command with a cold cache) and gain nothing where the simulation inside them is the C++
# kernel (`hertzchain.native`, an opaque call): what they would optimise is the interpolation
# of the traces and the optimiser's small linear algebra. Measured on the paper's 10-trace fit:
# the three steps' compilation 5.1 s -> 3.2 s, iterations unchanged, results identical. Where
# the JAX kernel runs inside, the passes stay on (without them its loop ran 10x slower).
_LIGHT_COMPILATION = {"xla_backend_optimization_level": 0}


@functools.cache
def _compiled_steps(light: bool):
    """`_init_batch`, `_advance_batch` and `_test_batch` compiled (`light`: without XLA's
    optimisation passes, for a simulation the C++ kernel runs)."""
    options = {"compiler_options": _LIGHT_COMPILATION} if light else {}
    return tuple(eqx.filter_jit(step, **options) for step in (_init_batch, _advance_batch, _test_batch))


# --- fits evaluated outside the compiled loop ---------------------------------------------------
# The width of the free block of `least_squares` is rounded up to a power of two, at least this,
# so that fits of different subsets share a compilation.
_MIN_WIDTH = 8
# Damping of `least_squares`'s first step relative to each free column's curvature (Marquardt's).
_START_DAMPING = 1e-3


@dataclasses.dataclass(frozen=True)
class LeastSquares:
    """One fit of some of the parameters (`least_squares`).

    **Fields:** `x` (p,) values (SI) at the end, the held ones unchanged; `chi2` the sum of
    squared weighted whitened residuals there; `steps` optimiser iterations; `converged`
    (`fit`'s test of an optimum, see its `tolerance`).
    """

    x: np.ndarray
    chi2: float
    steps: int
    converged: bool


# The loop runs on the host, one compiled optimistix step per iteration, and the model is
# evaluated between steps: evaluated inside the compiled loop (a `jax.pure_callback` running
# the caller's own compiled simulator), it deadlocked on a single CPU core, the callback holding
# the thread that the nested computation waits for. Each step of optimistix's Gauss-Newton
# family (Levenberg-Marquardt included) evaluates its function and Jacobian at one point only,
# `state.y_eval`, known before the step: the host evaluates the model there and the step sees
# the model's linearisation at that point (`_linearised`), exact where it is evaluated.


def _linearised(v, args):
    r, jac, at = args
    return r + jac @ (v - at), None


@eqx.filter_jit
def _lm_init(solver, v0, args):
    f_struct = jax.ShapeDtypeStruct(args[0].shape, args[0].dtype)
    return solver.init(_linearised, v0, args, _OPTIONS, f_struct, None, _NO_TAGS)


@eqx.filter_jit
def _lm_step(solver, v, state, args):
    v, state, _ = solver.step(_linearised, v, args, _OPTIONS, state, _NO_TAGS)
    return v, state, jnp.sum(state.f_info.residual**2), state.num_steps_since_acceptance


_decrement = jax.jit(_gauss_newton_decrement)


class _Scaled:
    """The caller's model in the optimiser's coordinates: v = (values - values0) scale on the
    free columns (padded to `width`), the held ones at `x_start`; rows multiplied by `weights`."""

    def __init__(self, model, x_start, free, width, weights):
        self.model, self.x_start, self.free, self.weights = model, x_start, free, weights
        self.values0 = np.zeros(width)
        self.values0[:len(free)] = x_start[free]
        self.scale = np.ones(width)
        self.bounds = None  # (lower, upper) (p,): hold columns on a bound (`held`)

    def values(self, v):
        return self.values0 + np.asarray(v) / self.scale

    def point(self, values):
        x = np.array(self.x_start, dtype=float)
        x[self.free] = values[:len(self.free)]
        return x

    def residuals(self, values):
        return self.weights * np.asarray(self.model.residuals(self.point(values)), dtype=float)

    def linearize(self, values):
        """Weighted residuals and Jacobian with respect to the (padded) values; with `bounds`,
        the columns of the parameters held on a bound zeroed (`held`)."""
        r, jac = self.model.linearize(self.point(values), self.free)
        full = np.zeros((np.size(r), self.values0.size))
        full[:, :len(self.free)] = jac
        r, full = self.weights * np.asarray(r, dtype=float), self.weights[:, None] * full
        if self.bounds is not None:
            full[:, self.held(values, full.T @ r)] = 0.0
        return r, full

    def held(self, values, gradient) -> np.ndarray:
        """Which (padded) columns sit on a bound with chi^2's descent, -`gradient`, pointing out."""
        lower, upper = (np.asarray(b, dtype=float)[self.free] for b in self.bounds)
        n = len(self.free)
        value = np.asarray(values)[:n]
        out = np.zeros(self.values0.size, dtype=bool)
        out[:n] = ((value >= upper) & (gradient[:n] < 0.0)) | ((value <= lower) & (gradient[:n] > 0.0))
        return out


def least_squares(model, x_start, free, *, weights=None, max_steps: int = 100,
                  tolerance: float = OPTIMUM_TOLERANCE, extrapolate: bool = False, bounds=None) -> LeastSquares:
    """Fit the parameters `free` (indices) from the values `x_start` (SI), the others held
    there, with `fit`'s solver and test of an optimum, on residuals a caller evaluates
    between the optimiser's compiled steps (one optimistix Levenberg-Marquardt step per
    iteration, driven from the host; see `_lm_step`).

    `model` gives the whitened residuals, `model.residuals(x)` (n,), and with their
    Jacobian, `model.linearize(x, columns)` -> (r (n,), J (n, len(columns))) with respect
    to `x[columns]`: a caller that keeps compiled models, caches and variants of its problem
    (`fitting.diagnosis`) evaluates them as it does elsewhere. The optimiser moves the
    values themselves (scaled by each column's norm at the start), not `fit`'s bounded
    transforms: bounds are the model's to apply (the diagnosis clips to them, as a
    projected Levenberg-Marquardt does), so that an optimum on a bound (a sensor read in the filter form, coupling 0) is
    reached and kept, where a transform's Gauss-Newton step from near one bound can leap to
    the other one and stay there. `weights` (n,): factors of the residuals (0 leaves a sample
    out, e.g. the end of a record; default 1). `tolerance`: as `fit`'s (chi^2,
    dimensionless). The free block is padded to a width of 8, 16, 32, ... so that fits of
    different subsets share a compilation; neither `tolerance` nor `weights` recompiles.
    A start that passes the test of an optimum's Gauss-Newton part ends the fit there with 0
    steps (`_start_is_optimum`); `max_steps=0` makes only that test.

    `bounds`: (lower, upper) of every parameter (p,), SI, where `model` clips to them. A free
    parameter on its bound whose descent (-J^T r) points out of the box is held for that
    linearisation (its Jacobian column zeroed for the optimiser and for the test of an
    optimum: the active set of a projected method), so that an optimum on a bound is reached
    and recognised; without, the optimiser kept proposing moves across the bound that the
    clipped model did not follow, and a diagnosis's sensor fits (coupling at its bound of 1)
    ended every refit at its step limit, unconverged.

    `extrapolate`: before the optimiser's proposed step is evaluated, go on along it (2, 4, ...
    `_EXTRAPOLATION_LIMIT` times its length; residuals only) while chi^2 falls, and restart the
    optimiser from the best point where it lies below the proposal by the test's threshold
    (each restart counts as a step). For residuals
    that are rough on a scale far below their trend (`fitting.driven`: lock-in curves whose
    sharp peaks move across the frequency grid), where the Jacobian is exact but the linear
    model holds only over a step much shorter than the way down, and a residual costs a tenth of
    a linearisation there.
    """
    x_start = np.array(x_start, dtype=float)
    free = [int(c) for c in free]
    weights = np.ones(np.size(model.residuals(x_start))) if weights is None else np.asarray(weights, float)
    if not free:
        r = weights * np.asarray(model.residuals(x_start))
        return LeastSquares(x_start, float(r @ r), 0, True)
    width = max(_MIN_WIDTH, 1 << (len(free) - 1).bit_length())
    mask = np.arange(width) < len(free)
    scaled = _Scaled(model, x_start, free, width, weights)
    # coordinates in which the Jacobian's columns all have the norm 1/sqrt(_START_DAMPING) at the
    # start: the optimiser damps with a multiple of the identity (1 at first), which is then
    # Marquardt's damping of each column by _START_DAMPING of its own curvature; parameters whose
    # sizes differ by orders of magnitude (a damping time in s beside a dashpot in N s/m) are
    # damped alike only in such coordinates
    r, whole = scaled.linearize(scaled.values0)
    scaled.bounds = bounds
    jac = whole if bounds is None else np.where(scaled.held(scaled.values0, whole.T @ r)[None, :], 0.0, whole)
    dof = int(np.count_nonzero(weights)) - len(free)
    if _start_is_optimum(r, jac, mask, dof, tolerance):
        return LeastSquares(x_start, float(r @ r), 0, True)
    # (the scales of every free column, those held on a bound included)
    scale = np.linalg.norm(whole, axis=0) * math.sqrt(_START_DAMPING)
    scaled.scale = np.where(np.isfinite(scale) & (scale > 0), scale, 1.0)
    solver = _make_solver()
    v = jnp.zeros(width)
    state = _lm_init(solver, v, (jnp.asarray(r), jnp.asarray(jac / scaled.scale), v))
    steps, previous, ok = 0, math.inf, False
    evaluated = np.zeros(width)  # where r and jac were evaluated, in the optimiser's coordinates

    def restart(better, evaluated_there: bool):
        # go on from the values `better`, the optimiser restarted there; `evaluated_there`: its
        # first step reuses the residuals and Jacobian of the restart (at the values the
        # optimiser's coordinates give), else it evaluates them again
        nonlocal v, r, jac, state, evaluated, previous
        v = jnp.asarray((better - scaled.values0) * scaled.scale)
        r, jac = scaled.linearize(scaled.values(v) if evaluated_there else better)
        if evaluated_there:
            evaluated = np.asarray(v)
        state = _lm_init(solver, v, (jnp.asarray(r), jnp.asarray(jac / scaled.scale), v))
        previous = math.inf

    chi2 = math.inf
    while steps < max_steps and not ok:
        at = np.asarray(state.y_eval)
        if extrapolate and steps and not np.array_equal(at, np.asarray(v)):
            further = _extrapolated(scaled, scaled.values(v), scaled.values(at), chi2,
                                    float(_chi2_threshold(chi2, dof, tolerance)))
            if further is not None:
                restart(further, evaluated_there=True)
                steps += 1
                continue
        if not np.array_equal(at, evaluated):  # (the start's, and a restart's, are evaluated already)
            r, jac = scaled.linearize(scaled.values(at))
            evaluated = at
        v, state, chi2, since = _lm_step(solver, v, state,
                                         (jnp.asarray(r), jnp.asarray(jac / scaled.scale), jnp.asarray(at)))
        steps += 1
        chi2, since = float(chi2), int(since)
        if not bool(np.all(np.isfinite(np.asarray(v)))):
            break
        worth = bool(_worth_testing(previous, chi2, since, float(_chi2_threshold(chi2, dof, tolerance))))
        if since == 0:
            previous = chi2
        if worth:
            ok, better = _host_optimum_test(scaled, scaled.values(v), scaled.values(state.y_eval), mask, dof,
                                            tolerance)
            if better is not None and steps < max_steps:
                # the optimiser only proposes moves too small to count, and a step of the test
                # lowers chi^2 by more (a kink): go on from there
                restart(better, evaluated_there=False)
    values = scaled.values(v)
    if not ok and 0 < max_steps <= steps and np.all(np.isfinite(values)):
        ok, _ = _host_optimum_test(scaled, values, scaled.values(state.y_eval), mask, dof, tolerance)
    r = scaled.residuals(values)
    return LeastSquares(scaled.point(values), float(r @ r), steps, bool(ok and np.all(np.isfinite(r))))


# The longest extrapolation of an accepted step (`least_squares`, `extrapolate`), in its lengths.
_EXTRAPOLATION_LIMIT = 64


def _extrapolated(scaled, start, proposed, chi2, threshold):
    """Along the optimiser's proposed step from the values `start` (chi^2 there `chi2`): chi^2
    at start + t (proposed - start), t = 1, 2, 4, ... `_EXTRAPOLATION_LIMIT`, t doubled while it
    falls; the values where it is lowest if t > 1 there and it lies below both the proposal's
    (t = 1) and `chi2` by `threshold`, else None (the optimiser then evaluates its proposal as
    it would)."""
    step = proposed - start
    at_proposal = best_chi2 = float(np.sum(scaled.residuals(proposed) ** 2))
    best, t = None, 2.0
    while t <= _EXTRAPOLATION_LIMIT:
        trial = float(np.sum(scaled.residuals(start + t * step) ** 2))
        if not trial < best_chi2:
            break
        best, best_chi2, t = start + t * step, trial, 2.0 * t
    return best if best is not None and min(at_proposal, chi2) - best_chi2 >= threshold else None


def _start_is_optimum(r, jac, mask, dof, tolerance) -> bool:
    """Whether no Gauss-Newton step from the start (residuals `r`, Jacobian `jac` there, free
    columns `mask`) would lower chi^2 by the test's threshold (`_at_optimum`): a fit started at
    its optimum (a refit from a saved result, a candidate effect that does not help) then ends
    there, on the linearisation every fit makes at its start, with 0 steps."""
    chi2 = float(r @ r)
    _, decrement = _decrement(jnp.asarray(r), jnp.asarray(jac), jnp.asarray(mask))
    return math.isfinite(chi2) and float(decrement) < float(_chi2_threshold(chi2, dof, tolerance))


def _host_optimum_test(scaled, values, proposed, mask, dof, tolerance):
    """`_at_optimum` at `values`, the model evaluated on the host (`least_squares`): (at an
    optimum, the best point of the line test where it lowers chi^2 by the threshold, else None);
    `proposed`: the optimiser's next point."""
    r, jac = scaled.linearize(values)
    chi2 = float(r @ r)
    threshold = float(_chi2_threshold(chi2, dof, tolerance))
    step, decrement = (np.asarray(a) for a in _decrement(jnp.asarray(r), jnp.asarray(jac), jnp.asarray(mask)))
    if float(decrement) < threshold:
        chi2_line = np.full(_LINE_FRACTIONS.shape, chi2)
    else:
        chi2_line = np.array([float(np.sum(scaled.residuals(values - t * step) ** 2))
                              for t in _LINE_FRACTIONS])
    finite = np.where(np.isfinite(chi2_line), chi2_line, np.inf)
    better = values - _LINE_FRACTIONS[int(np.argmin(finite))] * step
    proposal = float(np.sum((jac @ (np.asarray(proposed) - values)) ** 2))
    return (bool(_at_optimum(chi2, float(decrement), chi2_line, proposal, threshold)),
            better if chi2 - float(np.min(finite)) >= threshold and proposal < threshold else None)


def _multistart_points(problem: Problem, z0: np.ndarray, k: int, seed: int) -> np.ndarray:
    """`k` starting points: the data-derived start, then spread ones.

    Global parameters spread by up to a factor 3 (log and asinh parameters) or 3 scale units,
    except the speed constant C (and mu*), which the materials fix to a few %: +-5 %
    (a pulse arriving one width early or late at the far end of the chain); per-file
    velocities by 20 %, offsets by 3 us, gains by 10 %.
    """
    rng = np.random.default_rng(seed)
    points = [z0]
    for _ in range(k - 1):
        z = z0.copy()
        for i, inst in enumerate(problem.instances):
            if inst.name == "C":
                width = 0.05
            elif inst.name == "mu_star":
                width = 0.15 / inst.spec.scale
            elif inst.spec.scope == "global":
                width = 3.0 if inst.spec.space == "linear" else math.log(3.0)
            elif inst.name == "striker_velocity":
                width = 0.2
            elif inst.name == "time_offset":
                width = 3e-6 / inst.spec.scale
            else:
                width = 0.1
            z[i] = z0[i] + rng.uniform(-width, width)
        points.append(z)
    return np.asarray(points)


# --- results ---------------------------------------------------------------------------------------
@dataclasses.dataclass
class FitResult:
    """What a fit found.

    **Fields:**

    - `labels`: names of the fitted numbers (`eta`, `striker_velocity[run1]`, ...).
    - `values`, `stderr`: label -> value / standard error in SI units (stderr inf when the
      data cannot determine it).
    - `units`: label -> SI unit.
    - `correlation`: (p, p) correlation matrix in `labels` order; `covariance` likewise.
    - `covariance_scale`: "noise" (sigma known), "residual" (scaled by chi^2/dof) or
      "correlated" (the residuals' own sample-to-sample covariance, Newey-West);
      `stderr_stated_noise`: label -> the standard error the stated noise alone gives (the
      "noise" scale), beside `stderr` for comparison; `residuals`: the whitened residual
      vector at the optimum (`Problem.residuals` layout);
      `covariance_reason`: why, and whether chi^2/dof agrees with the noise estimate
      (`fitting.uncertainty.covariance_choice`).
    - `chi2`, `dof`, `reduced_chi2`: of the whitened residuals.
    - `residual_rms`: file label -> channel -> RMS residual in N; `residual_rms_whitened`
      likewise in units of the channel's sigma.
    - `speed_constant`: C of the fitted chain (discrete solitary waves, with standard
      error), Eq. 3's continuum value C_t (1+mu*)^(1/3), and mu*.
    - `converged`, `message`, `n_steps`: optimiser status of the kept start.
    - `starts`: one dict per start (start and final values, chi^2, converged, steps).
    - `warnings`: identifiability, bounds, multistart disagreement, resolution.
    - `profiles`: label -> profile likelihood (when asked for).
    - `problem`, `x`: the problem and the fitted vector (for predictions and plots).
    - `elapsed_s`, `timings`: wall time in all and by phase (set-up; compilation with the
      start's evaluation, until the first iteration; iterations; the final Jacobian and test
      of an optimum; covariance and profiles), s.
    """

    labels: tuple
    values: dict
    stderr: dict
    units: dict
    correlation: np.ndarray
    covariance: np.ndarray
    covariance_scale: str
    covariance_reason: str
    chi2: float
    dof: int
    reduced_chi2: float
    residual_rms: dict
    residual_rms_whitened: dict
    speed_constant: dict
    converged: bool
    message: str
    n_steps: int
    starts: list
    warnings: list
    identifiability: dict
    profiles: dict
    problem: Problem
    x: np.ndarray
    elapsed_s: float
    timings: dict = dataclasses.field(default_factory=dict)
    stderr_stated_noise: dict = dataclasses.field(default_factory=dict)
    residuals: np.ndarray | None = None

    def predictions(self) -> list[dict]:
        """Fitted model of every channel on the data's time axis, per file (N).

        Where every sample entered the fit, it is the data plus sigma times the whitened
        residuals at the optimum (`residuals`: the model the fit last evaluated there, to
        round-off, without a further simulation); otherwise the model is evaluated again."""
        problem = self.problem
        sigma = problem.sigma_vector()
        if self.residuals is None or not np.all(np.isfinite(sigma)):
            return problem.predictions(self.x)
        model = problem.data_vector() + sigma * np.asarray(self.residuals)[:sigma.size]
        return [{name: model[part] for name, part in parts.items()} for parts in problem.residual_slices()]

    def to_json(self) -> dict:
        """A JSON-ready dict (SI units; non-finite numbers as null)."""
        params = {
            label: {"value": json_ready(self.values[label]), "stderr": json_ready(self.stderr[label]),
                    "stderr_stated_noise": json_ready(self.stderr_stated_noise.get(label, self.stderr[label])),
                    "unit": self.units[label]}
            for label in self.labels
        }
        for key in ("C",):
            if key not in params:
                params[key] = {"value": json_ready(self.speed_constant["C"]),
                               "stderr": json_ready(self.speed_constant["C_stderr"]),
                               "unit": "m/s N^-1/6", "fitted": False}
        return {
            "params": params,
            "correlation": {
                "names": list(self.labels),
                "matrix": [[json_ready(c) for c in row] for row in np.asarray(self.correlation)],
            },
            "covariance_scale": self.covariance_scale,
            "covariance_reason": self.covariance_reason,
            "noise_band_reduced_chi2": list(noise_band(self.dof)),
            "chi2": json_ready(self.chi2),
            "dof": int(self.dof),
            "reduced_chi2": json_ready(self.reduced_chi2),
            "residual_rms_n": {k: {c: json_ready(v) for c, v in d.items()} for k, d in self.residual_rms.items()},
            "residual_rms_whitened": {
                k: {c: json_ready(v) for c, v in d.items()} for k, d in self.residual_rms_whitened.items()
            },
            "speed_constant": {k: json_ready(v) for k, v in self.speed_constant.items()},
            "converged": bool(self.converged),
            "message": self.message,
            "n_steps": int(self.n_steps),
            "starts": [
                {
                    "start": {k: json_ready(v) for k, v in s["start"].items()},
                    "final": {k: json_ready(v) for k, v in s["final"].items()},
                    "chi2": json_ready(s["chi2"]),
                    "converged": bool(s["converged"]),
                    "steps": int(s["steps"]),
                    "agrees_with_best": bool(s["agrees_with_best"]),
                }
                for s in self.starts
            ],
            "warnings": list(self.warnings),
            "identifiability": {
                "singular_values": [json_ready(v) for v in self.identifiability["singular_values"]],
                "condition_number": json_ready(self.identifiability["condition_number"]),
            },
            "profiles": {
                label: {
                    "values": [json_ready(v) for v in p["values"]],
                    "delta_chi2": [json_ready(v) for v in p["delta_chi2"]],
                    "converged": [bool(v) for v in p["converged"]],
                    "all_converged": bool(np.all(p["converged"])),
                    "interval_68": [json_ready(v) for v in p["interval_68"]],
                    "interval_95": [json_ready(v) for v in p["interval_95"]],
                }
                for label, p in self.profiles.items()
            },
            "noise_std_n": {
                e.label: {"source": e.noise_source, **{c: json_ready(s) for c, s in e.noise_std_n.items()}}
                for e in self.problem.experiments
            },
            "files": [e.trace.path or e.label for e in self.problem.experiments],
            "elapsed_s": json_ready(self.elapsed_s),
            "timings_s": {k: json_ready(v) for k, v in self.timings.items()},
        }


def _speed_constant(problem: Problem, x, cov: Covariance) -> dict:
    setup = problem.setup_at(x, 0)
    mu_star = float(setup.mu_star)
    bare = float(bare_speed_constant(setup))
    c = bare * (1 + mu_star) ** (1 / 3)
    error = math.nan
    labels = list(problem.labels)
    if "C" in labels:
        error = float(cov.stderr[labels.index("C")])
    elif "mu_star" in labels:
        error = float(cov.stderr[labels.index("mu_star")]) * c / (3 * (1 + mu_star))
    ratio = CONTINUUM_SPEED_FACTOR / DISCRETE_SPEED_FACTOR
    return {
        "C": c,
        "C_stderr": error,
        "C_continuum": c * ratio,
        "C_continuum_stderr": error * ratio,
        "mu_star": mu_star,
        "C_bare": bare,
    }


def _residual_rms(problem: Problem, residuals) -> tuple[dict, dict]:
    rms, whitened = {}, {}
    for experiment, slices in zip(problem.experiments, problem.residual_slices()):
        rms[experiment.label], whitened[experiment.label] = {}, {}
        for channel, part in slices.items():
            w = float(np.sqrt(np.mean(residuals[part] ** 2)))
            whitened[experiment.label][channel] = w
            rms[experiment.label][channel] = w * experiment.noise_std_n[channel]
    return rms, whitened


def _correlated_series(problem: Problem) -> tuple[list, str | None]:
    """Each fitted channel's residual rows with the lag over which its residuals may be
    correlated: the striker's Hertz collision time with bead 1 in samples (the duration of
    the impact, over which the model's pulse shape, and with it a converter's error of the
    moving signal, changes); and why the residuals are expected to be correlated (the
    channels recorded with less than `DITHER_STEPS` of analogue noise), or None."""
    series, coarse = [], []
    for experiment, slices in zip(problem.experiments, problem.residual_slices()):
        setup = experiment.trace.setup()
        striker, bead = float(setup.striker_mass_kg), float(setup.bead_mass_kg[0])
        duration = float(contact.collision_time(striker * bead / (striker + bead), float(setup.contact_kappa()[0]),
                                                float(setup.striker_velocity_m_s)))
        lags = max(1, round(duration / float(experiment.time_s[1] - experiment.time_s[0])))
        for channel, rows in slices.items():
            used = np.arange(rows.start, rows.stop)[experiment.used(channel)]
            series.append((used, lags))
            steps = experiment.analogue_noise_steps(channel)
            if steps is not None and steps < DITHER_STEPS:
                coarse.append(f"{experiment.label}:{channel} ({steps:.2f} step)")
    if not coarse:
        return series, None
    shown = ", ".join(coarse[:4]) + (f" and {len(coarse) - 4} more" if len(coarse) > 4 else "")
    return series, (f"{shown} recorded with analogue noise below {DITHER_STEPS:g} of a converter step, "
                    "where the converter's error of a moving signal is correlated from sample to sample")


def fit(experiments, params=("eta", "mu", "C"), *, start=None, fixed=None, multistart: int = 1,
        seed: int = 0, max_steps: int = 100, tolerance: float = OPTIMUM_TOLERANCE,
        covariance: str = "auto", profile=(), profile_points: int = 13,
        forward: ForwardModel | None = None, progress: bool = True, throw: bool = True,
        priors=()) -> FitResult:
    """Fit chain parameters to trace files by Levenberg-Marquardt.

    **Arguments:**

    - `experiments`: trace file paths, `TraceFile`s or `Experiment`s (`fitting.data`).
    - `params`: parameter names (see `fitting.parameters.REGISTRY`): e.g. `("eta", "mu", "C")`,
      plus nuisances `striker_velocity`, `time_offset` (per file), `gain` (per channel).
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
    - `priors`: tolerances of parameters (`fitting.priors`, e.g. `"bead_youngs=203GPa+-4GPa"`);
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
    for label in profile:
        if label not in problem.labels:
            raise ValueError(f"profile: {label!r} is not fitted; fitted: {', '.join(problem.labels)}.")
    x0 = initial_values(problem, start)
    constants = tuple(jnp.asarray(a) for a in transform_arrays(problem.instances))
    z0 = to_unbounded(problem.instances, x0)
    points = _multistart_points(problem, z0, multistart, seed)
    p = len(problem.instances)
    report = _IterationReport("fit", quiet=not progress)
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
