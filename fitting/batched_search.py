"""The compiled search: optimistix's Levenberg-Marquardt over a batch of starts (or of data
sets) in one compiled loop, stopped by `fitting.optimum`'s test; and the spread starts of a
multistart fit."""

from __future__ import annotations

import dataclasses
import functools
import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx

from .model import Problem
from .optimum import (
    _LINE_FRACTIONS,
    _at_optimum,
    _chi2_threshold,
    _gauss_newton_decrement,
    _worth_testing,
)
from .parameters import from_unbounded


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
