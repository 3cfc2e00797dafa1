"""Forces and energies of a chain model at given displacements and velocities.

Shared by the velocity-Verlet solver and the diffrax reference solver, so both integrate
exactly the same equations of motion: Eq. (1) of Job et al. with the viscoelastic term,
sensor springs, the wall contact and the static preload.
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp

from . import contact
from .chain import ChainModel


class ChainForces(NamedTuple):
    contact_total_n: jax.Array  # (n_contacts,) compression positive
    contact_elastic_n: jax.Array  # (n_contacts,)
    wall_total_n: jax.Array  # scalar
    wall_elastic_n: jax.Array  # scalar
    body_force_n: jax.Array  # (n_bodies,) total force on each body, +x towards the wall
    body_viscous_force_n: jax.Array  # (n_bodies,) the viscous part of it


def _net_force(contact_n, wall_n):
    """Force on each body from contact forces (compression positive) and the wall force."""
    pushed_forward = jnp.concatenate([jnp.zeros(1), contact_n])
    pushed_back = jnp.concatenate([contact_n, wall_n[None]])
    return pushed_forward - pushed_back


def chain_forces(model: ChainModel, displacement_m, velocity_m_s) -> ChainForces:
    """All forces of the chain, N. Displacements are measured from the initial positions."""
    overlap = displacement_m[:-1] - displacement_m[1:] + model.overlap0_m
    rate = velocity_m_s[:-1] - velocity_m_s[1:]
    hertz_elastic, hertz_total = contact.contact_force(overlap, rate, model.kappa, model.eta_s)
    spring = model.spring_n_m * overlap
    contact_total = jnp.where(model.is_spring, spring, hertz_total)
    contact_elastic = jnp.where(model.is_spring, spring, hertz_elastic)
    wall_elastic, wall_total = contact.contact_force(
        displacement_m[-1] + model.wall_overlap0_m, velocity_m_s[-1], model.wall_kappa, model.eta_s
    )
    external = jnp.zeros_like(displacement_m)
    external = external.at[1].add(model.first_bead_force_n).at[-1].add(model.last_body_force_n)
    body = _net_force(contact_total, wall_total) + external
    viscous = _net_force(contact_total - contact_elastic, wall_total - wall_elastic)
    return ChainForces(contact_total, contact_elastic, wall_total, wall_elastic, body, viscous)


def contact_potentials(model: ChainModel, displacement_m):
    """Elastic energy of each contact and of the wall contact, J: ((n_contacts,), scalar)."""
    overlap = displacement_m[:-1] - displacement_m[1:] + model.overlap0_m
    hertz = contact.hertz_potential(overlap, model.kappa)
    spring = 0.5 * model.spring_n_m * overlap**2
    wall = contact.hertz_potential(displacement_m[-1] + model.wall_overlap0_m, model.wall_kappa)
    return jnp.where(model.is_spring, spring, hertz), wall


def preload_potential(model: ChainModel, displacement_m):
    """Potential of the constant external preload forces, $-\\sum_i f_i u_i$, J."""
    return -(
        model.first_bead_force_n * displacement_m[1] + model.last_body_force_n * displacement_m[-1]
    )


def external_force_n(model: ChainModel):
    """Net constant external force on the chain (preload), N."""
    return model.first_bead_force_n + model.last_body_force_n


def initial_velocity(model: ChainModel):
    """Striker moving at the impact velocity, everything else at rest, m/s."""
    return jnp.zeros_like(model.mass_kg).at[0].set(model.striker_velocity_m_s)
