"""Prescribed motions of the driver face: harmonic with smooth amplitude changes, and sampled.

A harmonic drive is $u(t) = a(t)\\cos\\theta$, with the phase advanced by exactly
$2\\pi/N$ per step ($N$ = steps per period, each run's step $\\Delta t = 1/(fN)$), so the
phase at step $j$ is $\\theta_j = 2\\pi (j \\bmod N)/N$ whatever the frequency. A run made of
segments of whole periods, each with its own frequency (and so its own step), is therefore
phase-continuous at every frequency change: the lab's phase-continuous sweep. The
amplitude moves between levels along the quintic smooth step
$S(s) = 10s^3 - 15s^4 + 6s^5$ (zero slope and curvature at both ends), so the drive has
no kink and the chain is not kicked.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp


def smooth_step(s):
    """$S(s) = 10s^3 - 15s^4 + 6s^5$ on $s$ clipped to [0, 1], and $dS/ds$ (0 outside)."""
    inside = (s > 0.0) & (s < 1.0)
    s = jnp.clip(s, 0.0, 1.0)
    value = s**3 * (10.0 + s * (-15.0 + 6.0 * s))
    slope = jnp.where(inside, 30.0 * s**2 * (1.0 - s) ** 2, 0.0)
    return value, slope


def harmonic_segment(frequency_hz, dt_s, steps_per_period: int, from_amplitude_m, to_amplitude_m,
                     ramp_steps: int, first_step: int = 0):
    """The driver's motion through one segment of a harmonic drive, as a function of the
    global step index j (the step's end point, j > `first_step`).

    **Arguments:** `frequency_hz`, `dt_s` (= 1/(f N)), `from_amplitude_m`, `to_amplitude_m`:
    (B,) or scalars, Hz, s, m; the amplitude moves from the first to the second value over
    `ramp_steps` steps after `first_step` (0: at once) along `smooth_step`, then holds.

    **Returns:** `drive(j) -> (u_m, u_m_s)`: displacement (m) and velocity (m/s).
    """
    omega = 2.0 * jnp.pi * frequency_hz
    change = to_amplitude_m - from_amplitude_m
    ramp = max(int(ramp_steps), 0)

    def drive(j):
        theta = (2.0 * jnp.pi / steps_per_period) * jnp.mod(j, steps_per_period).astype(jnp.float64)
        if ramp == 0:
            envelope, envelope_rate = to_amplitude_m + 0.0 * change, 0.0 * change
        else:
            shape, slope = smooth_step((j - first_step).astype(jnp.float64) / ramp)
            envelope = from_amplitude_m + change * shape
            envelope_rate = change * slope / (ramp * dt_s)
        cos, sin = jnp.cos(theta), jnp.sin(theta)
        return envelope * cos, envelope_rate * cos - envelope * omega * sin

    return drive


def sampled(displacement_m: jax.Array, dt_s):
    """A drive given as samples: `displacement_m` (n_steps + 1, B) or (n_steps + 1,), m, the
    driver's displacement at t = 0, dt, 2 dt, ... (the first must be 0: the chain starts at
    rest in its static equilibrium); its velocity by central differences (one-sided at the
    ends), m/s. **Returns:** `drive(j)` for j = 1..n_steps."""
    velocity = jnp.gradient(displacement_m, axis=0) / dt_s

    def drive(j):
        return displacement_m[j], velocity[j]

    return drive
