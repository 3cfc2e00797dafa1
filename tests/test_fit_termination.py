"""The fits' test of an optimum (`fitting.fit._at_optimum`) on a loss with kinks.

Data: a 10-bead steel chain with little track friction (mu = 0.02: beads stick and slip, so
chi^2 is only piecewise smooth in mu), two impacts, sensor in bead 4, contact 7 and the wall,
1 us sampling, 0.5 % noise. The same rule ends every fit (`fit`, `fit_datasets`, profiles,
`least_squares`): it must stop soon after chi^2 stops changing, at the values of a fit run to
a tolerance 10^4 times tighter, and a fit started at its optimum must say it is there.
"""

import importlib

import numpy as np
import pytest

import fitting
from fitting.synthetic import paper_setups, synthetic_traces

fit_module = importlib.import_module("fitting.fit")
PARAMS = ("eta_s", "mu", "C")


@pytest.fixture(scope="module")
def kinked_files():
    setups = paper_setups((0.1, 0.4), eta_s=2e-6, mu=0.02, mu_star=0.02, n_beads=10, sensor_beads=(4,))
    clean = synthetic_traces(setups, contacts=(7,), t_end_s=1.0e-3)
    sigma = [0.005 * max(np.max(v) for v in f.channels.values()) for f in clean]
    return synthetic_traces(setups, contacts=(7,), t_end_s=1.0e-3, noise_std_n=sigma, seed=3)


class _Recorder:
    """Stands in for the fit's progress report: chi^2 of the last accepted point after every
    optimiser step."""

    chi2: list = []

    def __init__(self, label, stream=None, min_interval_s=0.5, quiet=False):
        type(self).chi2 = []
        self.first = self.latest = None

    def __call__(self, step, chi2):
        type(self).chi2.append(float(np.min(chi2)))


@pytest.fixture(scope="module")
def default_fit(kinked_files):
    patch = pytest.MonkeyPatch()
    patch.setattr(fit_module, "_IterationReport", _Recorder)
    try:
        result = fitting.fit(kinked_files, PARAMS, progress=True, throw=False)
    finally:
        patch.undo()
    return result, list(_Recorder.chi2)


@pytest.mark.slow  # default-suite time; benchmarks/stopping_rule.py holds the rule on a second code path
def test_stops_soon_after_chi2_is_final_at_the_tight_fits_values(kinked_files, default_fit):
    result, history = default_fit
    assert result.converged, result.message
    threshold = fit_module.OPTIMUM_TOLERANCE * max(1.0, result.reduced_chi2)
    # history[k]: chi^2 after step k + 1; the first step after which it was final
    final_after = 1 + next(k for k, c in enumerate(history) if c - result.chi2 < threshold)
    assert len(history) == result.n_steps
    assert result.n_steps - final_after <= 8, (result.n_steps, final_after, history)
    tight = fitting.fit(kinked_files, PARAMS, tolerance=1e-6, max_steps=200, progress=False, throw=False)
    assert tight.converged and tight.chi2 <= result.chi2 + 1e-9
    for name in PARAMS:
        moved = abs(result.values[name] - tight.values[name]) / tight.stderr[name]
        assert moved < 0.01, (name, moved)


def test_a_fit_at_its_optimum_says_so_at_once(kinked_files, default_fit):
    result, _ = default_fit
    again = fitting.fit(kinked_files, PARAMS, start=result.values, progress=False, throw=False)
    assert again.converged, again.message
    assert again.n_steps <= 3
    assert abs(again.chi2 - result.chi2) < fit_module.OPTIMUM_TOLERANCE


@pytest.mark.slow  # default-suite time on 2 cores; `pytest -m slow` runs it
def test_the_steps_compiled_without_xla_passes_give_the_same_fit(kinked_files, default_fit):
    # The fit of `default_fit` ran with the steps `problem.simulates_natively()` chose; the
    # other compilation must reach the same optimum by the same steps (only XLA's
    # optimisation passes differ between them, not the arithmetic's order in the kernel).
    result, _ = default_fit
    light = result.problem.simulates_natively()
    patch = pytest.MonkeyPatch()
    patch.setattr(type(result.problem), "simulates_natively", lambda self: not light)
    try:
        other = fitting.fit(kinked_files, PARAMS, progress=False, throw=False)
    finally:
        patch.undo()
    assert other.converged and other.n_steps == result.n_steps
    for name in PARAMS:
        assert abs(other.values[name] - result.values[name]) < 1e-6 * result.stderr[name], name


def test_predictions_from_the_residuals_equal_the_model_evaluated_again(default_fit):
    result, _ = default_fit
    assert result.residuals is not None
    shortcut, evaluated = result.predictions(), result.problem.predictions(result.x)
    for mine, theirs in zip(shortcut, evaluated):
        for channel in theirs:
            scale = np.max(np.abs(theirs[channel]))
            np.testing.assert_allclose(mine[channel], theirs[channel], rtol=0, atol=1e-12 * scale)


class _LinearModel:
    """r = A x - b (300 residuals of unit noise, 3 parameters); counts its linearisations."""

    def __init__(self):
        rng = np.random.default_rng(8)
        self.a = rng.normal(size=(300, 3))
        self.b = self.a @ np.array([1.0, -2.0, 0.5]) + rng.normal(size=300)
        self.linearisations = 0

    def residuals(self, x):
        return self.a @ x - self.b

    def linearize(self, x, columns):
        self.linearisations += 1
        return self.a @ x - self.b, self.a[:, list(columns)]


def test_least_squares_started_at_its_optimum_ends_there_at_once():
    """The host-driven fit (`least_squares`: the diagnosis's and the driven fits') tests its
    start on the linearisation it makes there: at the optimum it ends with 0 steps, the start
    unchanged; a start 3 standard errors away is not taken for one."""
    model = _LinearModel()
    optimum = np.linalg.lstsq(model.a, model.b, rcond=None)[0]
    at = fit_module.least_squares(model, optimum, [0, 1, 2])
    assert at.converged and at.steps == 0 and model.linearisations == 1
    np.testing.assert_array_equal(at.x, optimum)
    stderr = np.sqrt(np.diag(np.linalg.inv(model.a.T @ model.a)))
    away = fit_module.least_squares(model, optimum + 3 * stderr * np.array([1, 0, 0]), [0, 1, 2])
    assert away.converged and away.steps > 0
    np.testing.assert_allclose(away.x, optimum, atol=0.1 * stderr.min())
    tested_only = fit_module.least_squares(model, optimum + 3 * stderr * np.array([1, 0, 0]), [0, 1, 2],
                                           max_steps=0)
    assert not tested_only.converged and tested_only.steps == 0


class _ClippedModel(_LinearModel):
    """`_LinearModel` evaluated at points clipped to a box (as the diagnosis's `_Bounded`),
    its Jacobian at the clipped point."""

    def __init__(self, lower, upper):
        super().__init__()
        self.lower, self.upper = lower, upper

    def residuals(self, x):
        return super().residuals(np.clip(x, self.lower, self.upper))

    def linearize(self, x, columns):
        return super().linearize(np.clip(x, self.lower, self.upper), columns)


def test_least_squares_ends_at_an_optimum_on_a_bound():
    """A box whose upper bound on the first parameter cuts off the free optimum (by 5
    standard errors): with `bounds`, the fit ends converged on that bound in a few steps
    (measured 3), with the others at their optimum given it (the least squares of the
    remaining columns, to 1e-6 of their standard errors; measured 6e-7). On the clipped model
    without `bounds` the optimiser kept proposing steps across the bound that the model did
    not follow: 14 steps, and it stopped 0.11 standard errors from that optimum."""
    reference = _LinearModel()
    optimum = np.linalg.lstsq(reference.a, reference.b, rcond=None)[0]
    stderr = np.sqrt(np.diag(np.linalg.inv(reference.a.T @ reference.a)))
    lower, upper = np.full(3, -np.inf), np.full(3, np.inf)
    upper[0] = optimum[0] - 5 * stderr[0]
    start = optimum - 2 * stderr  # inside the box
    bounded = fit_module.least_squares(_ClippedModel(lower, upper), start, [0, 1, 2], bounds=(lower, upper))
    assert bounded.converged and bounded.steps <= 5
    x = np.clip(bounded.x, lower, upper)
    assert x[0] == upper[0]
    rest = np.linalg.lstsq(reference.a[:, 1:], reference.b - reference.a[:, 0] * upper[0], rcond=None)[0]
    np.testing.assert_allclose(x[1:], rest, rtol=0, atol=1e-6 * stderr[1:].min())
    unbounded = fit_module.least_squares(_ClippedModel(lower, upper), start, [0, 1, 2], max_steps=40)
    assert unbounded.steps > 10
    assert np.max(np.abs(np.clip(unbounded.x, lower, upper)[1:] - rest) / stderr[1:]) > 0.05
