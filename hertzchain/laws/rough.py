"""A rough contact: an asperity layer in series with the bulk contact.

Greenwood & Williamson (Proc. R. Soc. A 295, 300, 1966) sum Hertzian asperities whose summit
heights are spread over the nominal contact; for an exponential distribution of heights of
scale $\\sigma$ the asperities carry $F = F_s\\,e^{-h/\\sigma}$ at a separation h of the mean
planes, a layer that stiffens in proportion to its load ($dF/dh = -F/\\sigma$). That law has
no first touch, so the layer's compression $\\delta_L = h_t - h$ is counted from a separation
$h_t$ where it carries the force $F_t$, and the force there is taken off so that the contact
opens at zero force:

$F_L = F_t\\,(e^{\\delta_L/\\sigma} - 1)$, i.e. $\\delta_L(F) = \\sigma\\ln(1 + F/F_t)$,

in series with the bulk law (`hertzchain.laws.AbstractInSeries`): $\\delta = \\delta_{bulk}(F) +
\\sigma\\ln(1 + F/F_t)$, the layer's stiffness $(F_t + F)/\\sigma$. At loads far above $F_t$ the
layer adds a compression that grows only as $\\sigma\\ln F$; as $\\sigma \\to 0$ it vanishes and
the law is the bulk law's.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from ..validation import check_positive_parameters
from .contact_law import AbstractContactLaw
from .series import AbstractInSeries


class RoughContact(AbstractInSeries):
    """The bulk contact law in series with a Greenwood-Williamson asperity layer of
    exponential summit heights (see the module docstring).

    **Arguments:**

    - `law`: the bulk law (default `Hertz()`; no history).
    - `roughness_m`: $\\sigma$, the scale of the summit heights, m (> 0).
    - `touch_force_n`: $F_t$, the layer's force scale at first touch, N (> 0): the layer's
      stiffness at zero load is $F_t/\\sigma$.
    """

    law: AbstractContactLaw
    roughness_m: jax.Array
    touch_force_n: jax.Array

    def __init__(self, law: AbstractContactLaw | None = None, roughness_m=1e-8, touch_force_n=0.1):
        from .elastic import Hertz

        self.law = Hertz() if law is None else law
        self.roughness_m = jnp.asarray(roughness_m, dtype=jnp.float64)
        self.touch_force_n = jnp.asarray(touch_force_n, dtype=jnp.float64)

    def __check_init__(self):
        check_positive_parameters("RoughContact", (("roughness_m", self.roughness_m, "m"),
                                              ("touch_force_n", self.touch_force_n, "N")))

    def layer_overlap_m(self, force_n):
        return self.roughness_m * jnp.log1p(jnp.maximum(force_n, 0.0) / self.touch_force_n)

    def layer_force_n(self, layer_overlap_m):
        return self.touch_force_n * jnp.expm1(jnp.minimum(layer_overlap_m / self.roughness_m, 700.0))

    def layer_compliance_m_n(self, force_n):
        return self.roughness_m / (self.touch_force_n + jnp.maximum(force_n, 0.0))

    def layer_energy_j(self, force_n):
        return self.roughness_m * force_n - self.touch_force_n * self.layer_overlap_m(force_n)
