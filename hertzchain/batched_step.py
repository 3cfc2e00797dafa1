"""The batched kernel's physics on its packed state: the static `KernelFlags` that select it,
the contact forces and energy of every chain of a batch, and one velocity-Verlet step
(`_step`, with its start and end); `hertzchain.batched` runs it over a time grid, in JAX or
in the native kernels, which implement the same step."""

from __future__ import annotations

import dataclasses
from typing import NamedTuple

import jax
import jax.numpy as jnp

from . import compliant_sensor, contact, laws, verlet
from .chain import (
    PLASTIC_LAWS,
)
from .integrate import Recording, _channel_names, _layout, stack_setups  # noqa: F401

# `laws.ContactConstants` fields beyond the stiffness that the kernel arrays hold for laws with
# a history, and those of them with a value per contact (rows of the kernel's contact arrays);
# the others have one per chain.
_CONSTANTS = ("yield_force_n", "reduced_radius_m", "poisson", "yield_stress_pa")
_PER_CONTACT = ("yield_force_n", "reduced_radius_m", "poisson")


class KernelFlags(NamedTuple):
    """The physics a compiled kernel includes (static: each combination is its own kernel)."""

    viscous: bool
    springs: bool
    preload: bool
    friction: bool = False
    # The running maxima of every contact and the energy books (reductions over the chain at
    # every step); callers that read the recorded forces only (fits) switch them off.
    ledger: bool = True
    # The contacts' elastic law (`contact_law`: "hertz", "power_law" or a `PLASTIC_LAWS` name);
    # plastic laws carry each contact's largest overlap so far in the state.
    law: str = "hertz"
    # The law of the contacts' rate slot beside Kuwabara-Kono damping (with `viscous`, which
    # computes the rates), by its `laws.registry` name: "dashpot" (a linear dashpot on every
    # contact, `setup.dashpot_n_s_m`), "velocity_squared" (the setup's one further law, a
    # `laws.VelocitySquared`, which the native kernels carry there; the JAX kernel runs it from
    # the setup's laws whatever this says), or None.
    rate_law: str | None = None
    # The full step's state whatever the physics: set where the full C++ kernel runs a
    # conservative chain (laws other than Hertz's, `native.kernel_for`), whose books come in
    # and out in that layout. The JAX kernel keeps the conservative one for those chains: in
    # the full one an undamped Jackson-Green sweep took 18.2 s against 3.9 s
    # (`benchmarks/results/law_kernel/jackson_green/latest.json`, `jax_full_state`).
    full_step: bool = False
    # Beads K (1..N-1) with an embedded sensor in compliance form (`compliant_sensor`; their
    # strengths are `record_batched`'s `compliant_sensors`): the full step only, without the
    # books (the JAX kernel's, and on the CPU the C++ sensor libraries').
    sensors: tuple[int, ...] = ()

    @property
    def full_state(self) -> bool:
        """Velocities and accelerations kept apart (damping or friction acts between the
        two half kicks, compliant sensors, or `full_step`), rather than the next half kick's
        velocity alone."""
        return self.viscous or self.friction or self.full_step or bool(self.sensors)

    @property
    def plastic(self) -> bool:
        """Whether the contact law depends on the largest overlap so far."""
        return self.law in PLASTIC_LAWS


def _law(p, flags: KernelFlags, rows=lambda a: a):
    """The contact law (`flags.law`'s class, `laws.registry`) and its `laws.ContactConstants`
    (of the contacts `rows` picks) from the kernel arrays `_chain_params` stored."""
    return law_from_arrays(p, flags.law, rows)


def law_from_arrays(p, name: str, rows=lambda a: a):
    """The contact law of native name `name` (`laws.registry`) and its `laws.ContactConstants`
    (of the contacts `rows` picks) from the kernel arrays `_chain_params` stored."""
    kind = laws.registry.contact_law_named(name)
    law = kind(**{field.name: p[field.name] for field in dataclasses.fields(kind)})
    constants = {name: rows(p[name]) if name in _PER_CONTACT else p[name] for name in _CONSTANTS if name in p}
    return law, laws.ContactConstants(rows(p["kappa"]), **constants)


def _dissipation(p, flags: KernelFlags) -> tuple:
    """The dissipation laws the kernel compiles in: Kuwabara-Kono's (with `flags.viscous`),
    the dashpot (`flags.rate_law` "dashpot") and every other law of the setup."""
    if not flags.viscous:
        return ()
    return ((laws.Viscoelastic(p["eta"]),) + ((laws.Dashpot(p["dashpot"]),) if flags.rate_law == "dashpot" else ())
            + tuple(p.get("dissipation", ())))


def _shortened(p, flags: KernelFlags, amount, values):
    """`values` of every contact (n_bodies, B: overlaps, m, or rates, m/s) less what the
    compliant sensors compressed by `amount` (N, or N/s: (n_sensors, B)) take
    (`compliant_sensor.shortened`)."""
    back, front = p["sensor_back"], p["sensor_front"]
    if amount.ndim == 3:  # (n_sensors, k, B): k quantities at once
        back, front = back[:, None], front[:, None]
    return compliant_sensor.shortened(flags.sensors, back, front, amount, values)


def _contact_forces(p, flags: KernelFlags, x, v, contacts=None, peak=None, sensor=None):
    """Total and elastic force of every contact, wall last (n_bodies, B), or of the listed
    `contacts` only, N, from displacements x (m) and velocities v (m/s) of the bodies and
    the wall (and, for plastic laws, every contact's largest overlap so far, `peak`, m; with
    compliant sensors, their forces and rates, `sensor`, N and N/s, (n_sensors, B) each):
    the laws of `contact` (the ones `forces.chain_forces` uses), elementwise."""

    def rows(a):
        return a if contacts is None else jnp.stack([a[k] for k in contacts])

    def pair(a):  # the bodies in front of and behind each contact
        return rows(a[:-1]), rows(a[1:])

    front, back = pair(x)
    rate = None
    if flags.viscous:
        front_v, back_v = pair(v)
        rate = front_v - back_v
    overlap = front - back + rows(p["overlap0"]) if flags.preload else front - back
    if flags.sensors and sensor is not None:  # (None: at rest)
        force, sensor_rate = sensor
        if contacts is not None:
            raise ValueError("compliant sensors: the contact forces of every contact only")
        if flags.viscous:  # overlaps and rates in one scatter
            both = _shortened(p, flags, jnp.stack([force - p["first_force"], sensor_rate], axis=1),
                              jnp.stack([overlap, rate], axis=1))
            overlap, rate = both[:, 0], both[:, 1]
        else:
            overlap = _shortened(p, flags, force - p["first_force"], overlap)
    return _forces_at(p, flags, overlap, rate, rows, None if peak is None else rows(peak))


def _forces_at(p, flags: KernelFlags, overlap, rate, rows=lambda a: a, peak=None):
    """Total and elastic contact forces, N, at the given overlaps (m), overlap rates (m/s;
    None without damping) and, for plastic laws, largest overlaps so far (m), of the
    contacts that `rows` picks from the parameters."""
    law, constants = _law(p, flags, rows)
    elastic = law.force(overlap, peak, constants)
    total = laws.total_force(elastic, overlap, rate, constants.kappa_n_m1p5, _dissipation(p, flags))
    if flags.springs:
        spring = contact.spring_force(overlap, rows(p["spring"]))
        elastic, total = elastic + spring, total + spring
    return total, elastic


def _overlaps(p, flags: KernelFlags, x, sensor_force=None):
    """Overlap of every contact, wall last (n_bodies, B), m (with compliant sensors, those
    of sensor forces `sensor_force`, N, (n_sensors, B)). Without preload every static
    overlap is 0 and is not added (one array less to read per step)."""
    overlap = x[:-1] - x[1:] + p["overlap0"] if flags.preload else x[:-1] - x[1:]
    if flags.sensors and sensor_force is not None:  # (None: at rest)
        overlap = _shortened(p, flags, sensor_force - p["first_force"], overlap)
    return overlap


def _body_force(force, external=None):
    """Force on every body and on the wall (n_bodies + 1, B), N, from the contact forces
    (compression positive): contact k pushes body k + 1 forward and body k back."""
    zero = jnp.zeros_like(force[:1])
    body = jnp.concatenate([zero, force]) - jnp.concatenate([force, zero])
    return body if external is None else body + external


def _energy(p, flags: KernelFlags, x, v, peak=None):
    """Kinetic and potential (elastic plus preload) energy, J, each (B,), and the energy
    plastic contacts have dissipated so far (their largest overlaps `peak`), J, (B,)."""
    n = p["mass"].shape[0]
    kinetic = 0.5 * jnp.sum(p["mass"] * v[:n] ** 2, axis=0)
    overlap = _overlaps(p, flags, x)
    law, constants = _law(p, flags)
    _, elastic, plastic = law.parts(overlap, peak, constants)
    potential = jnp.sum(elastic, axis=0)
    if flags.springs:
        potential = potential + jnp.sum(contact.spring_potential(overlap, p["spring"]), axis=0)
    if flags.preload:
        potential = potential - (p["first_force"] * x[1] + p["last_force"] * x[n - 1])
    return kinetic, potential, jnp.sum(plastic, axis=0)


class _Layout(NamedTuple):
    """Row ranges of the packed state: one (rows, B) array, so that a step is one fused
    loop instead of one per state variable."""

    bodies: int

    def fields(self, flags: KernelFlags) -> tuple[tuple[str, int], ...]:
        b, c = self.bodies + 1, self.bodies
        # plastic contacts: every contact's largest overlap so far; compliant sensors: the
        # force, rate and drive (Eq. 4) of each
        n = len(flags.sensors)
        carried = ((("peak", c),) if flags.plastic else ()) + (
            (("sensor_force", n), ("sensor_rate", n), ("sensor_drive", n)) if flags.sensors else ())
        if flags.full_state:
            # x, v, a at the step; running maxima; viscous body forces; dissipated energy
            viscous = (("viscous", b),) if flags.viscous else ()
            books = (("max", c),) + viscous + (("dissipated", 1),)
            return (("x", b), ("v", b), ("a", b)) + carried + (books if flags.ledger else ())
        # x, u = v + (dt/2) a (the next half-kick's velocity), largest overlaps so far
        # (the elastic forces grow with the overlap, so their maxima are the forces there)
        return (("x", b), ("u", b)) + carried + ((("max", c),) if flags.ledger else ())

    def unpack(self, flags: KernelFlags, state) -> dict:
        out, row = {}, 0
        for name, rows in self.fields(flags):
            out[name] = state[row : row + rows]
            row += rows
        return out

    def pack(self, flags: KernelFlags, parts: dict):
        return jnp.concatenate([parts[name] for name, _ in self.fields(flags)])


def _step(p, flags: KernelFlags, layout: _Layout, dt: float, state):
    """One velocity-Verlet step on the packed state: with damping, friction or sensors
    `verlet.step` (as `integrate.verlet_step`), else its conservative form on (x, u), u the
    next half kick's velocity."""
    h = 0.5 * dt
    s = layout.unpack(flags, state)
    barrier = jax.lax.optimization_barrier
    new = {}

    sensor = None
    if flags.sensors:  # the sensors' first half kick and drift (`compliant_sensor.drift`)
        force, half_rate, predicted_rate, quasi_static = compliant_sensor.drift(
            p["sensor_inv"], dt, s["sensor_force"], s["sensor_rate"], s["sensor_drive"])
        sensor = (force, predicted_rate)

    def contact_forces(x, v):  # plastic contacts: their largest overlaps, these included
        if flags.plastic:
            new["peak"] = jnp.maximum(s["peak"], _overlaps(p, flags, x, None if sensor is None else sensor[0]))
        return _contact_forces(p, flags, x, v, peak=new.get("peak"), sensor=sensor)

    if not flags.full_state:
        x = verlet.drift(s["x"], s["u"], dt)
        force = contact_forces(x, None)[0]
        # Displacements and contact forces materialised together (one loop), so that the
        # next loop reads each contact's force instead of evaluating it again for each of
        # the two bodies it pushes (a square root per contact and step less).
        both = barrier(jnp.concatenate([x, force]))
        x, force = both[: layout.bodies + 1], both[layout.bodies + 1 :]
        a = _body_force(force, p["external"] if flags.preload else None) * p["inv_mass"]
        v = verlet.half_kick(s["u"], a, h)
        new |= {"x": x, "u": verlet.half_kick(v, a, h)}
        if flags.ledger:
            new["max"] = jnp.maximum(s["max"], _overlaps(p, flags, x))
        return barrier(layout.pack(flags, new))

    def accel_at(x, v):
        if flags.viscous:
            total, elastic = contact_forces(x, v)
            both = barrier(jnp.concatenate([total, elastic]))
            total, elastic = both[: layout.bodies], both[layout.bodies :]
        else:
            total, elastic = barrier(contact_forces(x, None)[0]), None
        a = _body_force(total, p["external"] if flags.preload else None) * p["inv_mass"]
        return a, (total, elastic)

    limit = (lambda w: _friction_kick(p, flags, w, h)) if flags.friction else None
    stepped = verlet.step(s["x"], s["v"], s["a"], dt, accel_at, limit=limit)
    x, v, a = stepped.displacement_m, stepped.velocity_m_s, stepped.accel_m_s2
    total, elastic = stepped.forces
    work, lost = 0.0, stepped.limited if flags.friction else 0.0
    if flags.viscous and flags.ledger:
        work = jnp.sum(s["viscous"] * h * 0.5 * (s["v"] + stepped.half_kicked_m_s), axis=0)
    new |= {"x": x, "a": a, "v": v}
    if flags.sensors:  # the second half kick, from the new drive
        drive = compliant_sensor.drive(p["sensor_beta"], *compliant_sensor.contacts_of(flags.sensors, total))
        new |= {"sensor_force": force, "sensor_drive": drive,
                "sensor_rate": compliant_sensor.kick(p["sensor_inv"], dt, force, half_rate, drive, quasi_static)}
    if flags.viscous and flags.ledger:
        viscous = _body_force(total - elastic)
        work = work + jnp.sum(viscous * h * 0.5 * (stepped.half_velocity_m_s + v), axis=0)
        # Chains without damping in a damped batch dissipate nothing, exactly (total - elastic
        # can be an ulp off zero when XLA contracts the force law into fused multiply-adds).
        work = jnp.where(laws.is_damped(_dissipation(p, flags)), work, 0.0)
        new["viscous"] = viscous
    if flags.friction:
        new["v"], lost_end = _friction_kick(p, flags, v, h)
        lost = lost + lost_end
    if flags.ledger:
        new["max"] = jnp.maximum(s["max"], total)
        new["dissipated"] = s["dissipated"] - work + lost
    return barrier(layout.pack(flags, new))


def _friction_kick(p, flags: KernelFlags, v, half_step_s):
    """Track friction over half a step (`contact.track_friction_kick`) on every body:
    the new velocities (n_bodies + 1, B), m/s, and the energy it took, (1, B), J (0 when
    the kernel keeps no books)."""
    clamped = contact.track_friction_kick(v, p["friction"], half_step_s)
    if not flags.ledger:
        return clamped, 0.0
    n = p["mass"].shape[0]
    lost = 0.5 * jnp.sum(p["mass"] * (v[:n] ** 2 - clamped[:n] ** 2), axis=0)
    return clamped, lost[None]


def _start(p, flags: KernelFlags):
    """Displacements, velocities and accelerations of the bodies and the wall at the impact
    (bodies + 1, B), and the total and elastic contact forces there (bodies, B)."""
    x = jnp.zeros_like(p["inv_mass"]) + jnp.zeros_like(p["v0"])  # (bodies + 1, B)
    v = x.at[0].set(p["v0"])
    total, elastic = _contact_forces(p, flags, x, v, peak=_initial_peak(p, flags, x))
    a = _body_force(total, p["external"] if flags.preload else None) * p["inv_mass"]
    return x, v, a, total, elastic


def _initial_peak(p, flags: KernelFlags, x):
    """Largest overlaps before the impact (the preload's, at displacements x = 0), m, for
    plastic contacts; None for the others."""
    return _overlaps(p, flags, x) if flags.plastic else None


def _sensors_at_rest(p) -> dict:
    """The compliant sensors' force (the preload's, N), rate (0, N/s) and drive (N) before the
    impact, (n_sensors, B) each."""
    at_rest = jnp.zeros_like(p["sensor_beta"]) + p["first_force"]
    return {"sensor_force": at_rest, "sensor_rate": jnp.zeros_like(at_rest), "sensor_drive": at_rest}


def _initial(p, flags: KernelFlags, layout: _Layout, dt: float):
    """Packed state at the impact and the bodies' (x, v) there."""
    x, v, a, total, elastic = _start(p, flags)
    carried = {"peak": _initial_peak(p, flags, x)} if flags.plastic else {}
    if flags.sensors:
        carried |= _sensors_at_rest(p)
    if flags.full_state:
        parts = {"x": x, "v": v, "a": a, "max": total, "dissipated": jnp.zeros_like(x[:1])}
        if flags.viscous:
            parts["viscous"] = _body_force(total - elastic)
    else:
        parts = {"x": x, "u": v + 0.5 * dt * a, "max": _overlaps(p, flags, x)}
    return layout.pack(flags, parts | carried), x, v


def _final(p, flags: KernelFlags, layout: _Layout, dt: float, state):
    """Displacements, velocities and dissipated energy (damping and friction; plastic work
    is `_energy`'s) at the end of the run."""
    s = layout.unpack(flags, state)
    if flags.full_state:
        return s["x"], s["v"], s["dissipated"][0]
    total = _contact_forces(p, flags, s["x"], None, peak=s.get("peak"))[0]
    a = _body_force(total, p["external"] if flags.preload else None) * p["inv_mass"]
    return s["x"], s["u"] - 0.5 * dt * a, jnp.zeros_like(s["x"][0])
