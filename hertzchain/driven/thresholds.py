"""The period-doubling threshold of a driven chain, by continuation in drive amplitude.

At a drive frequency f the chain's period-1 orbit (`hertzchain.driven.floquet`) period-doubles
where a real Floquet multiplier crosses $-1$. The threshold is the root in drive amplitude $a$
of the *doubling margin*

$$g(a, \\theta) = \\det(I + M(a, \\theta)) = \\prod_i (1 + \\mu_i),$$

$M$ the monodromy matrix at the orbit, $\\theta$ the chain's constants: a complex pair gives
$|1 + \\mu|^2 > 0$ and a stable real multiplier $1 + \\mu > 0$, so $g > 0$ on a stable
orbit and changes sign exactly where one real multiplier passes $-1$ (no eigenvalues are
computed, and $g$ is smooth in both arguments).

`period_doubling_onsets` follows the orbit from a low amplitude (reached from rest by the
ramp and hold of `lockin_grid`: the upward-sweep branch) to higher ones, each orbit the
Newton polish of the previous one (continuation), the step chosen by the Newton prediction
$a - g/g_a$ and a growth limit; once $g$ changes sign the root is polished by safeguarded
Newton iterations (bisection when a Newton step leaves the bracket). $g_a = \\partial g /
\\partial a$ is one Jacobian-vector product through the period map (forward mode), as are the
columns of $M$. The runs of a batch (one per frequency) advance together.

The threshold's derivative with respect to the chain's constants follows from the implicit
function theorem, $d a^*/d\\theta = -g_\\theta / g_a$ (`onset_tangents`): one more
Jacobian-vector product per direction, at the converged orbit (a Newton step from a fixed
point carries the orbit's own derivative, $-(M - I)^{-1} \\partial P/\\partial\\theta$).

`emulate_loop` runs the lab's loop instead, stepping the amplitude up and down by time
stepping: where f/2 appears going up and where the period-2 response ends coming down.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from . import kernel, measurements
from .chain import DrivenChain
from .floquet import orbit_state, period_map, polished_orbit
from .schedule import HarmonicSchedule, _levels, check_readout, lockin_schedule

# A polished orbit whose period map misses it by more than this (relative) is lost: the
# continuation jumped (a fold of the period-1 branch, or contact loss too abrupt to follow).
ORBIT_TOLERANCE = 1e-8
# The period map's steps, one per loop iteration: the nested forward-mode passes (monodromy
# columns, their amplitude derivative) compile in a third of the time unrolled by 8, and run
# no slower on one or two beads.
_UNROLL = 1


class DoublingOnsets(eqx.Module):
    """Period-doubling thresholds of B runs (one per frequency).

    **Fields:** `frequencies_hz` (B,); `amplitude_m` (B,) the driver amplitude at which a real
    multiplier crosses $-1$, m (NaN where none was found); `found` (B,) bool; `reasons` (B,)
    one sentence per run (`"crossed"`, or why not); `orbit_state` (N, B) the period-1 orbit
    at the threshold (the period map's state, `floquet.orbit_state`: m, m/s, m from the static
    equilibrium; for `onset_tangents`);
    `margin_slope_per_m` (B,) $\\partial g/\\partial a$ there; `evaluations` the batched
    evaluations of $g$ the search took; static `steps_per_period`, `newton_steps`.
    """

    frequencies_hz: np.ndarray
    amplitude_m: np.ndarray
    found: np.ndarray
    reasons: tuple
    orbit_state: np.ndarray
    margin_slope_per_m: np.ndarray
    evaluations: int
    steps_per_period: int = eqx.field(static=True)
    newton_steps: int = eqx.field(static=True)


def doubling_margin(chain: DrivenChain, frequency_hz, amplitude_m, guess, steps_per_period: int,
                    newton_steps: int, unroll: int = kernel.DEFAULT_UNROLL):
    """$g = \\det(I + M)$ at the period-1 orbit that `newton_steps` Newton steps polish from
    `guess` (N, B; the period map's state, `floquet.orbit_state`), at `frequency_hz`,
    `amplitude_m` (B,) (traceable in every argument). With micro-slip supports each slider
    stuck through the period contributes a factor $1 + 1 = 2$: $g$ keeps its sign, and jumps
    where a slider starts or stops slipping (the map is piecewise smooth, `floquet`).
    **Returns:** (g (B,), orbit (N, B), relative orbit residual $|P(z) - z|/|z|$ (B,))."""
    advance = period_map(chain, frequency_hz, amplitude_m, steps_per_period, unroll)
    z, monodromy, residual = polished_orbit(advance, guess, newton_steps, chain.n_beads)
    return jnp.linalg.det(jnp.eye(z.shape[0]) + monodromy), z, residual


@eqx.filter_jit
def _margin_and_slope(chain, frequency_hz, amplitude_m, guess, steps_per_period, newton_steps):
    def margin(a):
        g, z, residual = doubling_margin(chain, frequency_hz, a, guess, steps_per_period, newton_steps, _UNROLL)
        return g, (z, residual)

    g, slope, (z, residual) = jax.jvp(margin, (amplitude_m,), (jnp.ones_like(amplitude_m),), has_aux=True)
    return g, slope, z, residual


@eqx.filter_jit
def _ramped_orbit(chain, frequency_hz, amplitude_m, steps_per_period, ramp_periods, hold_periods):
    schedule = HarmonicSchedule(frequency_hz[None], amplitude_m[None], steps_per_period, ramp_periods, hold_periods, 0)
    _, _, state = _levels(chain, schedule, steps_per_period, lambda s, u, u_dot: u, kernel.DEFAULT_UNROLL)
    return orbit_state(state)


def period_doubling_onsets(chain: DrivenChain, frequencies_hz, *, lowest_amplitude_m: float,
                           highest_amplitude_m: float, growth: float = 1.25, rtol: float = 1e-6,
                           steps_per_period: int = 48, ramp_periods: int = 25, hold_periods: int = 35,
                           newton_steps: int = 4, max_evaluations: int = 80) -> DoublingOnsets:
    """The period-doubling threshold at each of `frequencies_hz` (B,), searched between
    `lowest_amplitude_m` and `highest_amplitude_m` (driver amplitude, m) by continuation (see
    the module docstring): steps of at most ×`growth`, the root polished to `rtol` (relative).
    The orbit at the lowest amplitude is reached from rest by `ramp_periods` + `hold_periods`
    (the upward-sweep branch). Concrete inputs; `chain`'s constants are not traced here
    (`onset_tangents` gives the derivatives).

    **Returns:** `DoublingOnsets`; a run where the orbit has already doubled at the lowest
    amplitude, does not double up to the highest, or is lost on the way reports why in its
    `reasons` entry, with `found` False and a NaN amplitude.
    """
    f = np.atleast_1d(np.asarray(frequencies_hz, dtype=float))
    check_readout(chain, 1, "velocity", (1.0,), 1, max(hold_periods, 1), steps_per_period, f)
    if not 0 < lowest_amplitude_m < highest_amplitude_m or not np.isfinite(highest_amplitude_m):
        raise ValueError(f"lowest_amplitude_m ({lowest_amplitude_m}) and highest_amplitude_m ({highest_amplitude_m}): "
                         "give 0 < lowest < highest, m.")
    if not growth > 1:
        raise ValueError(f"growth: the largest step's amplitude ratio must be > 1, got {growth}.")
    batch = f.size
    compiled = chain.for_kernel()
    frequency = jnp.asarray(f)
    a = np.full(batch, float(lowest_amplitude_m))
    z = np.asarray(_ramped_orbit(compiled, frequency, jnp.asarray(a), int(steps_per_period), int(ramp_periods),
                                 max(int(hold_periods), 1)))

    def evaluate(amplitude, guess):
        g, slope, orbit, residual = _margin_and_slope(compiled, frequency, jnp.asarray(amplitude), jnp.asarray(guess),
                                                      int(steps_per_period), int(newton_steps))
        return np.asarray(g), np.asarray(slope), np.asarray(orbit), np.asarray(residual)

    g, slope, z, residual = evaluate(a, z)
    evaluations = 1
    reasons = [""] * batch
    lo, hi = a.copy(), np.full(batch, np.nan)
    g_lo, slope_lo, z_lo = g.copy(), slope.copy(), z.copy()
    for i in np.flatnonzero(residual > ORBIT_TOLERANCE):
        reasons[i] = f"no period-1 orbit at the lowest amplitude {lowest_amplitude_m:.4g} m (residual {residual[i]:.2g})"
    for i in np.flatnonzero(g <= 0):
        reasons[i] = reasons[i] or f"already period-doubled at the lowest amplitude {lowest_amplitude_m:.4g} m"
    while evaluations < max_evaluations:
        active = np.array([not r for r in reasons])
        bracketed = active & np.isfinite(hi)
        marching = active & ~bracketed
        if not active.any():
            break
        trial = lo.copy()
        # marching: the Newton prediction of the root, at most x growth, at least 2 % on
        predicted = np.where(slope_lo < 0, lo - g_lo / np.where(slope_lo < 0, slope_lo, -1.0), np.inf)
        step = np.clip(predicted, lo * 1.02, lo * growth)
        trial[marching] = np.minimum(step, highest_amplitude_m)[marching]
        # bracketed: Newton from the lower end, bisection where it leaves the bracket
        newton = lo - g_lo / np.where(slope_lo != 0, slope_lo, np.nan)
        inside = np.isfinite(newton) & (newton > lo) & (newton < hi)
        trial[bracketed] = np.where(inside, newton, 0.5 * (lo + hi))[bracketed]
        g, slope, z, residual = evaluate(trial, z_lo)
        evaluations += 1
        for i in np.flatnonzero(active):
            if residual[i] > ORBIT_TOLERANCE:
                reasons[i] = (f"the period-1 orbit was lost between {lo[i]:.4g} and {trial[i]:.4g} m (residual "
                              f"{residual[i]:.2g}: a fold or a jump of the branch)")
                continue
            if g[i] > 0:
                lo[i], g_lo[i], slope_lo[i], z_lo[:, i] = trial[i], g[i], slope[i], z[:, i]
                if not bracketed[i] and trial[i] >= highest_amplitude_m:
                    reasons[i] = f"no period doubling up to {highest_amplitude_m:.4g} m"
            else:
                hi[i] = trial[i]
            converged = abs(hi[i] - lo[i]) <= rtol * lo[i] or abs(g[i]) < 1e-12
            if (bracketed[i] or g[i] <= 0) and converged:
                lo[i], g_lo[i], slope_lo[i], z_lo[:, i] = trial[i], g[i], slope[i], z[:, i]
                reasons[i] = "crossed"
    for i, reason in enumerate(reasons):
        if not reason:
            reasons[i] = f"not converged in {max_evaluations} evaluations"
    found = np.array([r == "crossed" for r in reasons])
    return DoublingOnsets(f, np.where(found, lo, np.nan), found, tuple(reasons), z_lo, slope_lo, evaluations,
                          int(steps_per_period), int(newton_steps))


@eqx.filter_jit
def _margin_tangents(chain, tangents, frequency_hz, amplitude_m, orbit, steps_per_period, newton_steps):
    def margin(c):
        return doubling_margin(c, frequency_hz, amplitude_m, orbit, steps_per_period, newton_steps, _UNROLL)[0]

    return jax.vmap(lambda t: jax.jvp(margin, (chain,), (t,))[1])(tangents)


def onset_tangents(chain: DrivenChain, onsets: DoublingOnsets, tangents: DrivenChain) -> np.ndarray:
    """$d a^*/d\\theta$ along K directions of the chain's constants: `tangents` is a
    `DrivenChain`-shaped pytree whose every leaf has a leading axis K (e.g. from
    `jax.vmap(lambda d: jax.jvp(build, (x,), (d,))[1])`), `chain` the chain `onsets` was
    found for. **Returns:** (K, B), m per unit of each direction (0 where not found)."""
    found = np.asarray(onsets.found)
    amplitude = np.where(found, onsets.amplitude_m, 1e-9)
    g_theta = _margin_tangents(chain, tangents, jnp.asarray(onsets.frequencies_hz), jnp.asarray(amplitude),
                               jnp.asarray(onsets.orbit_state), onsets.steps_per_period, onsets.newton_steps)
    slope = np.where(found, onsets.margin_slope_per_m, 1.0)
    return np.where(found, -np.asarray(g_theta) / slope, 0.0)


class LoopEmulation(eqx.Module):
    """The lab's amplitude loop run on the model (`emulate_loop`): `drive_amplitudes_m` (S,) the
    steps, `fundamental_m_s`, `subharmonic_m_s` (S,) the lock-in RMS at f and f/2 at the end of
    each, `onset_up_m`, `last_down_m`, `gone_down_m` by the lab's f/2 rule
    (`measurements.loop_thresholds`; NaN where there is none), `periods_per_level`."""

    drive_amplitudes_m: np.ndarray
    fundamental_m_s: np.ndarray
    subharmonic_m_s: np.ndarray
    onset_up_m: float
    last_down_m: float
    gone_down_m: float
    periods_per_level: int


def emulate_loop(chain: DrivenChain, frequency_hz: float, amplitudes_m, *, seconds_per_level: float = 0.25,
                 bead: int = 1, steps_per_period: int = 48, ramp_periods: int = 25, window_periods: int = 4,
                 rule: float = measurements.SUBHARMONIC_RULE) -> LoopEmulation:
    """Step the drive through `amplitudes_m` (S,) (m; up then down, as the lab's sweeper) at
    `frequency_hz`, each level held `seconds_per_level` (the sweeper's 0.25 s between steps,
    whole periods), and read `bead`'s velocity by lock-in at f and f/2 at the end of each level
    (`lockin_schedule`). The f/2 response grows only from what rounding leaves at f/2, so it
    shows once the multiplier's growth over a level lifts it above the rule: past the Floquet
    threshold by the margin the hold allows (the lab's noise seeds it too). The period-2 branch
    it reaches is followed down to where it ends: the model's hysteresis, by time stepping."""
    amplitudes = np.asarray(amplitudes_m, dtype=float)
    periods = max(round(seconds_per_level * frequency_hz), window_periods)
    schedule = HarmonicSchedule.levels(float(frequency_hz), amplitudes, steps_per_period=steps_per_period,
                                       ramp_periods=ramp_periods, periods_per_level=periods)
    reading = lockin_schedule(chain, schedule, bead=bead, harmonics=(1.0, 0.5), window_periods=window_periods)
    rms = np.asarray(reading.rms)[:, :, 0]
    onset, last, gone = measurements.loop_thresholds(amplitudes, measurements.subharmonic_present(rms[0], rms[1], rule))
    return LoopEmulation(amplitudes, rms[0], rms[1], onset, last, gone, periods)
