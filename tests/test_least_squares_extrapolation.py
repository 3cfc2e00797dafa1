"""`fitting.fit.least_squares(..., extrapolate=True)` on residuals whose Jacobian is exact but
rough: a linear trend in two parameters plus a small ripple of high frequency in their sum
(as lock-in curves whose sharp peaks move across a frequency grid, `fitting.driven`). The
ripple's slope inflates the Jacobian along (1, 1), so each Gauss-Newton step goes a fraction
of the way there, and the test of an optimum (the Gauss-Newton decrement) passes short of
the minimum. Going on along the proposed step must reach a lower chi^2, nearer the trend's
minimum, with several times fewer linearisations.
"""

import importlib

import numpy as np

fit_module = importlib.import_module("fitting.fit")

TRUTH = np.array([1.0, 2.0])
RIPPLE = 0.05  # ripple amplitude, in units of the residuals' standard deviation (1)


class _RoughModel:
    """r = A (x - TRUTH) + RIPPLE sin(w (x0 + x1)): 200 residuals, exact Jacobian; counts
    its linearisations and residual evaluations."""

    def __init__(self):
        rng = np.random.default_rng(4)
        self.a = rng.normal(size=(200, 2))
        self.w = rng.uniform(50.0, 100.0, size=200)
        self.linearisations = self.evaluations = 0

    def residuals(self, x):
        self.evaluations += 1
        return self.a @ (x - TRUTH) + RIPPLE * np.sin(self.w * (x[0] + x[1]))

    def linearize(self, x, columns):
        self.linearisations += 1
        ripple = RIPPLE * self.w * np.cos(self.w * (x[0] + x[1]))
        jac = self.a + ripple[:, None]
        return self.a @ (x - TRUTH) + RIPPLE * np.sin(self.w * (x[0] + x[1])), jac[:, list(columns)]


def _fit(extrapolate):
    model = _RoughModel()
    result = fit_module.least_squares(model, np.array([6.0, 4.0]), [0, 1], max_steps=400, extrapolate=extrapolate)
    return result, model


def test_extrapolation_reaches_the_optimum_with_fewer_linearisations():
    plain, plain_model = _fit(False)
    fast, fast_model = _fit(True)
    assert plain.converged and fast.converged
    # the plain optimiser crawls along (1, 1): each Gauss-Newton step goes a fraction of the way
    assert plain_model.linearisations > 40
    assert fast_model.linearisations * 3 < plain_model.linearisations
    # measured: chi^2 0.235 against 0.425 where the plain one stops, its test passing there
    assert fast.chi2 < plain.chi2 - 0.1
    # the ripple moves the minimum off the trend's by about RIPPLE / sqrt(200) in the sum, 0.004
    np.testing.assert_allclose(fast.x, TRUTH, atol=0.01)
    assert np.linalg.norm(fast.x - TRUTH) < np.linalg.norm(plain.x - TRUTH)
    # the residual evaluations it adds (a tenth of a linearisation each in `fitting.driven`)
    assert fast_model.evaluations < plain_model.linearisations


def test_extrapolation_off_is_the_plain_optimiser():
    """The default (`extrapolate=False`) evaluates no residual beyond the one that sizes the
    weights and the end's chi^2: the optimiser's path is its own."""
    _, model = _fit(False)
    assert model.evaluations == 2
