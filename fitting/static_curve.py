"""The contact exponent of a chain from its static force-displacement curve.

A chain of identical contacts in series, each of the power law `laws.PowerLaw` (exponent n,
Hertz's at a reference overlap), compressed by a displacement Delta carries a force
F = kappa_eff delta_r^{3/2} (Delta/delta_r)^n: N contacts in series share Delta, so N and the
contacts' stiffness only set kappa_eff, and the exponent of the chain's curve is the contacts'.
`fit_static_exponent` fits n and kappa_eff to a measured curve (residuals in force, as a lab
fits F = A Delta^n) with the project's optimiser (`fitting.fit.least_squares`), the standard
errors from `hertzchain.covariance` scaled by the residuals' own scatter and by the
correlation of neighbouring steps of a slow ramp ((1 + rho)/(1 - rho) for lag-1
autocorrelation rho, as the driven fits do).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import jax
import jax.numpy as jnp
import numpy as np

from fitting.least_squares import least_squares
from fitting.uncertainty import ar1_inflation, lag1_autocorrelation
from hertzchain.covariance import gauss_newton_covariance
from hertzchain.laws import ContactConstants, PowerLaw

# Where n and the stiffness are measured against each other: the middle of a curve over
# about a micrometre (a fit's result does not depend on it, only the correlation of the two).
DEFAULT_REFERENCE_OVERLAP_M = 1e-6


@dataclass(frozen=True)
class StaticExponentFit:
    """The fit of a chain's static curve (`fit_static_exponent`).

    **Fields:** `exponent` n and `exponent_stderr`; `kappa_eff_n_m1p5` (the one contact
    equivalent to the chain in series, N/m^{3/2}) and its standard error; `prefactor` A of
    F = A Delta^n (N/m^n, the form a lab writes); `reference_overlap_m`; `rms_residual_n`;
    `lag1_correlation` of the residuals along the curve and `correlation_factor` the
    standard errors were scaled by (`exponent_stderr_white`: n's standard error without
    that factor, as for independent residuals); `points`; `steps`, `converged` (the optimiser's test of
    an optimum)."""

    exponent: float
    exponent_stderr: float
    exponent_stderr_white: float
    kappa_eff_n_m1p5: float
    kappa_eff_stderr: float
    prefactor: float
    reference_overlap_m: float
    rms_residual_n: float
    lag1_correlation: float
    correlation_factor: float
    points: int
    steps: int
    converged: bool

    def as_dict(self) -> dict:
        return {name: getattr(self, name) for name in self.__dataclass_fields__}


def chain_force_n(displacement_m, exponent, kappa_eff_n_m1p5, reference_overlap_m=DEFAULT_REFERENCE_OVERLAP_M):
    """Force (N) of a chain of power-law contacts compressed by `displacement_m` (m), as one
    contact of stiffness `kappa_eff_n_m1p5`: the law's own force (`laws.PowerLaw`)."""
    law = PowerLaw(exponent, reference_overlap_m)
    overlap = jnp.asarray(displacement_m, dtype=jnp.float64)
    return law.force(overlap, overlap, ContactConstants(jnp.asarray(kappa_eff_n_m1p5, dtype=jnp.float64)))


class _Residuals:
    """Force residuals of parameters x = (n, ln kappa_eff) for `least_squares`, in units of
    `scale_n` (N): whitened, so that the optimiser's test of an optimum reads chi^2 as it does
    for every fit."""

    def __init__(self, displacement_m, force_n, reference_overlap_m, scale_n):
        self.displacement = jnp.asarray(displacement_m, dtype=jnp.float64)
        self.force = jnp.asarray(force_n, dtype=jnp.float64)

        def residuals(x):
            return (chain_force_n(self.displacement, x[0], jnp.exp(x[1]), reference_overlap_m) - self.force) / scale_n

        self._residuals = jax.jit(residuals)
        self._jacobian = jax.jit(jax.jacfwd(residuals))

    def residuals(self, x):
        return np.asarray(self._residuals(jnp.asarray(x)))

    def linearize(self, x, columns):
        x = jnp.asarray(x)
        return np.asarray(self._residuals(x)), np.asarray(self._jacobian(x))[:, list(columns)]


def fit_static_exponent(displacement_m, force_n, *, reference_overlap_m: float = DEFAULT_REFERENCE_OVERLAP_M,
                        start_exponent: float = 1.5) -> StaticExponentFit:
    """Fit the contact exponent and the equivalent stiffness of a chain to its static curve.

    **Arguments:** `displacement_m` (m) and `force_n` (N), one entry per step of the ramp in
    the order recorded (the residuals' correlation is read along it); only points of positive
    displacement and force are fitted (a power law has neither below its contact);
    `reference_overlap_m`: delta_r of `laws.PowerLaw`; `start_exponent`: n to start from.

    **Returns:** `StaticExponentFit`."""
    displacement = np.asarray(displacement_m, dtype=float)
    force = np.asarray(force_n, dtype=float)
    if displacement.shape != force.shape or displacement.ndim != 1:
        raise ValueError(f"displacement_m and force_n must be 1-D of one length, got {displacement.shape} "
                         f"and {force.shape}")
    keep = (displacement > 0) & (force > 0) & np.isfinite(displacement) & np.isfinite(force)
    if keep.sum() < 3:
        raise ValueError(f"fit_static_exponent: {int(keep.sum())} points of positive displacement and force; "
                         "a curve needs at least 3")
    displacement, force = displacement[keep], force[keep]
    # start: the stiffness that puts the start exponent's curve through the median point
    middle = int(np.argsort(force)[force.size // 2])
    ratio = displacement[middle] / reference_overlap_m
    start = np.array([start_exponent, np.log(force[middle] / (reference_overlap_m**1.5 * ratio**start_exponent))])
    # the noise of the readings from their second differences along the ramp (6 sigma^2 for
    # white noise), the whitening of the residuals; their own scatter sets the errors below
    scale = max(float(np.std(np.diff(force, 2)) / np.sqrt(6.0)), 1e-9 * float(np.max(force)))
    model = _Residuals(displacement, force, reference_overlap_m, scale)
    result = least_squares(model, start, [0, 1])
    residual, jacobian = model.linearize(result.x, [0, 1])
    residual, jacobian = residual * scale, jacobian * scale
    dof = max(residual.size - 2, 1)
    scatter = float(np.sqrt(np.sum(residual**2) / dof))
    rho = lag1_autocorrelation(residual)
    factor = math.sqrt(ar1_inflation(rho))
    stderr = np.asarray(gauss_newton_covariance(jacobian, residual_std=scatter).stderr) * factor
    exponent, kappa = float(result.x[0]), float(np.exp(result.x[1]))
    return StaticExponentFit(
        exponent=exponent, exponent_stderr=float(stderr[0]), exponent_stderr_white=float(stderr[0] / factor),
        kappa_eff_n_m1p5=kappa, kappa_eff_stderr=float(kappa * stderr[1]),
        prefactor=kappa * reference_overlap_m ** (1.5 - exponent), reference_overlap_m=reference_overlap_m,
        rms_residual_n=float(np.sqrt(np.mean(residual**2))), lag1_correlation=rho, correlation_factor=factor,
        points=int(residual.size), steps=int(result.steps), converged=bool(result.converged))
