"""Floquet multipliers of a driven chain's periodic orbit, and the period-doubling threshold.

The period map $P$ advances the beads' state $z = (x, v)$ (2n numbers) by one drive period
at constant amplitude (N velocity-Verlet steps from phase 0). A period-1 orbit is a fixed
point $z^* = P(z^*)$; its monodromy matrix $M = \\partial P/\\partial z$ at $z^*$ is built
column by column from 2n Jacobian-vector products through the period (forward mode, all B
runs at once: the runs are independent, so one tangent per column serves every run), and
its eigenvalues are the Floquet multipliers. The orbit is stable while every $|\\mu| < 1$; a
real multiplier crossing $-1$ is a period doubling (the f/2 response appears), a complex
pair leaving the unit circle a torus (quasi-periodic) bifurcation.

The orbit is found by running the ramp and hold of `lockin_grid` and then polishing with
Newton steps $z \\leftarrow z - (M - I)^{-1}(P(z) - z)$, which converge also to orbits that
are no longer stable (past a threshold), so the multipliers vary smoothly through it.

For a linear damped oscillator the multipliers are $e^{(-\\gamma/2 \\pm i\\omega_d)T}$,
$\\omega_d = \\sqrt{\\omega_0^2 - \\gamma^2/4}$ (the tests check this).
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from . import drive as drives
from . import kernel
from .chain import DrivenChain
from .schedule import HarmonicSchedule, _levels, check_readout


class Floquet(eqx.Module):
    """Floquet analysis of B runs' period-1 orbits.

    **Fields:** `multipliers` (B, 2n) complex, sorted by modulus, largest first;
    `monodromy` (B, 2n, 2n) $\\partial P/\\partial (x, v)$ (state order: displacements of
    beads 1..n, then velocities); `orbit_state` (B, 2n) the orbit's state at phase 0 (m,
    m/s, from the static equilibrium); `orbit_residual` (B,) $|P(z) - z|$ over $|z|$ after the
    Newton steps (small: a converged period-1 orbit); `frequencies_hz`, `amplitudes_m` (B,).
    """

    multipliers: np.ndarray
    monodromy: np.ndarray
    orbit_state: np.ndarray
    orbit_residual: np.ndarray
    frequencies_hz: np.ndarray
    amplitudes_m: np.ndarray

    @property
    def largest_modulus(self) -> np.ndarray:
        """(B,) the largest $|\\mu|$: the orbit is stable where it is below 1."""
        return np.abs(self.multipliers[:, 0])

    @property
    def most_negative_real(self) -> np.ndarray:
        """(B,) the most negative real multiplier (NaN where none is real and negative): it
        crosses -1 at a period doubling."""
        real = np.where(np.abs(self.multipliers.imag) <= 1e-9 * np.abs(self.multipliers), self.multipliers.real,
                        np.inf)
        lowest = np.min(real, axis=1)
        return np.where(lowest < 0.0, lowest, np.nan)


def floquet_multipliers(chain: DrivenChain, frequencies_hz, amplitudes_m, *, steps_per_period: int = 64,
                        ramp_periods: int = 25, hold_periods: int = 35, newton_steps: int = 3,
                        unroll: int = kernel.DEFAULT_UNROLL) -> Floquet:
    """Floquet multipliers of the period-1 orbits at `frequencies_hz` and `amplitudes_m`
    (B,) each (Hz, m; broadcast against each other), reached from rest by the ramp and hold
    of `lockin_grid` (the upward-sweep branch) and polished by `newton_steps` Newton steps.
    Concrete inputs (the eigenvalues are computed on the host). **Returns:** `Floquet`."""
    f, a = np.broadcast_arrays(np.atleast_1d(np.asarray(frequencies_hz, float)),
                               np.atleast_1d(np.asarray(amplitudes_m, float)))
    check_readout(chain, 1, "velocity", (1.0,), 1, max(hold_periods, 1), steps_per_period, f)
    if np.any(f <= 0) or np.any(a < 0) or not np.all(np.isfinite(f) & np.isfinite(a)):
        raise ValueError("frequencies_hz must be > 0 Hz and amplitudes_m >= 0 m (finite).")
    if chain.support_friction is not None:
        raise ValueError("floquet_multipliers: the supports' friction sliders are state the period map in (x, v) "
                         "leaves out (and slip makes it non-smooth); run lockin_schedule instead.")
    if int(newton_steps) != newton_steps or newton_steps < 0:
        raise ValueError(f"newton_steps: expected a whole number >= 0, got {newton_steps}.")
    monodromy, orbit, residual = _monodromy(chain.for_kernel(), jnp.asarray(f), jnp.asarray(a), int(steps_per_period), int(ramp_periods),
                                     int(hold_periods), int(newton_steps), int(unroll))
    monodromy = np.asarray(monodromy)
    multipliers = np.linalg.eigvals(monodromy)
    order = np.argsort(-np.abs(multipliers), axis=1, kind="stable")
    return Floquet(np.take_along_axis(multipliers, order, axis=1), monodromy, np.asarray(orbit).T,
                   np.asarray(residual), f, a)


def period_map(chain: DrivenChain, frequency_hz, amplitude_m, steps_per_period: int,
               unroll: int = kernel.DEFAULT_UNROLL, contact_history_m=None):
    """$P$: the state (2n, B) (displacements then velocities, from the static equilibrium)
    one drive period later, at constant amplitude, starting at phase 0 (traceable). A
    contact law with a history (`laws.Thornton`, ...) starts every period from
    `contact_history_m` (n + 1, B), m, the largest overlaps the run reached: a seated
    contact, whose history the orbit no longer changes, is a parameter of $P$, not a state."""
    p = kernel.kernel_params(chain)
    n = chain.n_beads
    dt = 1.0 / (frequency_hz * steps_per_period)
    drive = drives.harmonic_segment(frequency_hz, dt, steps_per_period, amplitude_m, amplitude_m, 0,
                                    stroke=chain.drive_stroke)

    def advance(z):
        x, v = z[:n], z[n:]
        u, u_dot = drive(jnp.asarray(0))
        force = kernel.contact_forces(p, x, v, u, u_dot, contact_history_m)
        state = kernel.State(x, v, kernel.contact_accel(p, force), contact_history_m)
        state, _ = kernel.advance(p, state, dt, drive, jnp.arange(1, steps_per_period + 1), unroll=unroll)
        return jnp.concatenate([state.displacement_m, state.velocity_m_s])

    return advance


@eqx.filter_jit
def _monodromy(chain, frequency_hz, amplitude_m, steps_per_period, ramp_periods, hold_periods, newton_steps, unroll):
    schedule = HarmonicSchedule(frequency_hz[None], amplitude_m[None], steps_per_period, ramp_periods,
                                max(hold_periods, 1), 0)
    _, _, state = _levels(chain, schedule, steps_per_period, lambda s, u, u_dot: u, unroll)
    z = jnp.concatenate([state.displacement_m, state.velocity_m_s])
    advance = period_map(chain, frequency_hz, amplitude_m, steps_per_period, unroll, state.contact_history_m)
    size = z.shape[0]

    def linearise(z):
        def column(i):
            tangent = jnp.zeros_like(z).at[i].set(1.0)
            return jax.jvp(advance, (z,), (tangent,))

        images, columns = jax.vmap(column)(jnp.arange(size))  # (2n, 2n, B): column i of every run
        return images[0], jnp.moveaxis(columns, -1, 0).swapaxes(1, 2)  # P(z) (2n, B), M (B, 2n, 2n)

    for _ in range(newton_steps):
        image, monodromy = linearise(z)
        step = jnp.linalg.solve(monodromy - jnp.eye(size), (image - z).T[..., None])[..., 0]
        z = z - step.T
    image, monodromy = linearise(z)
    residual = jnp.linalg.norm(image - z, axis=0) / jnp.maximum(jnp.linalg.norm(z, axis=0), 1e-300)
    return monodromy, z, residual


def period_doubling_threshold(chain: DrivenChain, frequency_hz: float, amplitudes_m, **options) -> float:
    """The drive amplitude (m) at which the period-1 orbit at `frequency_hz` first
    period-doubles along the increasing `amplitudes_m` (a real multiplier crossing -1;
    linear interpolation of $\\mu + 1$ between the two amplitudes that bracket it), or NaN
    if it does not within them. `options` go to `floquet_multipliers`."""
    amplitudes = np.asarray(amplitudes_m, float)
    if amplitudes.ndim != 1 or amplitudes.size < 2 or np.any(np.diff(amplitudes) <= 0):
        raise ValueError("amplitudes_m: expected at least two increasing drive amplitudes (m).")
    floquet = floquet_multipliers(chain, np.full_like(amplitudes, frequency_hz), amplitudes, **options)
    margin = np.nan_to_num(floquet.most_negative_real, nan=0.0) + 1.0  # < 0 once doubled
    crossed = np.flatnonzero(margin < 0.0)
    if crossed.size == 0:
        return float("nan")
    i = crossed[0]
    if i == 0:
        return float(amplitudes[0])
    lo, hi = margin[i - 1], margin[i]
    return float(amplitudes[i - 1] + (amplitudes[i] - amplitudes[i - 1]) * lo / (lo - hi))
