"""A contact law in series with a layer: the same force through both, the overlaps added.

A contact whose force passes through a second compliant element (the piezo's cap, a
fixture, a rough surface layer) carries one force F through both, and its total overlap is
the sum of the two compressions, $\\delta = \\delta_{law}(F) + \\delta_L(F)$. The static
overlap is that sum (exact); the force at an overlap solves it for F. `AbstractInSeries`
does that once for every layer: it finds the inner law's overlap $d \\in [0, \\delta]$ with
$d + \\delta_L(F_{law}(d)) = \\delta$ by Newton's method kept inside a bracket (a fixed number
of iterations, `newton_iterations`), then takes one more Newton step that is differentiated:
at the root that step's derivative is the implicit function's, $\\partial d/\\partial\\theta =
-(\\partial h/\\partial\\theta)/h'$, so forward and reverse mode see the exact tangent
$1/(1/k_{law} + 1/k_L)$ and no derivative goes through the iterations.

`SeriesCompliance` is the linear spring, $\\delta_L = F/k_s$; `hertzchain.laws.RoughContact`
an asperity layer. The inner law must be one without a history (its history would be the
inner overlap, which the chain does not track).
"""

from __future__ import annotations

import abc

import equinox as eqx
import jax
import jax.numpy as jnp

from ..validation import check_positive_parameters
from .contact_law import AbstractContactLaw, ContactConstants

# Bracketed Newton iterations of the series split before its differentiated step. Started
# from the upper bound min(delta, delta_law(F_layer(delta))), 4 reach round-off at every
# stiffness ratio from 1e-8 to 1e8 (measured); twice that for margin.
NEWTON_ITERATIONS = 8


class AbstractInSeries(AbstractContactLaw):
    """The contact law `law` (a field of every subclass) in series with a layer of force-
    compression law $\\delta_L(F)$, which subclasses give by `layer_overlap_m`,
    `layer_force_n` (its inverse), `layer_compliance_m_n` ($d\\delta_L/dF$) and
    `layer_energy_j` (the energy it stores, $\\int F\\,d\\delta_L$)."""

    law: eqx.AbstractVar[AbstractContactLaw]

    def __check_init__(self):
        if not isinstance(self.law, AbstractContactLaw):
            raise ValueError(f"{type(self).__name__}: law must be a hertzchain.laws contact law, got {self.law!r}.")
        if self.law.has_history:
            raise ValueError(f"{type(self).__name__}: the inner law must have no history (Hertz, PowerLaw, ...); "
                             f"{type(self.law).__name__}'s would be the inner overlap, which is not tracked.")

    @abc.abstractmethod
    def layer_overlap_m(self, force_n):
        """The layer's compression at `force_n` (N, >= 0), m."""

    @abc.abstractmethod
    def layer_force_n(self, layer_overlap_m):
        """The layer's force at its compression (m, >= 0), N (may be inf: a rigid layer)."""

    @abc.abstractmethod
    def layer_compliance_m_n(self, force_n):
        """$d\\delta_L/dF$ at `force_n`, m/N."""

    @abc.abstractmethod
    def layer_energy_j(self, force_n):
        """Energy the layer stores at `force_n`, J."""

    def inner_overlap_m(self, overlap_m, constants: ContactConstants):
        """The inner law's share $d$ of the total overlap `overlap_m` (m; 0 where open), m."""
        total = jnp.maximum(overlap_m, 0.0)

        def residual(series, constants, d, total):
            force = series.law.force(d, d, constants)
            stiffness = series.law.tangent_stiffness(d, d, constants)
            return d + series.layer_overlap_m(force) - total, 1.0 + series.layer_compliance_m_n(force) * stiffness

        # the iterations on values only (no tangents go through them)
        series, fixed_constants, fixed = jax.lax.stop_gradient((self, constants, total))
        upper = jnp.minimum(fixed, series.law.overlap_at_force(series.layer_force_n(fixed), fixed_constants))

        def bracketed_newton(_, carry):
            d, low, high = carry
            value, slope = residual(series, fixed_constants, d, fixed)
            low = jnp.where(value < 0.0, d, low)
            high = jnp.where(value >= 0.0, d, high)
            newton = d - value / slope
            return jnp.where((newton >= low) & (newton <= high), newton, 0.5 * (low + high)), low, high

        d, _, _ = jax.lax.fori_loop(0, NEWTON_ITERATIONS, bracketed_newton, (upper, jnp.zeros_like(upper), upper))
        value, slope = residual(self, constants, d, total)
        return jnp.where(overlap_m > 0.0, d - value / slope, 0.0)

    def parts(self, overlap_m, max_overlap_m, constants: ContactConstants):
        d = self.inner_overlap_m(overlap_m, constants)
        force, energy, dissipated = self.law.parts(d, d, constants)
        return force, energy + self.layer_energy_j(force), dissipated

    def overlap_at_force(self, force_n, constants: ContactConstants):
        """$\\delta_{law}(F) + \\delta_L(F)$, exact, m."""
        return self.law.overlap_at_force(force_n, constants) + self.layer_overlap_m(force_n)


class SeriesCompliance(AbstractInSeries):
    """A contact law in series with a linear spring (a piezo's cap, a fixture, a sensor
    plate): $\\delta = \\delta_{law}(F) + c\\,F$, tangent stiffness
    $1/(1/k_{law} + c)$.

    **Arguments:**

    - `law`: the contact's own law (default `Hertz()`; no history).
    - `compliance_m_n`: c = 1/k_s, the spring's compliance, m/N (>= 0; 0: no spring). One
      value, or in a `DrivenChain` one per contact ((n + 1,), e.g. only at the driver).
    """

    law: AbstractContactLaw
    compliance_m_n: jax.Array

    def __init__(self, law: AbstractContactLaw | None = None, compliance_m_n=0.0):
        from .elastic import Hertz

        self.law = Hertz() if law is None else law
        self.compliance_m_n = jnp.asarray(compliance_m_n, dtype=jnp.float64)

    def __check_init__(self):
        check_positive_parameters("SeriesCompliance", (("compliance_m_n", self.compliance_m_n, "m/N, the spring's 1/k"),),
                             zero_ok=True)

    def layer_overlap_m(self, force_n):
        return self.compliance_m_n * force_n

    def layer_force_n(self, layer_overlap_m):
        rigid = self.compliance_m_n == 0.0
        return jnp.where(rigid, jnp.inf, layer_overlap_m / jnp.where(rigid, 1.0, self.compliance_m_n))

    def layer_compliance_m_n(self, force_n):
        return self.compliance_m_n + 0.0 * force_n

    def layer_energy_j(self, force_n):
        return 0.5 * self.compliance_m_n * force_n**2
