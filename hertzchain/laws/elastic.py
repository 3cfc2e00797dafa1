"""Elastic contact laws without a history: Hertz's and a power law."""

from __future__ import annotations

import jax
import jax.numpy as jnp

from .. import contact
from .contact_law import AbstractContactLaw, ContactConstants


class Hertz(AbstractContactLaw):
    """Hertz's law $F = \\kappa\\,\\delta_+^{3/2}$ (`contact.hertz_force`), the paper's;
    tangent stiffness $\\tfrac32\\kappa\\delta^{1/2}$."""

    def parts(self, overlap_m, max_overlap_m, constants: ContactConstants):
        kappa = constants.kappa_n_m1p5
        return (contact.hertz_force(overlap_m, kappa), contact.hertz_potential(overlap_m, kappa),
                jnp.zeros_like(overlap_m))

    def overlap_at_force(self, force_n, constants: ContactConstants):
        return contact.overlap_at_force(force_n, constants.kappa_n_m1p5)


class PowerLaw(AbstractContactLaw):
    """$F = \\kappa\\,\\delta_r^{3/2}(\\delta_+/\\delta_r)^n$ (`contact.power_law_force`): a
    contact law of exponent n (non-ideal, rough or non-spherical contacts) equal to
    Hertz's at the reference overlap $\\delta_r$ whatever n, so that n and the stiffness
    stay apart; n = 3/2 is Hertz.

    **Arguments:**

    - `exponent`: n, between 1 and 3 (Hertz: 1.5).
    - `reference_overlap_m`: $\\delta_r$, m (default 10 um).
    """

    exponent: jax.Array
    reference_overlap_m: jax.Array

    def __init__(self, exponent=1.5, reference_overlap_m=1e-5):
        self.exponent = jnp.asarray(exponent, dtype=jnp.float64)
        self.reference_overlap_m = jnp.asarray(reference_overlap_m, dtype=jnp.float64)

    def parts(self, overlap_m, max_overlap_m, constants: ContactConstants):
        shape = (constants.kappa_n_m1p5, self.exponent, self.reference_overlap_m)
        return (contact.power_law_force(overlap_m, *shape), contact.power_law_potential(overlap_m, *shape),
                jnp.zeros_like(overlap_m))

    def overlap_at_force(self, force_n, constants: ContactConstants):
        return contact.overlap_at_force(force_n, constants.kappa_n_m1p5, self.exponent, self.reference_overlap_m)

    def native_rows(self, constants: ContactConstants) -> tuple:
        """The exponent and the reference overlap (m)."""
        return (self.exponent, self.reference_overlap_m)
