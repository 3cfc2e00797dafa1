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


class ElasticLaw(NamedTuple):
    """The rate-independent law of every contact, contacts then wall (arrays that broadcast
    with the overlaps): Hertz where every field is None; power law with `exponent`; elastic-
    plastic with `yield_force_n` (Thornton's law, or Jackson-Green's with `reduced_radius_m`,
    `poisson` and `yield_stress_pa`; an infinite yield force or a zero stiffness keeps the
    contact elastic: sensor springs, a free end)."""

    exponent: jax.Array | None = None
    reference_overlap_m: jax.Array | None = None
    yield_force_n: jax.Array | None = None
    reduced_radius_m: jax.Array | None = None
    poisson: jax.Array | None = None
    yield_stress_pa: jax.Array | None = None


def elastic_law(model: ChainModel) -> ElasticLaw:
    """The `ElasticLaw` of a chain model, (n_contacts + 1,) arrays (wall last)."""
    if model.contact_exponent is not None:
        return ElasticLaw(exponent=model.contact_exponent, reference_overlap_m=model.reference_overlap_m)
    if not model.plastic:
        return ElasticLaw()
    return ElasticLaw(yield_force_n=jnp.concatenate([model.yield_force_n, model.wall_yield_force_n[None]]),
                      reduced_radius_m=model.reduced_radius_m, poisson=model.contact_poisson,
                      yield_stress_pa=model.yield_stress_pa)


def elastic_parts(law: ElasticLaw, overlap_m, max_overlap_m, kappa_n_m1p5):
    """Elastic force (N), stored energy (J) and plastic dissipation so far (J) of contacts at
    `overlap_m` whose largest overlap so far is `max_overlap_m` (m; read by plastic laws
    only), elementwise: the one place where a contact's law is chosen, for the general
    solver (`chain_forces`) and the batched kernel alike."""
    kappa = kappa_n_m1p5
    if law.exponent is not None:
        shape = (kappa, law.exponent, law.reference_overlap_m)
        return (contact.power_law_force(overlap_m, *shape), contact.power_law_potential(overlap_m, *shape),
                jnp.zeros_like(overlap_m))
    hertz = contact.hertz_force(overlap_m, kappa), contact.hertz_potential(overlap_m, kappa)
    if law.yield_force_n is None:
        return hertz[0], hertz[1], jnp.zeros_like(overlap_m)
    plastic = jnp.isfinite(law.yield_force_n)
    if law.reduced_radius_m is None:
        safe_yield = jnp.where(plastic, law.yield_force_n, 1.0)
        force, energy, dissipated = contact.thornton_contact(overlap_m, max_overlap_m, kappa, safe_yield)
    else:
        plastic = plastic & (kappa > 0.0)  # a free end has no wall contact
        safe_kappa = jnp.where(plastic, kappa, 1.0)
        safe_stress = jnp.where(plastic, law.yield_stress_pa, 1.0)
        force, energy, dissipated = contact.jackson_green_contact(
            overlap_m, max_overlap_m, safe_kappa, law.reduced_radius_m, safe_stress, law.poisson)
    return (
        jnp.where(plastic, force, hertz[0]),
        jnp.where(plastic, energy, hertz[1]),
        jnp.where(plastic, dissipated, 0.0),
    )


def _elastic_parts(model: ChainModel, displacement_m, max_overlap_m, sensor_force_n=None):
    """Overlap (m), elastic force (N), stored energy (J) and plastic dissipation (J) of every
    contact and of the wall (last)."""
    contacts, wall = overlaps(model, displacement_m, sensor_force_n)
    overlap = jnp.concatenate([contacts, wall[None]])
    kappa = jnp.concatenate([model.kappa, model.wall_kappa[None]])
    return (overlap, *elastic_parts(elastic_law(model), overlap, max_overlap_m, kappa))


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
    hertz_elastic, hertz_total = contact.contact_force(
        overlap, rate, model.kappa, model.eta_s, elastic_all[:-1], model.dashpot_n_s_m
    )
    spring = contact.spring_force(overlap, model.spring_n_m)
    contact_total = jnp.where(model.is_spring, spring, hertz_total)
    contact_elastic = jnp.where(model.is_spring, spring, hertz_elastic)
    wall_elastic, wall_total = contact.contact_force(
        wall_overlap, velocity_m_s[-1], model.wall_kappa, model.eta_s, elastic_all[-1],
        model.dashpot_n_s_m,
    )
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
    if not model.plastic:
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
