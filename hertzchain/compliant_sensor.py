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
booked).
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


def with_compliant_sensors(model: ChainModel, beads, *, beta, inv_omega0_sq_s2) -> ChainModel:
    """`model` with embedded sensors in compliance form in `beads` (bead numbers 1..N-1).

    **Arguments:**

    - `model`: a model without split sensor beads (`build_model` of a setup with no
      `sensor_beads`: `solve` checks it).
    - `beads`: bead numbers K; each sensor's back contact is K-1 and its front contact K.
    - `beta`: mass fraction of the front half (scalar or one per sensor).
    - `inv_omega0_sq_s2`: $1/\\omega_0^2$ with $\\omega_0 = 2\\pi f_0$, s^2 (0: rigid sensor).
    """
    beads = tuple(int(b) for b in beads)
    n_beads = model.kappa.shape[0]
    for bead in beads:
        if not 1 <= bead <= n_beads - 1:
            raise ValueError(f"sensor beads: bead {bead} has no contact on both sides (beads 1..{n_beads - 1}).")
    if len(set(beads)) != len(beads):
        raise ValueError(f"sensor beads: {beads} lists a bead twice.")
    shape = (len(beads),)
    beta = jnp.broadcast_to(jnp.asarray(beta, dtype=jnp.float64), shape)
    inv = jnp.broadcast_to(jnp.asarray(inv_omega0_sq_s2, dtype=jnp.float64), shape)
    mass = model.mass_kg[np.asarray(beads, dtype=int)]
    sensors = CompliantSensorModel(
        beads=beads,
        beta=beta,
        inv_omega0_sq_s2=inv,
        back_m_n=inv / ((1.0 - beta) * mass),
        front_m_n=inv / (jnp.maximum(beta, BETA_FLOOR) * mass),
        reduced_mass_kg=jnp.maximum(beta, BETA_FLOOR) * (1.0 - beta) * mass,
    )
    return dataclasses.replace(model, compliant=sensors)


def overlap_offsets(model: ChainModel, sensor_force_n) -> jax.Array:
    """Overlap each internal contact loses to the sensors' compression, m: (n_contacts,)."""
    sensors = model.compliant
    offsets = jnp.zeros_like(model.kappa)
    if sensors is None:
        return offsets
    beads = np.asarray(sensors.beads, dtype=int)
    return offsets.at[beads - 1].add(sensors.back_m_n * sensor_force_n).at[beads].add(
        sensors.front_m_n * sensor_force_n
    )


def sensor_drive(model: ChainModel, contact_force_n) -> jax.Array:
    """$\\beta F_{K-1} + (1-\\beta) F_K$ of each sensor, N: (n_sensors,)."""
    sensors = model.compliant
    beads = np.asarray(sensors.beads, dtype=int)
    return sensors.beta * contact_force_n[beads - 1] + (1.0 - sensors.beta) * contact_force_n[beads]


def is_quasi_static(model: ChainModel, dt_s: float) -> jax.Array:
    """True for sensors whose resonance the step does not resolve ($\\omega_0 \\Delta t > 1$)."""
    return model.compliant.inv_omega0_sq_s2 < dt_s**2


def sensor_accel(model: ChainModel, drive_n, sensor_force_n, quasi_static) -> jax.Array:
    """$\\ddot F_s$, N/s^2 (0 for quasi-static sensors)."""
    inv = jnp.where(quasi_static, 1.0, model.compliant.inv_omega0_sq_s2)
    return jnp.where(quasi_static, 0.0, (drive_n - sensor_force_n) / inv)


def sensor_energies(model: ChainModel, sensor_force_n, sensor_rate_n_s):
    """Spring energy $c F_s^2/2$ and internal kinetic energy $\\mu (c\\dot F_s)^2/2$, J (summed)."""
    sensors = model.compliant
    if sensors is None:
        return jnp.zeros(()), jnp.zeros(())
    compliance = sensors.back_m_n + sensors.front_m_n
    spring = 0.5 * jnp.sum(compliance * sensor_force_n**2)
    kinetic = 0.5 * jnp.sum(sensors.reduced_mass_kg * (compliance * sensor_rate_n_s) ** 2)
    return spring, kinetic
