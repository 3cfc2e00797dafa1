"""Prescribed motions of the driver face: harmonic with smooth amplitude changes, and sampled.

A harmonic drive is $u(t) = a(t)\\cos\\theta$, with the phase advanced by exactly
$2\\pi/N$ per step ($N$ = steps per period, each run's step $\\Delta t = 1/(fN)$), so the
phase at step $j$ is $\\theta_j = 2\\pi (j \\bmod N)/N$ whatever the frequency. A run made of
segments of whole periods, each with its own frequency (and so its own step), is therefore
phase-continuous at every frequency change: the lab's phase-continuous sweep. The
amplitude moves between levels along the quintic smooth step
$S(s) = 10s^3 - 15s^4 + 6s^5$ (zero slope and curvature at both ends), so the drive has
no kink and the chain is not kicked.

The driver's stroke per volt may itself depend on the amplitude or the frequency (given to
`DrivenChain` as `drive_stroke`): `RayleighStroke` is a piezo whose $d_{33}$ follows
Rayleigh's law, `ActuatorMode` a face that reaches the calibrated stroke through one mode of
the actuator and its fixture.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp

from ..validation import check_positive_parameters


class RayleighStroke(eqx.Module):
    """A piezo stack whose stroke grows with its drive: Rayleigh's law of soft piezoceramics
    (Damjanovic, J. Appl. Phys. 82, 1788, 1997), $d = d_0 + \\alpha E_0$, with its hysteresis
    $S = (d_0 + \\alpha E_0)E \\pm \\tfrac{\\alpha}{2}(E_0^2 - E^2)$ (+ on the falling branch).
    In terms of the nominal amplitude a (m; the small-signal calibration $d_0E_0$ times the
    stack's length) and the drive's phase $\\theta$ the face moves by

    $u = a(1 + ra)\\cos\\theta + \\tfrac12 ra^2\\,|\\sin\\theta|\\sin\\theta$,

    a fundamental larger by $ra$ and lagging by $\\approx \\tfrac{4}{3\\pi}ra$, and odd
    harmonics: $\\tfrac12 ra^2 \\cdot \\tfrac{8}{\\pi}\\,(\\tfrac13, -\\tfrac1{15}, -\\tfrac1{105}, \\ldots)$
    at 1, 3, 5 f (the sine parts). While the amplitude ramps, the loop of the instantaneous
    amplitude is taken (a quasi-static envelope).

    **Arguments:** `rayleigh_per_m`: r, the stroke's relative growth per metre of nominal
    amplitude, 1/m (>= 0; e.g. 1e6: 10 % more stroke at 100 nm).
    """

    rayleigh_per_m: jax.Array

    def __init__(self, rayleigh_per_m=0.0):
        self.rayleigh_per_m = jnp.asarray(rayleigh_per_m, dtype=jnp.float64)

    def __check_init__(self):
        check_positive_parameters("RayleighStroke", (("rayleigh_per_m", self.rayleigh_per_m, "1/m"),), zero_ok=True)

    def motion(self, amplitude_m, amplitude_rate_m_s, omega_rad_s, cos, sin):
        """The face's displacement (m) and velocity (m/s) at the phase of `cos`, `sin`, for
        the nominal amplitude (m) changing at `amplitude_rate_m_s` (m/s), drive at `omega_rad_s`."""
        r, a = self.rayleigh_per_m, amplitude_m
        loop = jnp.abs(sin) * sin
        gain, hysteresis = a * (1.0 + r * a), 0.5 * r * a**2
        displacement = gain * cos + hysteresis * loop
        velocity = ((1.0 + 2.0 * r * a) * cos + r * a * loop) * amplitude_rate_m_s + omega_rad_s * (
            -gain * sin + hysteresis * 2.0 * jnp.abs(sin) * cos)
        return displacement, velocity


class ActuatorMode(eqx.Module):
    """A driver whose face reaches the calibrated stroke through one mode of the actuator and
    its fixture (the stack's mass on its own stiffness, the fixture's first mode): the face
    follows the small-signal stroke through the one-mode transfer function

    $H(f) = 1 / (1 - (f/f_a)^2 + 2i\\zeta_a f/f_a)$,

    normalised to the calibration at low frequency ($H(0) = 1$): for a nominal amplitude a (m)
    and drive phase $\\theta$ the face moves by $u = a|H|\\cos(\\theta - \\varphi)$, $\\varphi =
    \\arg(1 - (f/f_a)^2 + 2i\\zeta_a f/f_a)$ its lag. $|H| = 1/(2\\zeta_a)$ at $f_a$ and falls as
    $(f_a/f)^2$ above it. The face's motion is prescribed: the bead's reaction on the actuator
    is left out (a stack far heavier and stiffer than the bead's contacts). While the amplitude
    ramps, the envelope is taken as quasi-static.

    **Arguments:** `mode_hz`: $f_a$, the mode's frequency, Hz (> 0); `damping_ratio`:
    $\\zeta_a$ (> 0).
    """

    mode_hz: jax.Array
    damping_ratio: jax.Array

    def __init__(self, mode_hz, damping_ratio):
        self.mode_hz = jnp.asarray(mode_hz, dtype=jnp.float64)
        self.damping_ratio = jnp.asarray(damping_ratio, dtype=jnp.float64)

    def __check_init__(self):
        check_positive_parameters("ActuatorMode", (("mode_hz", self.mode_hz, "Hz"), ("damping_ratio", self.damping_ratio, "1")))

    def transfer(self, frequency_hz):
        """$H(f)$ at `frequency_hz` (Hz): (real part, imaginary part), face over nominal stroke."""
        r = jnp.asarray(frequency_hz) / self.mode_hz
        real, imaginary = 1.0 - r**2, 2.0 * self.damping_ratio * r
        size = real**2 + imaginary**2
        return real / size, -imaginary / size

    def motion(self, amplitude_m, amplitude_rate_m_s, omega_rad_s, cos, sin):
        """The face's displacement (m) and velocity (m/s) at the phase of `cos`, `sin`, for
        the nominal amplitude (m) changing at `amplitude_rate_m_s` (m/s), drive at `omega_rad_s`."""
        real, imaginary = self.transfer(omega_rad_s / (2.0 * jnp.pi))
        shape = real * cos - imaginary * sin  # Re[H e^{i theta}]
        slope = -real * sin - imaginary * cos  # its derivative in theta
        return amplitude_m * shape, amplitude_rate_m_s * shape + amplitude_m * omega_rad_s * slope


# The stroke laws a `DrivenChain` takes as `drive_stroke` (each with `motion`).
DRIVE_STROKES = (RayleighStroke, ActuatorMode)


def smooth_step(s):
    """$S(s) = 10s^3 - 15s^4 + 6s^5$ on $s$ clipped to [0, 1], and $dS/ds$ (0 outside)."""
    inside = (s > 0.0) & (s < 1.0)
    s = jnp.clip(s, 0.0, 1.0)
    value = s**3 * (10.0 + s * (-15.0 + 6.0 * s))
    slope = jnp.where(inside, 30.0 * s**2 * (1.0 - s) ** 2, 0.0)
    return value, slope


def harmonic_segment(frequency_hz, dt_s, steps_per_period: int, from_amplitude_m, to_amplitude_m,
                     ramp_steps: int, first_step: int = 0, stroke=None):
    """The driver's motion through one segment of a harmonic drive, as a function of the
    global step index j (the step's end point, j > `first_step`).

    **Arguments:** `frequency_hz`, `dt_s` (= 1/(f N)), `from_amplitude_m`, `to_amplitude_m`:
    (B,) or scalars, Hz, s, m; the amplitude moves from the first to the second value over
    `ramp_steps` steps after `first_step` (0: at once) along `smooth_step`, then holds.
    `stroke`: the driver's stroke law (one of `DRIVE_STROKES`; None: $a\\cos\\theta$).

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
        if stroke is not None:
            return stroke.motion(envelope, envelope_rate, omega, cos, sin)
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
