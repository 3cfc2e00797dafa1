"""Floquet multipliers of a driven chain's periodic orbit, and the period-doubling threshold.

The period map $P$ advances the chain's state $z$ by one drive period at constant amplitude
(N velocity-Verlet steps from phase 0): the beads' $(x, v)$ (2n numbers) and, on micro-slip
supports (`laws.IwanSupport`, E sliders a bead), the sliders' positions $s$ (E n more: they
are state, the force depends on them). A period-1 orbit is a fixed point $z^* = P(z^*)$;
its monodromy matrix $M = \\partial P/\\partial z$ at $z^*$ is built column by column from
Jacobian-vector products through the period (forward mode, all B runs at once: the runs are
independent, so one tangent per column serves every run), and its eigenvalues are the
Floquet multipliers. The orbit is stable while every $|\\mu| < 1$; a real multiplier crossing
$-1$ is a period doubling (the f/2 response appears), a complex pair leaving the unit circle
a torus (quasi-periodic) bifurcation.

$M$ is the exact derivative of the discretised map. With sliders that map is piecewise
smooth: a slider either sticks through a step (it keeps its position) or slips (it follows
the bead at its limit $\\pm\\phi_j$), and $M$ jumps where the set of steps at which some
slider slips changes (with the state, the amplitude or the frequency). On a period-1 orbit
each slider either slips both ways every period or sticks throughout; a slider stuck
throughout keeps its position exactly, so its row of $M$ is exactly a unit row and
$\\det(M - \\lambda I) = (1 - \\lambda)^k \\det(M_r - \\lambda I)$, $M_r$ the monodromy with the k
stuck sliders' rows and columns left out. Those k multipliers of exactly 1 are neutral, not
an instability: a stuck slider moved a little is another period-1 orbit (the bead settles
about a shifted spring), neither approached nor left. `Floquet` reports them apart
(`neutral`), and stability, period doubling and tori are read from the multipliers of
$M_r$ alone.

The orbit is found by running the ramp and hold of `lockin_grid` and then polishing with
Newton steps $z \\leftarrow z - (M - I)^{-1}(P(z) - z)$, which converge also to orbits that
are no longer stable (past a threshold), so the multipliers vary smoothly through it (between
the slip pattern's jumps). The stuck sliders' rows of $M - I$ vanish: the Newton step keeps
them where they are and solves the others' equations.

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

    **Fields:** `multipliers` (B, N) complex, N = 2n (+ E n with micro-slip supports): the
    multipliers of the dynamics sorted by modulus, largest first, then those of the sliders
    stuck throughout the period, exactly 1; `neutral` (B, N) bool, True at those stuck
    sliders' multipliers (see the module docstring: they are not an instability);
    `monodromy` (B, N, N) $\\partial P/\\partial z$ (state order: displacements of beads 1..n,
    then velocities, then the sliders' positions, element by element, beads 1..n within
    each); `orbit_state` (B, N) the orbit's state at phase 0 (m, m/s, m, from the static
    equilibrium); `stuck_sliders` (B, E, n) bool, the sliders that stick through the
    period (None without micro-slip supports); `orbit_residual` (B,) $|P(z) - z|$ over $|z|$
    after the Newton steps (small: a converged period-1 orbit); `frequencies_hz`,
    `amplitudes_m` (B,).
    """

    multipliers: np.ndarray
    neutral: np.ndarray
    monodromy: np.ndarray
    orbit_state: np.ndarray
    stuck_sliders: np.ndarray | None
    orbit_residual: np.ndarray
    frequencies_hz: np.ndarray
    amplitudes_m: np.ndarray

    @property
    def largest_modulus(self) -> np.ndarray:
        """(B,) the largest $|\\mu|$ of the dynamics (the stuck sliders' neutral 1s left
        out): the orbit is stable where it is below 1."""
        return np.max(np.where(self.neutral, 0.0, np.abs(self.multipliers)), axis=1)

    @property
    def most_negative_real(self) -> np.ndarray:
        """(B,) the most negative real multiplier (NaN where none is real and negative): it
        crosses -1 at a period doubling."""
        real = np.where(np.abs(self.multipliers.imag) <= 1e-9 * np.abs(self.multipliers), self.multipliers.real,
                        np.inf)
        lowest = np.min(np.where(self.neutral, np.inf, real), axis=1)
        return np.where(lowest < 0.0, lowest, np.nan)


def floquet_multipliers(chain: DrivenChain, frequencies_hz, amplitudes_m, *, steps_per_period: int = 64,
                        ramp_periods: int = 25, hold_periods: int = 35, newton_steps: int = 3,
                        unroll: int = kernel.DEFAULT_UNROLL) -> Floquet:
    """Floquet multipliers of the period-1 orbits at `frequencies_hz` and `amplitudes_m`
    (B,) each (Hz, m; broadcast against each other), reached from rest by the ramp and hold
    of `lockin_grid` (the upward-sweep branch) and polished by `newton_steps` Newton steps.
    With micro-slip supports the sliders are part of the state (see the module docstring).
    Concrete inputs (the eigenvalues are computed on the host). **Returns:** `Floquet`."""
    f, a = np.broadcast_arrays(np.atleast_1d(np.asarray(frequencies_hz, float)),
                               np.atleast_1d(np.asarray(amplitudes_m, float)))
    check_readout(chain, 1, "velocity", (1.0,), 1, max(hold_periods, 1), steps_per_period, f)
    if np.any(f <= 0) or np.any(a < 0) or not np.all(np.isfinite(f) & np.isfinite(a)):
        raise ValueError("frequencies_hz must be > 0 Hz and amplitudes_m >= 0 m (finite).")
    if int(newton_steps) != newton_steps or newton_steps < 0:
        raise ValueError(f"newton_steps: expected a whole number >= 0, got {newton_steps}.")
    monodromy, orbit, residual = _monodromy(chain.for_kernel(), jnp.asarray(f), jnp.asarray(a), int(steps_per_period),
                                            int(ramp_periods), int(hold_periods), int(newton_steps), int(unroll))
    monodromy = np.asarray(monodromy)
    n = chain.n_beads
    stuck = np.asarray(stuck_rows(jnp.asarray(monodromy), n))
    multipliers = np.ones(stuck.shape, dtype=complex)
    for run in range(f.size):
        keep = ~stuck[run]
        values = np.linalg.eigvals(monodromy[run][np.ix_(keep, keep)])
        multipliers[run, :values.size] = values[np.argsort(-np.abs(values), kind="stable")]
    neutral = np.sort(stuck, axis=1)  # the dynamics' multipliers first, the stuck sliders' 1s last
    sliders = None
    if chain.support_friction is not None:
        sliders = stuck[:, 2 * n:].reshape(f.size, chain.support_friction.elements, n)
    return Floquet(multipliers, neutral, monodromy, np.asarray(orbit).T, sliders, np.asarray(residual), f, a)


def orbit_state(state: kernel.State) -> jax.Array:
    """The period map's state (N, B) of a kernel state: displacements, velocities and (with
    micro-slip supports) the sliders' positions, element by element."""
    parts = [state.displacement_m, state.velocity_m_s]
    if state.support_slider_m is not None:
        parts.append(state.support_slider_m.reshape(-1, state.support_slider_m.shape[-1]))
    return jnp.concatenate(parts)


def period_map(chain: DrivenChain, frequency_hz, amplitude_m, steps_per_period: int,
               unroll: int = kernel.DEFAULT_UNROLL, contact_history_m=None):
    """$P$: the state (N, B) (displacements, velocities, and with micro-slip supports the
    sliders' positions, as `orbit_state`; from the static equilibrium) one drive period
    later, at constant amplitude, starting at phase 0 (traceable). A contact law with a
    history (`laws.Thornton`, ...) starts every period from `contact_history_m` (n + 1, B),
    m, the largest overlaps the run reached: a seated contact, whose history the orbit no
    longer changes, is a parameter of $P$, not a state."""
    p = kernel.kernel_params(chain)
    n = chain.n_beads
    dt = 1.0 / (frequency_hz * steps_per_period)
    drive = drives.harmonic_segment(frequency_hz, dt, steps_per_period, amplitude_m, amplitude_m, 0,
                                    stroke=chain.drive_stroke)

    def advance(z):
        x, v = z[:n], z[n:2 * n]
        slider = None if p.support_friction is None else z[2 * n:].reshape((-1, n) + z.shape[1:])
        u, u_dot = drive(jnp.asarray(0))
        force = kernel.contact_forces(p, x, v, u, u_dot, contact_history_m)
        state = kernel.State(x, v, kernel.contact_accel(p, force, x, slider), contact_history_m, slider)
        state, _ = kernel.advance(p, state, dt, drive, jnp.arange(1, steps_per_period + 1), unroll=unroll)
        return orbit_state(state)

    return advance


def linearise(advance, z):
    """$P(z)$ (N, B) and $M = \\partial P/\\partial z$ (B, N, N) of B runs at their states z
    (N, B): N Jacobian-vector products, one per column, each serving every run."""
    def column(i):
        return jax.jvp(advance, (z,), (jnp.zeros_like(z).at[i].set(1.0),))

    images, columns = jax.vmap(column)(jnp.arange(z.shape[0]))  # (N, N, B): column i of every run
    return images[0], jnp.moveaxis(columns, -1, 0).swapaxes(1, 2)


def stuck_rows(monodromy, n_beads: int) -> jax.Array:
    """(B, N) bool: the sliders' coordinates whose row of `monodromy` (B, N, N) is exactly the
    identity's (sliders that stuck through the period; never a bead's x or v)."""
    size = monodromy.shape[-1]
    unit = jnp.all(monodromy == jnp.eye(size), axis=-1)
    return unit & (jnp.arange(size) >= 2 * n_beads)


def newton_step(z, image, monodromy, n_beads: int):
    """One Newton step $z - (M - I)^{-1}(P(z) - z)$ towards the period-1 orbit (z, image: (N, B),
    monodromy (B, N, N)); the stuck sliders' rows of $M - I$ vanish, and so do their residuals:
    they are replaced by unit rows, keeping those sliders in place."""
    size = z.shape[0]
    stuck = stuck_rows(monodromy, n_beads)
    system = monodromy - jnp.eye(size) + stuck[..., None] * jnp.eye(size)
    residual = jnp.where(stuck, 0.0, (image - z).T)
    return z - jnp.linalg.solve(system, residual[..., None])[..., 0].T


def polished_orbit(advance, z, newton_steps: int, n_beads: int):
    """The period-1 orbit `newton_steps` Newton steps (`newton_step`) polish from z (N, B)
    under the period map `advance`. **Returns:** (the orbit (N, B), its monodromy (B, N, N),
    the relative residual $|P(z) - z|/|z|$ (B,))."""
    for _ in range(newton_steps):
        image, monodromy = linearise(advance, z)
        z = newton_step(z, image, monodromy, n_beads)
    image, monodromy = linearise(advance, z)
    residual = jnp.linalg.norm(image - z, axis=0) / jnp.maximum(jnp.linalg.norm(z, axis=0), 1e-300)
    return z, monodromy, residual


@eqx.filter_jit
def _monodromy(chain, frequency_hz, amplitude_m, steps_per_period, ramp_periods, hold_periods, newton_steps, unroll):
    schedule = HarmonicSchedule(frequency_hz[None], amplitude_m[None], steps_per_period, ramp_periods,
                                max(hold_periods, 1), 0)
    _, _, state = _levels(chain, schedule, steps_per_period, lambda s, u, u_dot: u, unroll)
    z = orbit_state(state)
    advance = period_map(chain, frequency_hz, amplitude_m, steps_per_period, unroll, state.contact_history_m)
    z, monodromy, residual = polished_orbit(advance, z, newton_steps, chain.n_beads)
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
