"""Description of a chain experiment (`ChainSetup`) and the mechanical model derived from it.

Numbering (used everywhere in the package, in files and on the command line):
beads are numbered 1..N from the striker end; contact K is between bead K and bead K+1;
contact 0 is the striker on bead 1; the wall is after bead N. An embedded sensor in bead K
splits that bead into a back half (mass $(1-\\beta)m$, facing the striker, touched by
contact K-1) and a front half (mass $\\beta m$, touched by contact K), joined by a linear
spring of stiffness $k_s$ chosen so that $\\omega_0^2 = k_s(1/m_+ + 1/m_-)$ (Eq. 4 of
Job et al.).
"""

from __future__ import annotations

import math
import warnings

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from . import laws, setup_constants, setup_laws
from .caller import user_stacklevel
from .materials import BEAD_STEEL, sphere_mass_kg, sphere_volume_m3
from .setup_laws import LAW_ATTRIBUTES  # noqa: F401  (importable from here too)
from .validation import as_float64, check_setup, check_values

ENDS = ("wall", "free")
PLASTIC_LAWS = laws.registry.PLASTIC_LAW_NAMES
# Keywords of `ChainSetup` that `contact_law=` replaces (kept for one release).
DEPRECATED_LAW_KEYWORDS = ("plasticity", "plastic_law", "power_law", "contact_exponent",
                           "exponent_reference_overlap_m")




def _or_default(value, default, name: str) -> jax.Array:
    """`value` (None: `default`) as a float64 array; ValueError naming `name` for a non-number."""
    return as_float64(default if value is None else value, name)


def _per_bead(value, name: str, n_beads: int) -> jax.Array:
    """`value`, a number or one per bead, as an (n_beads,) float64 array; ValueError naming
    `name` for another shape."""
    array = as_float64(value, name)
    if array.ndim == 0:
        return jnp.full((n_beads,), array)
    if array.shape != (n_beads,):
        raise ValueError(
            f"{name} must be a scalar or have one value per bead ({n_beads}), "
            f"got shape {array.shape}."
        )
    return array


def _bead_sizes(n_beads: int, radius_m, density_kg_m3, mass_kg) -> tuple[jax.Array, jax.Array]:
    """The beads' radii (m) and densities (kg/m^3), each (n_beads,): `density_kg_m3`, or
    where `mass_kg` (kg) is given (not None) the density of full spheres of that mass."""
    radius = _per_bead(radius_m, "bead_radius_m", n_beads)
    check_values("bead_radius_m", radius)
    if mass_kg is None:
        return radius, _per_bead(density_kg_m3, "bead_density_kg_m3", n_beads)
    mass = _per_bead(mass_kg, "bead_mass_kg", n_beads)
    check_values("bead_mass_kg", mass)
    return radius, mass / sphere_volume_m3(radius)


def _striker_size(radius_m, mass_kg, density_kg_m3, bead_radius_m, bead_density_kg_m3) -> tuple[jax.Array, jax.Array]:
    """The striker's radius (m) and density (kg/m^3): the density given (None: bead 1's,
    `bead_density_kg_m3`), the radius given, or that of a full sphere of mass `mass_kg` (kg),
    else bead 1's (`bead_radius_m`)."""
    density = _or_default(density_kg_m3, bead_density_kg_m3, "striker_density_kg_m3")
    if mass_kg is not None and radius_m is not None:
        raise ValueError("Give striker_mass_kg or striker_radius_m, not both.")
    if mass_kg is not None:
        mass = as_float64(mass_kg, "striker_mass_kg")
        check_values("striker_mass_kg", mass)
        radius_m = (3.0 * mass / (4.0 * jnp.pi * density)) ** (1.0 / 3.0)
    return _or_default(radius_m, bead_radius_m, "striker_radius_m"), density


def _contact_law(contact_law, old: dict) -> laws.AbstractContactLaw:
    """The setup's contact law: `contact_law`, or the one the deprecated keywords `old`
    (name -> value, None: not given) describe (with a `DeprecationWarning`), else Hertz's."""
    old = {name: value for name, value in old.items() if value is not None}
    if old:
        if contact_law is not None:
            raise ValueError(f"Give contact_law only: {', '.join(old)} are its former spelling.")
        contact_law = laws.contact_law_from_keywords(**old)
        replacement = type(contact_law).__name__
        warnings.warn(f"ChainSetup({'=..., '.join(old)}=...) is deprecated: pass "
                      f"contact_law=hertzchain.laws.{replacement}(...) instead.", DeprecationWarning,
                      stacklevel=user_stacklevel())
    if contact_law is None:
        return laws.Hertz()
    if not isinstance(contact_law, laws.AbstractContactLaw):
        raise ValueError(f"contact_law must be a hertzchain.laws contact law (e.g. laws.Hertz(), "  # noqa: TRY004 (bad input is a ValueError here)
                         f"laws.PowerLaw(1.6)), got {contact_law!r}.")
    return contact_law


def _dissipation(dissipation, eta_s, dashpot_n_s_m) -> tuple[laws.AbstractDissipation, ...]:
    """(Viscoelastic, Dashpot, the other laws...) from `dissipation` (a law or a sequence)
    and the shorthands `eta_s`, `dashpot_n_s_m` (None: not given), which replace the
    coefficients of those two laws."""
    given = (dissipation,) if isinstance(dissipation, laws.AbstractDissipation) else tuple(dissipation)
    for law in given:
        if not isinstance(law, laws.AbstractDissipation):
            raise ValueError(f"dissipation must hold hertzchain.laws dissipation laws (e.g. "  # noqa: TRY004 (bad input is a ValueError here)
                             f"laws.Viscoelastic(eta_s=1e-6)), got {law!r}.")
    firsts = []
    for kind, value, name in ((laws.Viscoelastic, eta_s, "eta_s"), (laws.Dashpot, dashpot_n_s_m, "dashpot_n_s_m")):
        found = [law for law in given if type(law) is kind]
        if len(found) > 1:
            raise ValueError(f"dissipation lists {kind.__name__} {len(found)} times; give it once.")
        firsts.append(kind(as_float64(value, name)) if value is not None else found[0] if found else kind())
    return tuple(firsts) + tuple(law for law in given if type(law) not in (laws.Viscoelastic, laws.Dashpot))


def _check_sensor_beads(sensor_beads: tuple[int, ...], n_beads: int) -> None:
    """ValueError for a sensor bead outside 1..`n_beads` or listed twice."""
    for bead in sensor_beads:
        if not 1 <= bead <= n_beads:
            raise ValueError(
                f"sensor_beads: bead {bead} is not in the chain (beads are numbered 1..{n_beads})."
            )
    if len(set(sensor_beads)) != len(sensor_beads):
        raise ValueError(f"sensor_beads lists a bead twice: {sensor_beads}.")


class ChainSetup(eqx.Module):
    """A 1-D chain experiment: beads, striker, wall or free end, dissipation, sensors.

    Every dimensional field is SI and named with its unit. Array fields are float64 JAX
    arrays, so a setup can be differentiated, `vmap`ped over, or changed with
    `equinox.tree_at`. Defaults are the paper's chain (Job, Melo, Sokolow, Sen, PRL 94,
    178002, 2005): 21 steel beads of radius 13 mm, density 7780 kg/m^3, Y = 203 GPa,
    nu = 0.3, a wall of the same steel, and a striker identical to the beads (the paper
    does not give its striker; give `striker_mass_kg` or `striker_radius_m` for yours).

    **Arguments:**

    - `n_beads`: number of beads N (the striker is extra).
    - `bead_radius_m`, `bead_density_kg_m3`, `bead_youngs_pa`, `bead_poisson`: scalars or
      arrays of length N (heterogeneous chains).
    - `bead_mass_kg`: alternative to the density (scalar or length N); the density is then
      derived from it and the radius.
    - `bead_yield_stress_pa`: the beads' yield stress (paper: 2 GPa). It sets each contact's
      yield force (`contact_yield_force_n`: the paper's mean-pressure estimate, or where the
      contact law `laws.JacksonGreen` leaves Hertz), used for the yield check and by the
      elastic-plastic contact laws.
    - `contact_law`: the law of every contact, wall included (`hertzchain.laws`):
      `laws.Hertz()` (default, the paper's), `laws.PowerLaw(exponent, reference_overlap_m)`
      ($F = \\kappa\\,\\delta_r^{3/2}(\\delta/\\delta_r)^n$, equal to Hertz at $\\delta_r$),
      `laws.Thornton()` (Thornton 1997, yield at `contact_yield_force_n`) or
      `laws.JacksonGreen()` (first yield from the von Mises criterion, hardness 2.84
      $\\sigma_Y$ when fully plastic, unloading from the flattened contact; it matches
      measured sphere-sphere curves, Thornton's does not). Give the dynamic yield stress
      for impacts (`contact.rate_hardened_yield_stress`).
    - `dissipation`: rate-dependent contact laws (`laws.AbstractDissipation`, one or a
      sequence), acting at every contact in compression, their sum with the elastic force
      clipped at 0 (beads do not pull). The setup always holds one `laws.Viscoelastic` and
      one `laws.Dashpot` (of coefficient 0 where not given) first, then the others.
    - `eta_s`: shorthand for `laws.Viscoelastic(eta_s)`, the viscoelastic time $\\eta$ of
      $F_v = \\eta\\kappa\\,\\partial_t\\delta^{3/2}$, s; it replaces the coefficient of a
      `Viscoelastic` in `dissipation`.
    - `dashpot_n_s_m`: shorthand for `laws.Dashpot(dashpot_n_s_m)`, a linear dashpot
      $\\gamma\\dot\\delta$ on the overlap rate while in contact, N s/m (the damping of much
      of the granular-crystal literature, Herbold & Nesterenko, PRE 75, 021304, 2007); it
      replaces the coefficient of a `Dashpot` in `dissipation`.
    - `plasticity`, `plastic_law`, `power_law`, `contact_exponent`,
      `exponent_reference_overlap_m`: the former spelling of `contact_law` (deprecated,
      with a `DeprecationWarning`): `plasticity=True` with `plastic_law="thornton"` or
      `"jackson_green"` is `laws.Thornton()` or `laws.JacksonGreen()`; `contact_exponent`
      n != 1.5 (or `power_law=True`) is `laws.PowerLaw(n, exponent_reference_overlap_m)`.
    - `striker_radius_m` / `striker_mass_kg`: size of the striker (one of them; default: bead 1's
      radius). `striker_density_kg_m3`, `striker_youngs_pa`, `striker_poisson`: its material
      (default: bead 1's).
    - `striker_velocity_m_s`: impact velocity, m/s, > 0.
    - `end`: `"wall"` (flat elastic wall) or `"free"`.
    - `wall_youngs_pa`, `wall_poisson`: the wall's material (default: bead N's);
      `wall_youngs_pa=inf` is a rigid wall.
    - `mu`: friction coefficient of the beads (and striker) on the track, force $\\mu m g$.
    - `mu_star`: thwarted-rotation friction, $\\kappa^* = (1+\\mu^*)\\kappa$ at every contact.
    - `precompression_n`: static force pressing the chain against the wall (or squeezing a
      free chain from both ends), N.
    - `gravity_m_s2`: gravity for the track friction.
    - `sensor_beads`: beads (1..N) with an embedded force sensor; `sensor_beta` the mass
      fraction $\\beta = m_+/(m_+ + m_-)$ of the front half; `sensor_f0_hz` the resonance
      $f_0 = \\omega_0/2\\pi$ (paper: 0.11 and 85 kHz).
    """

    bead_radius_m: jax.Array
    bead_density_kg_m3: jax.Array
    bead_youngs_pa: jax.Array
    bead_poisson: jax.Array
    bead_yield_stress_pa: jax.Array
    striker_radius_m: jax.Array
    striker_density_kg_m3: jax.Array
    striker_youngs_pa: jax.Array
    striker_poisson: jax.Array
    striker_velocity_m_s: jax.Array
    wall_youngs_pa: jax.Array
    wall_poisson: jax.Array
    contact_law: laws.AbstractContactLaw
    dissipation: tuple[laws.AbstractDissipation, ...]
    mu: jax.Array
    mu_star: jax.Array
    precompression_n: jax.Array
    gravity_m_s2: jax.Array
    sensor_beta: jax.Array
    sensor_f0_hz: jax.Array
    end: str = eqx.field(static=True)
    sensor_beads: tuple[int, ...] = eqx.field(static=True)

    def __init__(
        self,
        n_beads: int = 21,
        *,
        bead_radius_m=0.013, bead_density_kg_m3=BEAD_STEEL.density_kg_m3, bead_youngs_pa=BEAD_STEEL.youngs_pa,
        bead_poisson=BEAD_STEEL.poisson, bead_mass_kg=None, bead_yield_stress_pa=BEAD_STEEL.yield_stress_pa,
        striker_radius_m=None, striker_mass_kg=None, striker_density_kg_m3=None, striker_youngs_pa=None,
        striker_poisson=None, striker_velocity_m_s=0.3,
        end: str = "wall", wall_youngs_pa=None, wall_poisson=None,
        contact_law: laws.AbstractContactLaw | None = None, dissipation=(), eta_s=None, dashpot_n_s_m=None,
        mu=0.0, mu_star=0.0, precompression_n=0.0, gravity_m_s2=9.81,
        sensor_beads=(), sensor_beta=0.11, sensor_f0_hz=85e3,
        plasticity: bool | None = None, contact_exponent=None, exponent_reference_overlap_m=None,
        power_law: bool | None = None, plastic_law: str | None = None,
    ):
        if isinstance(n_beads, bool) or not isinstance(n_beads, (int, np.integer)) or n_beads < 1:
            raise ValueError(f"n_beads must be a positive integer, got {n_beads!r}.")
        if end not in ENDS:
            raise ValueError(f"end must be one of {ENDS}, got {end!r}.")
        self.bead_radius_m, self.bead_density_kg_m3 = _bead_sizes(n_beads, bead_radius_m, bead_density_kg_m3,
                                                                   bead_mass_kg)
        self.bead_youngs_pa = _per_bead(bead_youngs_pa, "bead_youngs_pa", n_beads)
        self.bead_poisson = _per_bead(bead_poisson, "bead_poisson", n_beads)
        self.bead_yield_stress_pa = _or_default(bead_yield_stress_pa, math.inf, "bead_yield_stress_pa")
        self.striker_radius_m, self.striker_density_kg_m3 = _striker_size(
            striker_radius_m, striker_mass_kg, striker_density_kg_m3, self.bead_radius_m[0], self.bead_density_kg_m3[0])
        self.striker_youngs_pa = _or_default(striker_youngs_pa, self.bead_youngs_pa[0], "striker_youngs_pa")
        self.striker_poisson = _or_default(striker_poisson, self.bead_poisson[0], "striker_poisson")
        self.striker_velocity_m_s = as_float64(striker_velocity_m_s, "striker_velocity_m_s")
        self.end = end
        self.wall_youngs_pa = _or_default(wall_youngs_pa, self.bead_youngs_pa[-1], "wall_youngs_pa")
        self.wall_poisson = _or_default(wall_poisson, self.bead_poisson[-1], "wall_poisson")
        self.dissipation = _dissipation(dissipation, eta_s, dashpot_n_s_m)
        self.mu = as_float64(mu, "mu")
        self.mu_star = as_float64(mu_star, "mu_star")
        self.precompression_n = as_float64(precompression_n, "precompression_n")
        self.gravity_m_s2 = as_float64(gravity_m_s2, "gravity_m_s2")
        self.sensor_beads = tuple(sorted(int(k) for k in sensor_beads))
        self.sensor_beta = as_float64(sensor_beta, "sensor_beta")
        self.sensor_f0_hz = as_float64(sensor_f0_hz, "sensor_f0_hz")
        self.contact_law = _contact_law(contact_law, {
            "plasticity": plasticity, "plastic_law": plastic_law, "power_law": power_law,
            "contact_exponent": contact_exponent, "exponent_reference_overlap_m": exponent_reference_overlap_m})

    def __check_init__(self):
        check_setup(self)
        _check_sensor_beads(self.sensor_beads, self.n_beads)

    @property
    def n_beads(self) -> int:
        return self.bead_radius_m.shape[-1]

    @property
    def bead_mass_kg(self) -> jax.Array:
        return sphere_mass_kg(self.bead_radius_m, self.bead_density_kg_m3)

    @property
    def striker_mass_kg(self) -> jax.Array:
        return sphere_mass_kg(self.striker_radius_m, self.striker_density_kg_m3)

    # The laws under the attribute names of the former keywords (`hertzchain.setup_laws`).
    law_attributes = property(setup_laws.law_attributes)
    eta_s = property(setup_laws.eta_s)
    dashpot_n_s_m = property(setup_laws.dashpot_n_s_m)
    plasticity = property(setup_laws.plasticity)
    plastic_law = property(setup_laws.plastic_law)
    power_law = property(setup_laws.power_law)
    contact_exponent = property(setup_laws.contact_exponent)
    exponent_reference_overlap_m = property(setup_laws.exponent_reference_overlap_m)

    def contact_kappa(self) -> jax.Array:
        """Hertz stiffness of contacts 0..N-1, N/m^{3/2} (`setup_constants.contact_kappa`)."""
        return setup_constants.contact_kappa(self)

    def wall_kappa(self) -> jax.Array:
        """Hertz stiffness of bead N on the wall, N/m^{3/2} (`setup_constants.wall_kappa`)."""
        return setup_constants.wall_kappa(self)

    def contact_constants(self) -> laws.ContactConstants:
        """The `laws.ContactConstants` of contacts 0..N-1 and the wall contact (last)
        (`setup_constants.contact_constants`)."""
        return setup_constants.contact_constants(self)

    def contact_yield_force_n(self) -> jax.Array:
        """The contact law's yield force of contacts 0..N-1 and the wall contact (last), N
        (`setup_constants.contact_yield_force_n`)."""
        return setup_constants.contact_yield_force_n(self)

    def contact_reduced_radius_m(self) -> jax.Array:
        """Reduced radius of contacts 0..N-1 and the wall contact (last), m
        (`setup_constants.contact_reduced_radius_m`)."""
        return setup_constants.contact_reduced_radius_m(self)

    def sensor_spring_n_m(self) -> jax.Array:
        """Spring stiffness of each embedded sensor, N/m (`setup_constants.sensor_spring_n_m`)."""
        return setup_constants.sensor_spring_n_m(self)


class CompliantSensorModel(eqx.Module):
    """Embedded sensors as compliances of unsplit beads (`hertzchain.compliant_sensor`).

    Sensor j sits in bead `beads[j]`: its back contact is internal contact `beads[j] - 1`
    and its front contact `beads[j]`; a sensor force $F_s$ shortens them by
    `back_m_n * F_s` and `front_m_n * F_s`.
    """

    beads: tuple[int, ...] = eqx.field(static=True)
    beta: jax.Array  # (n_sensors,) mass fraction of the front half
    inv_omega0_sq_s2: jax.Array  # (n_sensors,) 1/omega0^2, s^2 (0: rigid sensor)
    back_m_n: jax.Array  # (n_sensors,) m/N
    front_m_n: jax.Array  # (n_sensors,) m/N
    reduced_mass_kg: jax.Array  # (n_sensors,) beta (1 - beta) m


class ChainModel(eqx.Module):
    """The mechanical model of a setup: bodies on a line, joined by contacts.

    Bodies are the striker, then the beads, with each sensor bead split in two halves.
    Internal contact c joins body c and body c+1. All arrays are float64.
    """

    mass_kg: jax.Array  # (n_bodies,)
    kappa: jax.Array  # (n_contacts,) Hertz stiffness, 0 for sensor springs
    spring_n_m: jax.Array  # (n_contacts,) linear stiffness, 0 for Hertz contacts
    is_spring: jax.Array  # (n_contacts,) bool
    overlap0_m: jax.Array  # (n_contacts,) static overlap from precompression
    wall_kappa: jax.Array  # scalar (0 for a free end)
    wall_overlap0_m: jax.Array  # scalar
    yield_force_n: jax.Array  # (n_contacts,) used when plastic
    wall_yield_force_n: jax.Array  # scalar
    contact_law: laws.AbstractContactLaw  # the law of every Hertz contact, wall included
    dissipation: tuple[laws.AbstractDissipation, ...]  # rate-dependent laws of those contacts
    friction_decel_m_s2: jax.Array  # mu * g
    first_bead_force_n: jax.Array  # external force on bead 1, towards the wall
    last_body_force_n: jax.Array  # external force on the last body (free end only)
    striker_velocity_m_s: jax.Array
    # Embedded sensors in compliance form (`hertzchain.compliant_sensor`): none by default.
    compliant: CompliantSensorModel | None = None
    # Elastic-plastic laws: reduced radius (m) and Poisson ratio of every internal contact then
    # the wall (n_contacts + 1,), and the yield stress (Pa); None for laws without a history.
    reduced_radius_m: jax.Array | None = None
    contact_poisson: jax.Array | None = None
    yield_stress_pa: jax.Array | None = None


def internal_contact_index(setup: ChainSetup, contact_number: int) -> int:
    """Index in the model's contact array of the paper-numbered contact K (0..N-1)."""
    return contact_number + sum(1 for bead in setup.sensor_beads if bead <= contact_number)


def internal_sensor_index(setup: ChainSetup, bead: int) -> int:
    """Index in the model's contact array of the spring of the sensor in `bead`."""
    return internal_contact_index(setup, bead - 1) + 1


def _bead_links(setup: ChainSetup):
    """(bead, kind) of the internal contacts after the striker's, in order: a sensor bead
    contributes its spring, every bead but the last its contact with the next bead."""
    for bead in range(1, setup.n_beads + 1):
        if bead in setup.sensor_beads:
            yield bead, "spring"
        if bead < setup.n_beads:
            yield bead, "hertz"


def end_loads(setup: ChainSetup) -> dict:
    """The `ChainModel` fields of what acts on the chain from outside: the track friction's
    deceleration mu g (m/s^2), the preload on bead 1 and, at a free end, on the last body
    (N), and the striker's impact velocity (m/s)."""
    preload = setup.precompression_n
    return {
        "friction_decel_m_s2": setup.mu * setup.gravity_m_s2,
        "first_bead_force_n": preload,
        "last_body_force_n": jnp.zeros(()) if setup.end == "wall" else -preload,
        "striker_velocity_m_s": setup.striker_velocity_m_s,
    }


def build_model(setup: ChainSetup) -> ChainModel:
    """Derive masses, stiffnesses and the static state of a setup (pure, differentiable).

    A setup built from concrete numbers was checked when it was built; one whose values are
    traced (changed inside `jit`, `vmap` or `grad`, e.g. by `eqx.tree_at`) is checked here
    with `eqx.error_if`: a mass or a contact or sensor stiffness that is not positive and
    finite, or a damping, friction, preload or impact-velocity value that is not finite,
    raises at run time (under `vmap`, one bad element raises for the batch). The checks run
    once per solve, outside the time loop.
    """
    bead_mass = setup.bead_mass_kg
    kappa = setup.contact_kappa()
    yield_force = setup.contact_yield_force_n()
    springs_k = setup.sensor_spring_n_m()
    beta = setup.sensor_beta
    sensor_rank = {bead: i for i, bead in enumerate(setup.sensor_beads)}
    zero, never = jnp.zeros(()), jnp.asarray(jnp.inf)
    masses = [setup.striker_mass_kg]
    for bead in range(1, setup.n_beads + 1):
        m = bead_mass[bead - 1]
        masses += [(1.0 - beta) * m, beta * m] if bead in sensor_rank else [m]
    reduced_radius = setup.contact_reduced_radius_m()
    one = jnp.ones(())
    # (Hertz stiffness, spring stiffness, is a sensor spring, yield force, reduced radius,
    # Poisson ratio of the bead behind) per internal contact
    links = [(kappa[0], zero, False, yield_force[0], reduced_radius[0], setup.bead_poisson[0])]
    for bead, kind in _bead_links(setup):
        if kind == "spring":
            links.append((zero, springs_k[sensor_rank[bead]], True, never, one, setup.bead_poisson[bead - 1]))
        else:
            links.append((kappa[bead], zero, False, yield_force[bead], reduced_radius[bead],
                          setup.bead_poisson[bead]))
    kappa_all = jnp.stack([link[0] for link in links])
    spring_all = jnp.stack([link[1] for link in links])
    is_spring = jnp.asarray([link[2] for link in links])
    preload = setup.precompression_n
    safe_kappa = jnp.where(is_spring, 1.0, kappa_all)
    hertz_overlap = setup.contact_law.overlap_at_force(preload, laws.ContactConstants(safe_kappa))
    spring_overlap = preload / jnp.where(is_spring, spring_all, 1.0)
    overlap0 = jnp.where(is_spring, spring_overlap, hertz_overlap).at[0].set(0.0)
    has_wall = setup.end == "wall"
    wall_kappa = setup.wall_kappa() if has_wall else jnp.zeros(())
    wall_overlap0 = (setup.contact_law.overlap_at_force(preload, laws.ContactConstants(setup.wall_kappa()))
                     if has_wall else jnp.zeros(()))
    mass_kg = jnp.stack(masses)
    mass_kg = eqx.error_if(
        mass_kg, ~(jnp.isfinite(mass_kg) & (mass_kg > 0)),
        "ChainSetup: a bead or striker mass is not positive and finite (check the radii and "
        "densities of the traced setup).",
    )
    stiffness = jnp.where(is_spring, spring_all, kappa_all)
    kappa_all = eqx.error_if(
        kappa_all, ~(jnp.isfinite(stiffness) & (stiffness > 0)),
        "ChainSetup: a contact or sensor stiffness is not positive and finite (check the radii, "
        "Young's moduli, Poisson ratios, mu_star and sensor_f0_hz of the traced setup).",
    )
    scalars = (setup.eta_s, setup.dashpot_n_s_m, setup.mu, preload, setup.striker_velocity_m_s)
    mass_kg = eqx.error_if(
        mass_kg, ~jnp.all(jnp.stack([jnp.all(jnp.isfinite(x)) for x in scalars])),
        "ChainSetup: eta_s, dashpot_n_s_m, mu, precompression_n or striker_velocity_m_s is not "
        "finite in the traced setup.",
    )
    return ChainModel(
        mass_kg=mass_kg,
        kappa=kappa_all,
        spring_n_m=spring_all,
        is_spring=is_spring,
        overlap0_m=overlap0,
        wall_kappa=wall_kappa,
        wall_overlap0_m=wall_overlap0,
        yield_force_n=jnp.stack([link[3] for link in links]),
        wall_yield_force_n=yield_force[-1],
        contact_law=setup.contact_law,
        dissipation=setup.dissipation,
        **end_loads(setup),
        **(_plastic_fields(setup, links) if setup.contact_law.has_history else {}),
    )


def _plastic_fields(setup: ChainSetup, links) -> dict:
    """The `ChainModel` fields of elastic-plastic contact laws."""
    radius = jnp.stack([link[4] for link in links] + [setup.bead_radius_m[-1]])
    poisson = jnp.stack([link[5] for link in links] + [setup.bead_poisson[-1]])
    return {"reduced_radius_m": radius, "contact_poisson": poisson, "yield_stress_pa": setup.bead_yield_stress_pa}
