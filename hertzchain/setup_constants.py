"""The mechanical constants of a `ChainSetup`'s contacts and sensors.

Functions of a setup (its methods of the same names call them): the Hertz stiffness of the
contacts and of the wall, their yield forces and reduced radii (with the Poisson ratios and
the yield stress, the `laws.ContactConstants` the contact law reads), and the springs of the
embedded sensors. Contacts are numbered as in `hertzchain.chain`: contact 0 is the striker
on bead 1, contact K joins bead K and bead K+1, the wall contact comes last.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import jax
import jax.numpy as jnp

from . import contact, laws

if TYPE_CHECKING:
    from .chain import ChainSetup


def contact_kappa(setup: ChainSetup) -> jax.Array:
    """Hertz stiffness of contacts 0..N-1 (striker-bead 1, then bead-bead), N/m^{3/2}.

    Includes the thwarted-rotation factor $(1+\\mu^*)$.
    """
    radius = jnp.concatenate([setup.striker_radius_m[None], setup.bead_radius_m])
    youngs = jnp.concatenate([setup.striker_youngs_pa[None], setup.bead_youngs_pa])
    poisson = jnp.concatenate([setup.striker_poisson[None], setup.bead_poisson])
    bare = contact.kappa_sphere_sphere(
        radius[:-1], youngs[:-1], poisson[:-1], radius[1:], youngs[1:], poisson[1:]
    )
    return (1.0 + setup.mu_star) * bare


def wall_kappa(setup: ChainSetup) -> jax.Array:
    """Hertz stiffness of bead N on the flat wall, N/m^{3/2} (with $(1+\\mu^*)$)."""
    bare = contact.kappa_sphere_flat(
        setup.bead_radius_m[-1],
        setup.bead_youngs_pa[-1],
        setup.bead_poisson[-1],
        setup.wall_youngs_pa,
        setup.wall_poisson,
    )
    return (1.0 + setup.mu_star) * bare


def contact_constants(setup: ChainSetup) -> laws.ContactConstants:
    """What the chain gives its contacts 0..N-1 and the wall contact (last): Hertz
    stiffness (N/m^{3/2}), the paper's mean-pressure yield force (`contact.yield_force`,
    N), reduced radius (m), the Poisson ratio of the bead behind, the yield stress (Pa)."""
    radius = jnp.concatenate([setup.striker_radius_m[None], setup.bead_radius_m])
    theta = contact.theta(
        jnp.concatenate([setup.striker_youngs_pa[None], setup.bead_youngs_pa]),
        jnp.concatenate([setup.striker_poisson[None], setup.bead_poisson]),
    )
    beads = contact.yield_force(
        setup.bead_yield_stress_pa, radius[:-1], theta[:-1], radius[1:], theta[1:]
    )
    wall = contact.yield_force(
        setup.bead_yield_stress_pa,
        setup.bead_radius_m[-1],
        theta[-1],
        theta_b=contact.theta(setup.wall_youngs_pa, setup.wall_poisson),
    )
    return laws.ContactConstants(
        kappa_n_m1p5=jnp.concatenate([contact_kappa(setup), wall_kappa(setup)[None]]),
        yield_force_n=jnp.concatenate([beads, wall[None]]),
        reduced_radius_m=contact_reduced_radius_m(setup),
        poisson=jnp.concatenate([setup.bead_poisson, setup.bead_poisson[-1:]]),
        yield_stress_pa=setup.bead_yield_stress_pa,
    )


def contact_yield_force_n(setup: ChainSetup) -> jax.Array:
    """Yield force of contacts 0..N-1 and of the wall contact (last entry), N: the
    contact law's (`laws.AbstractContactLaw.yield_force_n`): the paper's mean-pressure
    estimate (`contact.yield_force`), or for `laws.JacksonGreen` the force at which that
    law leaves Hertz (`contact.jackson_green_yield_force`)."""
    return setup.contact_law.yield_force_n(contact_constants(setup))


def contact_reduced_radius_m(setup: ChainSetup) -> jax.Array:
    """Reduced radius $R^* = RR'/(R+R')$ of contacts 0..N-1 and of the wall contact (last,
    the bead's radius), m."""
    radius = jnp.concatenate([setup.striker_radius_m[None], setup.bead_radius_m])
    beads = 1.0 / (1.0 / radius[:-1] + 1.0 / radius[1:])
    return jnp.concatenate([beads, setup.bead_radius_m[-1:]])


def sensor_spring_n_m(setup: ChainSetup) -> jax.Array:
    """Spring stiffness $k_s$ of each embedded sensor, N/m (in `sensor_beads` order).

    From $\\omega_0^2 = k_s(1/m_+ + 1/m_-)$ with $m_+ = \\beta m$, $m_- = (1-\\beta) m$:
    $k_s = \\omega_0^2\\,\\beta(1-\\beta)\\,m$.
    """
    beads = jnp.asarray(setup.sensor_beads, dtype=int) - 1
    mass = setup.bead_mass_kg[beads]
    omega0 = 2.0 * jnp.pi * setup.sensor_f0_hz
    return omega0**2 * setup.sensor_beta * (1.0 - setup.sensor_beta) * mass
