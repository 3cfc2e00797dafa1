"""The test of an optimum, one rule for every fit (`fitting.fit.fit`, `fit_datasets`, profiles,
`fitting.least_squares.least_squares`): done when no step can move chi^2 by a statistically
meaningful amount."""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np

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
