"""Embedded sensors as compliances of unsplit beads: the split-bead mechanics, regular at f0 = inf.

`ChainSetup.sensor_beads` models a sensor bead as two bodies joined by a spring of
stiffness $k_s = \\omega_0^2\\beta(1-\\beta)m$; an explicit step must resolve $\\omega_0$, and
the rigid limit $f_0 \\to \\infty$ cannot be reached. Fitting the sensor's resonance needs
that limit (it is "no sensor dynamics"), so here the same mechanics is written in other
coordinates: the bead's centre of mass $x_c$ (mass $m$) and the sensor force
$F_s = k_s (x_- - x_+)$. With $c = 1/k_s$ the halves sit at $x_- = x_c + \\beta c F_s$ and
$x_+ = x_c - (1-\\beta) c F_s$, so the bead's back contact (K-1) loses $\\beta c F_s$ of
overlap and its front contact (K) $(1-\\beta) c F_s$, and Newton's law for the halves gives
Eq. (4) of Job et al.:

$$\\ddot F_s = \\omega_0^2\\,[\\beta F_{K-1} + (1-\\beta) F_K - F_s],$$

the contact forces being those of the shortened bead. The chain and $F_s$ are advanced by one
velocity-Verlet step (the split-bead model's step in these coordinates, so the two agree to
O(dt^2)). The compliances vanish as $1/\\omega_0^2$; once $\\omega_0 \\Delta t > 1$ the
oscillator is not resolved and $F_s$ is taken quasi-statically, equal to the drive of the
previous step (its ringing, of relative size $1/(\\omega_0\\Delta t)$, is then negligible
against a compliance already $(\\omega_0\\Delta t)^{-2}$ times the bead's). At
$1/\\omega_0^2 = 0$ the chain is exactly the rigid one, and derivatives exist there.

The front compliance $1/(\\omega_0^2\\beta m)$ diverges as $\\beta \\to 0$ (a massless front
half on a spring of vanishing stiffness); $\\beta$ is floored at `BETA_FLOOR` in it.
The energy ledger counts the sensor's spring and internal kinetic energy; it is exact
without viscous damping (the viscous force's work on the sensor's internal motion is not
booked). `solve` runs these sensors, and so does the batched JAX kernel
(`batched.record_batched(..., compliant_sensors=)`, without the books): both take the step's
sensor arithmetic from here (`drift`, `kick`, `shortened`). On the CPU `record_batched` runs
them in the C++ kernel's sensor libraries (one per contact law) (`native.run_full(...,
sensors=)`, its tangents included), the same arithmetic in the same order but for a contact
between two sensors, which loses the two terms summed (equal to round-off).
"""

from __future__ import annotations

import dataclasses
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from .chain import ChainModel, CompliantSensorModel

# Smallest front-half mass fraction used in the front compliance.
BETA_FLOOR = 0.02


class CompliantSensors(NamedTuple):
    r"""Embedded sensors to model in compliance form (`solve(..., compliant_sensors=...)`).

    **Fields:** `beads` bead numbers K (1..N-1), each sensor's back contact is K-1 and its
    front contact K; `beta` mass fraction of the front half; `inv_omega0_sq_s2`
    $1/(2\pi f_0)^2$, s^2 (0: rigid sensor, the base chain).
    """

    beads: tuple[int, ...]
    beta: float | jax.Array
    inv_omega0_sq_s2: float | jax.Array

    @classmethod
    def from_f0(cls, beads, *, beta, f0_hz) -> CompliantSensors:
        """Sensors of resonance `f0_hz` (Hz; inf for rigid)."""
        return cls(tuple(beads), beta, 1.0 / (2.0 * jnp.pi * jnp.asarray(f0_hz, dtype=jnp.float64)) ** 2)


def compliances(mass_kg, beta, inv_omega0_sq_s2):
    """(back, front) compliances, m/N, and the halves' reduced mass $\\beta(1-\\beta)m$, kg, of
    sensors in beads of mass `mass_kg` (arrays that broadcast; `BETA_FLOOR` in the front's)."""
    floored = jnp.maximum(beta, BETA_FLOOR)
    return (inv_omega0_sq_s2 / ((1.0 - beta) * mass_kg), inv_omega0_sq_s2 / (floored * mass_kg),
            floored * (1.0 - beta) * mass_kg)


def with_compliant_sensors(model: ChainModel, beads, *, beta, inv_omega0_sq_s2) -> ChainModel:
    """`model` with embedded sensors in compliance form in `beads` (bead numbers 1..N-1).

    **Arguments:**

    - `model`: a model without split sensor beads (`build_model` of a setup with no
      `sensor_beads`: `solve` checks it).
    - `beads`: bead numbers K; each sensor's back contact is K-1 and its front contact K.
    - `beta`: mass fraction of the front half (scalar or one per sensor).
    - `inv_omega0_sq_s2`: $1/\\omega_0^2$ with $\\omega_0 = 2\\pi f_0$, s^2 (0: rigid sensor).
    """
    beads = checked_beads(beads, model.kappa.shape[0])
    shape = (len(beads),)
    beta = jnp.broadcast_to(jnp.asarray(beta, dtype=jnp.float64), shape)
    inv = jnp.broadcast_to(jnp.asarray(inv_omega0_sq_s2, dtype=jnp.float64), shape)
    back, front, reduced = compliances(model.mass_kg[np.asarray(beads, dtype=int)], beta, inv)
    sensors = CompliantSensorModel(beads=beads, beta=beta, inv_omega0_sq_s2=inv, back_m_n=back, front_m_n=front,
                                   reduced_mass_kg=reduced)
    return dataclasses.replace(model, compliant=sensors)


def checked_beads(beads, n_contacts: int) -> tuple[int, ...]:
    """`beads` as a tuple of ints, each with a contact on both sides (1..n_contacts - 1, the
    chain's internal contacts 0..n_contacts - 1), none twice; else a ValueError."""
    beads = tuple(int(b) for b in beads)
    for bead in beads:
        if not 1 <= bead <= n_contacts - 1:
            raise ValueError(f"sensor beads: bead {bead} has no contact on both sides (beads 1..{n_contacts - 1}).")
    if len(set(beads)) != len(beads):
        raise ValueError(f"sensor beads: {beads} lists a bead twice.")
    return beads


def shortened(beads, back_m_n, front_m_n, amount, values):
    """`values` of every contact (the internal contacts on axis 0, wall or none after them;
    overlaps, m, or their rates, m/s) less what sensors in `beads` (static) of compliances
    `back_m_n`, `front_m_n` (m/N) compressed by `amount` (N, or N/s: the sensors on axis 0
    of all three) take from their back (K-1) and front (K) contacts.

    One scatter into `values` itself: only the sensors' rows are touched. (A batched
    kernel's forward run with 3 sensors, 21 beads, 4 chains, damped, took 1.9 times its run
    without sensors so, overlaps and rates shortened in one call (`batched`), 2.2 times in
    two; with a scatter into zeros subtracted afterwards 3.4 times, with products of one-hot
    rows over every contact 4.2 times, with a concatenation of rows 6 times.)"""
    rows = np.concatenate([np.asarray(beads, dtype=int) - 1, np.asarray(beads, dtype=int)])
    lost = jnp.concatenate([back_m_n * amount, front_m_n * amount])
    return values.at[rows].add(-lost, unique_indices=len(set(rows.tolist())) == rows.size,
                               mode="promise_in_bounds")


def shortened_by_model(model: ChainModel, amount, values) -> jax.Array:
    """`shortened` by the model's compliant sensors (`values` unchanged without)."""
    sensors = model.compliant
    if sensors is None:
        return values
    return shortened(sensors.beads, sensors.back_m_n, sensors.front_m_n, amount, values)


def drive(beta, back_force_n, front_force_n):
    """$\\beta F_{K-1} + (1-\\beta) F_K$ of each sensor, N, from its back and front contact forces."""
    return beta * back_force_n + (1.0 - beta) * front_force_n


def sensor_drive(model: ChainModel, contact_force_n) -> jax.Array:
    """`drive` of each of the model's sensors, N: (n_sensors,)."""
    sensors = model.compliant
    back, front = contacts_of(sensors.beads, contact_force_n)
    return drive(sensors.beta, back, front)


def contacts_of(beads, contact_values):
    """(back, front): the rows K-1 and K of `contact_values` (internal contacts on axis 0) of
    every bead K of `beads` (static slices, stacked)."""
    return (jnp.stack([contact_values[bead - 1] for bead in beads]),
            jnp.stack([contact_values[bead] for bead in beads]))


def is_quasi_static(inv_omega0_sq_s2, dt_s: float) -> jax.Array:
    """True for sensors whose resonance the step does not resolve ($\\omega_0 \\Delta t > 1$)."""
    return inv_omega0_sq_s2 < dt_s**2


def sensor_accel(inv_omega0_sq_s2, drive_n, sensor_force_n, quasi_static) -> jax.Array:
    """$\\ddot F_s$, N/s^2 (0 for quasi-static sensors)."""
    inv = jnp.where(quasi_static, 1.0, inv_omega0_sq_s2)
    return jnp.where(quasi_static, 0.0, (drive_n - sensor_force_n) / inv)


def drift(inv_omega0_sq_s2, dt_s: float, force_n, rate_n_s, drive_n):
    """A step's first half kick and drift of the sensor forces (Eq. 4; quasi-static sensors
    take the previous step's drive): (force N, half-step rate N/s, predicted end rate N/s,
    quasi-static), elementwise."""
    h = 0.5 * dt_s
    quasi_static = is_quasi_static(inv_omega0_sq_s2, dt_s)
    accel = sensor_accel(inv_omega0_sq_s2, drive_n, force_n, quasi_static)
    half_rate = rate_n_s + h * accel
    force = jnp.where(quasi_static, drive_n, force_n + dt_s * half_rate)
    return force, half_rate, half_rate + h * accel, quasi_static


def kick(inv_omega0_sq_s2, dt_s: float, force_n, half_rate_n_s, drive_n, quasi_static):
    """A step's second half kick: the sensor rates at its end, N/s, from the new drive (N)."""
    accel = sensor_accel(inv_omega0_sq_s2, drive_n, force_n, quasi_static)
    return jnp.where(quasi_static, 0.0, half_rate_n_s + 0.5 * dt_s * accel)


def sensor_energies(model: ChainModel, sensor_force_n, sensor_rate_n_s):
    """Spring energy $c F_s^2/2$ and internal kinetic energy $\\mu (c\\dot F_s)^2/2$, J (summed)."""
    sensors = model.compliant
    if sensors is None:
        return jnp.zeros(()), jnp.zeros(())
    compliance = sensors.back_m_n + sensors.front_m_n
    spring = 0.5 * jnp.sum(compliance * sensor_force_n**2)
    kinetic = 0.5 * jnp.sum(sensors.reduced_mass_kg * (compliance * sensor_rate_n_s) ** 2)
    return spring, kinetic
