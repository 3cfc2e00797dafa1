"""Forces and energies of a chain model at given displacements and velocities.

Shared by the velocity-Verlet solver and the diffrax reference solver, so both integrate
exactly the same equations of motion: Eq. (1) of Job et al. with the viscoelastic term,
sensor springs, the wall contact and the static preload.
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp

from . import contact, laws
from .chain import ChainModel
from .compliant_sensor import shortened_by_model


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


def overlaps(model: ChainModel, displacement_m, sensor_force_n=None):
    """Overlaps of the internal contacts and of the wall contact, m: ((n_contacts,), scalar).

    `sensor_force_n`: forces of the model's compliant sensors, which shorten their beads by
    their compliance times the force beyond the preload's (None: at the preload's)."""
    contacts = displacement_m[:-1] - displacement_m[1:] + model.overlap0_m
    if model.compliant is not None and sensor_force_n is not None:
        contacts = shortened_by_model(model, sensor_force_n - model.first_bead_force_n, contacts)
    return contacts, displacement_m[-1] + model.wall_overlap0_m


def initial_max_overlap(model: ChainModel):
    """Largest overlaps before the impact (the preload's), contacts then wall, m."""
    contacts, wall = overlaps(model, jnp.zeros_like(model.mass_kg))
    return jnp.concatenate([contacts, wall[None]])


def contact_constants(model: ChainModel) -> laws.ContactConstants:
    """What the model gives its contact law, (n_contacts + 1,) arrays (wall last): Hertz
    stiffness and, for elastic-plastic laws, yield force, reduced radius, Poisson ratio and
    yield stress (an infinite yield force or a zero stiffness keeps a contact elastic:
    sensor springs, a free end)."""
    kappa = jnp.concatenate([model.kappa, model.wall_kappa[None]])
    if not model.contact_law.has_history:
        return laws.ContactConstants(kappa)
    return laws.ContactConstants(kappa, jnp.concatenate([model.yield_force_n, model.wall_yield_force_n[None]]),
                                 model.reduced_radius_m, model.contact_poisson, model.yield_stress_pa)


def _elastic_parts(model: ChainModel, displacement_m, max_overlap_m, sensor_force_n=None):
    """Overlap (m), elastic force (N), stored energy (J) and plastic dissipation (J) of every
    contact and of the wall (last)."""
    contacts, wall = overlaps(model, displacement_m, sensor_force_n)
    overlap = jnp.concatenate([contacts, wall[None]])
    return (overlap, *model.contact_law.parts(overlap, max_overlap_m, contact_constants(model)))


def chain_forces(model: ChainModel, displacement_m, velocity_m_s, max_overlap_m=None, sensor_force_n=None,
                 sensor_rate_n_s=None) -> ChainForces:
    """All forces of the chain, N. Displacements are measured from the initial positions.

    `max_overlap_m` (contacts then wall, m) is the largest overlap reached so far, needed
    only by plastic contacts; it must already include the current overlaps.
    `sensor_force_n`, `sensor_rate_n_s`: force and its rate of the model's compliant sensors
    (`hertzchain.compliant_sensor`), N and N/s.
    """
    if max_overlap_m is None:
        max_overlap_m = initial_max_overlap(model)
    overlap_all, elastic_all, _, _ = _elastic_parts(model, displacement_m, max_overlap_m, sensor_force_n)
    overlap, wall_overlap = overlap_all[:-1], overlap_all[-1]
    rate = velocity_m_s[:-1] - velocity_m_s[1:]
    if model.compliant is not None and sensor_rate_n_s is not None:
        rate = shortened_by_model(model, sensor_rate_n_s, rate)
    hertz_elastic = elastic_all[:-1]
    hertz_total = laws.total_force(hertz_elastic, overlap, rate, model.kappa, model.dissipation)
    spring = contact.spring_force(overlap, model.spring_n_m)
    contact_total = jnp.where(model.is_spring, spring, hertz_total)
    contact_elastic = jnp.where(model.is_spring, spring, hertz_elastic)
    wall_elastic = elastic_all[-1]
    wall_total = laws.total_force(wall_elastic, wall_overlap, velocity_m_s[-1], model.wall_kappa, model.dissipation)
    external = jnp.zeros_like(displacement_m)
    external = external.at[1].add(model.first_bead_force_n).at[-1].add(model.last_body_force_n)
    body = _net_force(contact_total, wall_total) + external
    viscous = _net_force(contact_total - contact_elastic, wall_total - wall_elastic)
    return ChainForces(contact_total, contact_elastic, wall_total, wall_elastic, body, viscous)


def contact_potentials(model: ChainModel, displacement_m, max_overlap_m=None, sensor_force_n=None):
    """Elastic energy of each contact and of the wall contact, J: ((n_contacts,), scalar)."""
    if max_overlap_m is None:
        max_overlap_m = initial_max_overlap(model)
    overlap, _, energy, _ = _elastic_parts(model, displacement_m, max_overlap_m, sensor_force_n)
    spring = contact.spring_potential(overlap[:-1], model.spring_n_m)
    return jnp.where(model.is_spring, spring, energy[:-1]), energy[-1]


def plastic_dissipation(model: ChainModel, displacement_m, max_overlap_m, sensor_force_n=None):
    """Energy dissipated by plastic deformation so far, summed over contacts, J."""
    if not model.contact_law.has_history:
        return jnp.zeros(())
    return jnp.sum(_elastic_parts(model, displacement_m, max_overlap_m, sensor_force_n)[3])


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
