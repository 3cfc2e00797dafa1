"""The evaluator of a diagnosis's problems: residuals and Jacobian columns on the cheapest
equivalent model, bounded for the optimiser, and how a fit ended."""

from __future__ import annotations

import math
import time

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from ..fit import LeastSquares
from ..model import Problem, residuals_and_jacobian


class _Evaluator:
    """Whitened residuals (alone, cheap: from the model vector, `model`, which also gives the
    predictions) and with the Jacobian (one forward-mode pass per simulator parameter) of one
    problem, with small caches, counters and timers.

    With `elastic` (the same problem on Hertz contacts) and `plastic_columns`, points
    where those strengths are all 0 are evaluated on `elastic`: the same numbers there
    (an infinite yield force), at a quarter of the cost of the elastic-plastic contact law.
    With `power` (power-law contacts) and `power_columns`, points where the exponent's shift
    is not 0 are evaluated on `power` (compiled on first use).
    With `twins` (each of those problems -> the same with rigid sensor beads and without the
    dashpot effect, which the C++ kernel runs: `fitting.effects.EffectsSimulation`; the
    problems themselves run the batched JAX kernel), `dashpot_twins` (the same with the
    dashpot effect: its term costs every run, so it has a twin of its own),
    `compliance_columns` (`sensor_coupling`, `sensor_rate`) and `dashpot_column`, points where
    a twin gives the model and the derivatives asked for are evaluated on it (`twin_exact`):
    the same numbers to round-off, several times faster.
    """

    def __init__(self, problem: Problem, elastic: Problem | None = None, plastic_columns=(),
                 power: Problem | None = None, power_columns=(), twins: dict | None = None,
                 dashpot_twins: dict | None = None, compliance_columns=(), dashpot_column: int | None = None):
        self.problem = problem
        self.elastic = elastic
        self.plastic_columns = np.asarray(plastic_columns, dtype=int)
        self.power = power
        self.power_columns = np.asarray(power_columns, dtype=int)
        self.twins = twins or {}
        self.dashpot_twins = dashpot_twins or {}
        self.compliance_columns = tuple(int(c) for c in compliance_columns)
        self.dashpot_column = dashpot_column
        self.calls = 0
        self.residual_calls = 0
        self.seconds = 0.0
        self._cache: dict = {}
        self._model_cache: dict = {}
        self._whitening = None  # (data, sigma) of the residuals, read from `problem` at first use

    def __call__(self, x, columns=None):
        """(r, J) at x; with `columns`, only those columns of J are computed (others NaN)."""
        key = np.asarray(x, dtype=float).tobytes()
        wanted = None if columns is None else tuple(int(c) for c in columns)
        for cached in ((key, None), (key, wanted)):
            if cached in self._cache:
                return self._cache[cached]
        began = time.perf_counter()
        self.calls += 1
        x = np.asarray(x, dtype=float)
        r, jac = residuals_and_jacobian(self.problem_at(x, range(x.size) if wanted is None else wanted), x, wanted)
        if len(self._cache) > 6:
            self._cache.pop(next(iter(self._cache)))
        self._cache[(key, wanted)] = (r, jac)
        self.seconds += time.perf_counter() - began
        return r, jac

    def law_at(self, x) -> Problem:
        """The contact law's problem at `x`: `elastic` where no contact can yield, `power` where
        the contact exponent differs from Hertz's (plasticity, built on Hertz contacts,
        takes precedence where both are on)."""
        x = np.asarray(x)
        if self.elastic is None or np.any(x[self.plastic_columns] > 0):
            return self.problem
        if self.power is not None and np.any(x[self.power_columns] != 0):
            return self.power
        return self.elastic

    def twin_exact(self, x, columns, *, dashpot: bool = False) -> bool:
        """Whether a twin (rigid sensor beads; `dashpot`: with the dashpot effect, else
        without) gives the model at `x` and its derivatives in `columns`: the sensors'
        compliance c x rate is 0 there, and so is its derivative in each of `columns` (in c:
        the rate; in the rate: c); without the dashpot, its strength is 0 and its derivative
        not asked for."""
        if not dashpot and self.dashpot_column is not None and (
                x[self.dashpot_column] != 0.0 or self.dashpot_column in columns):
            return False
        if not self.compliance_columns:
            return True
        coupling, rate = self.compliance_columns
        c, f = float(x[coupling]), float(x[rate])
        return c * f == 0.0 and not (coupling in columns and f != 0.0) and not (rate in columns and c != 0.0)

    def problem_at(self, x, columns=()) -> Problem:
        """The problem that evaluates the model at `x` and its derivatives in `columns`: the
        law's (`law_at`), on a twin where one is exact (the one without the dashpot first)."""
        law = self.law_at(x)
        x, columns = np.asarray(x), {int(c) for c in columns}
        if law in self.twins and self.twin_exact(x, columns):
            return self.twins[law]
        if law in self.dashpot_twins and self.twin_exact(x, columns, dashpot=True):
            return self.dashpot_twins[law]
        return law

    def off_variant(self, x, columns) -> list[int]:
        """The columns of `columns` that switch on a variant of the law which is off at `x`
        (the contact exponent and stiffness with Hertz contacts evaluated, the yield force
        with Hertz contacts): where such a column is 0 in the Jacobian at `x`, it is for
        want of the variant, not the derivative of the law it switches on."""
        law = self.law_at(x)
        missing = set()
        if law is not self.problem:
            missing.update(int(c) for c in self.plastic_columns)
        if self.power is not None and law is not self.power:
            missing.update(int(c) for c in self.power_columns)
        return [int(c) for c in columns if int(c) in missing]

    def model(self, x) -> np.ndarray:
        """The model of every fitted channel at `x`, concatenated as the residuals (N), on the
        cheapest equivalent problem (`problem_at`): one compiled function per problem serves the
        residuals and the predictions (`locate`'s windows)."""
        key = np.asarray(x, dtype=float).tobytes()
        if key not in self._model_cache:
            began = time.perf_counter()
            self.residual_calls += 1
            model = np.asarray(_model_vector(self.problem_at(x), jnp.asarray(np.asarray(x, dtype=float))))
            if len(self._model_cache) > 32:
                self._model_cache.pop(next(iter(self._model_cache)))
            self._model_cache[key] = model
            self.seconds += time.perf_counter() - began
        return self._model_cache[key]

    def residuals(self, x):
        """Whitened residuals at `x`, (model - data) / sigma as `Problem.residuals` forms them
        (0 for samples left out, whose sigma is inf); from a Jacobian's evaluation where one
        was made there."""
        key = np.asarray(x, dtype=float).tobytes()
        for (cached, _), (r, _) in self._cache.items():
            if cached == key:
                return r
        if self._whitening is None:
            if self.problem.priors:
                raise ValueError("_Evaluator: a diagnosis's problem has no priors (its residuals are the data's).")
            self._whitening = (self.problem.data_vector(), self.problem.sigma_vector())
        data, sigma = self._whitening
        return (self.model(x) - data) / sigma

    def predictions(self, x) -> list[dict]:
        """The model at `x` per experiment, channel -> values on the data's times (N), as
        `Problem.predictions` gives them, from `model`."""
        model = self.model(x)
        return [{name: model[part] for name, part in parts.items()} for parts in self.problem.residual_slices()]


class _Bounded:
    """The evaluator as `fitting.fit.least_squares` sees it: at points clipped to the bounds
    (`_Search.lower`, `upper`: the registry's, one-sided strengths from 0), with the Jacobian
    at the clipped point, so that a fit can leave a bound again (a projected
    Levenberg-Marquardt); the fits' end points are clipped too (`_Search.fit`)."""

    def __init__(self, evaluate: _Evaluator, lower, upper):
        self.evaluate = evaluate
        self.lower = lower
        self.upper = upper

    def residuals(self, x):
        return self.evaluate.residuals(np.clip(x, self.lower, self.upper))

    def linearize(self, x, columns):
        """(r, J[:, columns]) at x: the residuals and the Jacobian columns `columns` only."""
        r, jac = self.evaluate(np.clip(x, self.lower, self.upper), columns)
        return r, jac[:, list(columns)]


# XLA's options for the model vector's compilation: LLVM without its optimisation passes. The
# simulation runs in the native kernel (compiled once, by the C++ compiler); what XLA compiles
# here is the glue around it (parameter mapping, the sensors' filter, interpolation onto the
# data's times), compiled once per variant of the law and run a few dozen times: measured on the
# 15-bead brass chain's elastic-plastic twin, the compilation took 2.9 s of CPU instead of 4.2 s
# and a run 0.016 s as before, the model equal to the last bit but in a denormal.
_COMPILER_OPTIONS = {"xla_backend_optimization_level": 0}


@eqx.filter_jit(compiler_options=_COMPILER_OPTIONS)
def _model_vector(problem, x):
    return problem.model_vector(x)


def _rank(result: LeastSquares) -> float:
    """A fit's chi^2 for choosing the best of several; a non-finite one ranks last."""
    return result.chi2 if math.isfinite(result.chi2) else math.inf


def _status(result: LeastSquares) -> dict:
    """How a fit ended, for the report: `converged` (`fitting.fit`'s test of an optimum), `steps`."""
    return {"converged": bool(result.converged), "steps": int(result.steps)}
