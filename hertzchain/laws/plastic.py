"""Elastic-plastic contact laws: Thornton's and Jackson-Green's. Both follow Hertz until
they yield and read the largest overlap so far (their history) afterwards; a contact of
infinite yield force (a sensor spring) or zero stiffness (a free end) stays Hertzian."""

from __future__ import annotations

import jax.numpy as jnp

from .. import contact
from .contact_law import AbstractContactLaw, ContactConstants


def _hertz_where_elastic(plastic, parts, overlap_m, kappa):
    """`parts` (force, energy, dissipated) where `plastic`, Hertz's elsewhere."""
    force, energy, dissipated = parts
    return (jnp.where(plastic, force, contact.hertz_force(overlap_m, kappa)),
            jnp.where(plastic, energy, contact.hertz_potential(overlap_m, kappa)),
            jnp.where(plastic, dissipated, 0.0))


class Thornton(AbstractContactLaw):
    """Thornton's elastic-plastic contact (`contact.thornton_contact`, J. Appl. Mech. 64,
    383, 1997): Hertz up to the yield force (the paper's mean-pressure estimate,
    `ContactConstants.yield_force_n`), a straight loading line beyond, Hertzian unloading
    of enlarged radius about a residual overlap."""

    has_history = True

    def parts(self, overlap_m, max_overlap_m, constants: ContactConstants):
        kappa = constants.kappa_n_m1p5
        plastic = jnp.isfinite(constants.yield_force_n)
        safe_yield = jnp.where(plastic, constants.yield_force_n, 1.0)
        return _hertz_where_elastic(plastic, contact.thornton_contact(overlap_m, max_overlap_m, kappa, safe_yield),
                                    overlap_m, kappa)

    def overlap_at_force(self, force_n, constants: ContactConstants):
        """Hertz's overlap (a chain's static preload is taken below the yield force)."""
        return contact.overlap_at_force(force_n, constants.kappa_n_m1p5)

    def native_rows(self, constants: ContactConstants) -> tuple:
        """Every contact's yield force (N)."""
        return (constants.yield_force_n,)


class JacksonGreen(AbstractContactLaw):
    """Jackson & Green's elastic-plastic contact of spheres (`contact.jackson_green_contact`,
    J. Tribol. 127, 343, 2005), which matches measured sphere-sphere curves: Hertz up to
    1.9 times the von Mises critical interference, their finite-element fit beyond with the
    hardness held at 2.84 $\\sigma_Y$ (`contact.JG_HARDNESS_RATIO`), Hertzian unloading from
    the flattened contact. Reads the reduced radius, Poisson ratio and yield stress of
    `ContactConstants`."""

    has_history = True

    def _plastic(self, constants: ContactConstants):
        return jnp.isfinite(constants.yield_force_n) & (constants.kappa_n_m1p5 > 0.0)

    def parts(self, overlap_m, max_overlap_m, constants: ContactConstants):
        kappa = constants.kappa_n_m1p5
        plastic = self._plastic(constants)
        safe_kappa = jnp.where(plastic, kappa, 1.0)
        safe_stress = jnp.where(plastic, constants.yield_stress_pa, 1.0)
        parts = contact.jackson_green_contact(overlap_m, max_overlap_m, safe_kappa, constants.reduced_radius_m,
                                              safe_stress, constants.poisson)
        return _hertz_where_elastic(plastic, parts, overlap_m, kappa)

    def overlap_at_force(self, force_n, constants: ContactConstants):
        """Hertz's overlap (a chain's static preload is taken below the yield force)."""
        return contact.overlap_at_force(force_n, constants.kappa_n_m1p5)

    def native_rows(self, constants: ContactConstants) -> tuple:
        """Every contact's yield force (N; where it yields at all), reduced radius (m) and
        Poisson ratio, then the yield stress (Pa) and the hardness ratio
        (`contact.JG_HARDNESS_RATIO`, the one `contact.jackson_green_contact` applies)."""
        return (constants.yield_force_n, constants.reduced_radius_m, constants.poisson, constants.yield_stress_pa,
                jnp.full((1,), contact.JG_HARDNESS_RATIO))

    def yield_force_n(self, constants: ContactConstants):
        """Where the law leaves Hertz, $\\kappa(1.9\\,\\delta_c)^{3/2}$ (`contact.jackson_green_yield_force`), N."""
        return contact.jackson_green_yield_force(constants.kappa_n_m1p5, constants.reduced_radius_m,
                                                 constants.yield_stress_pa, constants.poisson)
