"""Least squares evaluated outside the compiled loop: any model with `residuals` and
`linearize` (the diagnosis, the contact calibration, the driven fit), optimistix's
Levenberg-Marquardt step on the host, `fitting.optimum`'s test, optional extrapolation."""

from __future__ import annotations

import dataclasses
import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .batched_search import _NO_TAGS, _OPTIONS, _make_solver
from .optimum import (
    _LINE_FRACTIONS,
    OPTIMUM_TOLERANCE,
    _at_optimum,
    _chi2_threshold,
    _gauss_newton_decrement,
    _worth_testing,
)

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
