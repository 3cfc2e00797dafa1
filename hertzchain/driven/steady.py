"""Steady-state detection: drive until successive lock-in windows agree.

`lockin_until_steady` ramps the drive from rest as `lockin_grid` does, then reads the lock-in
over successive windows of `window_periods` whole periods and stops once, for every run,
two successive readings differ by at most `rtol` of the run's largest component (all
harmonics compared), or after `max_windows` windows. It returns the last readings, the
windows each run needed and whether it got there. (`grid.settle_periods` is the other way:
a hold long enough for the slowest transient of a viscously damped chain to decay.)
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp

from . import drive as drives
from . import kernel
from .chain import DrivenChain
from .grid import check_grid_arguments
from .lockin import AbstractReading, lockin_steps
from .schedule import readout


class SteadyLockin(AbstractReading):
    """What `lockin_until_steady` returns.

    **Fields:** `complex_amplitude` (n_harmonics, F, A) of the last window (`.rms`,
    `.phase_rad` as in `LockinGrid`); `windows` (F, A) the windows after the ramp at which
    each run first met the tolerance (`max_windows` + 1 where it never did); `converged`
    (F, A) whether the last two windows agree to the tolerance; `periods_run` (): the
    periods every run was driven after the ramp (all runs stop together)."""

    complex_amplitude: jax.Array
    windows: jax.Array
    converged: jax.Array
    periods_run: jax.Array
    harmonics: tuple[float, ...] = eqx.field(static=True)


def lockin_until_steady(chain: DrivenChain, frequencies_hz, drive_amplitudes_m, *, rtol: float = 1e-4,
                        bead: int = 1, quantity: str = "velocity", harmonics: tuple[float, ...] = (1.0, 0.5),
                        ramp_periods: int = 25, window_periods: int = 4, max_windows: int = 50,
                        steps_per_period: int = 64, contact: int | None = None,
                        unroll: int = kernel.DEFAULT_UNROLL) -> SteadyLockin:
    """Lock-in over the grid `frequencies_hz` (F,) × `drive_amplitudes_m` (A,), driven until
    steady (see the module docstring; arguments as `lockin_grid`'s, `rtol` relative, and at
    most `max_windows` windows after the ramp). Forward-mode differentiable (the number of
    windows is decided by the values, not differentiated)."""
    harmonics = tuple(float(h) for h in harmonics)
    check_grid_arguments(chain, frequencies_hz, drive_amplitudes_m, bead, quantity, harmonics, ramp_periods,
                         window_periods, window_periods, steps_per_period, contact)
    if int(max_windows) != max_windows or max_windows < 2:
        raise ValueError(f"max_windows: at least 2 windows to compare, got {max_windows}.")
    if not rtol > 0:
        raise ValueError(f"rtol: a relative tolerance > 0, got {rtol}.")
    return _until_steady(chain.for_kernel(), jnp.asarray(frequencies_hz, dtype=jnp.float64),
                         jnp.asarray(drive_amplitudes_m, dtype=jnp.float64), float(rtol), int(bead), quantity,
                         harmonics, int(ramp_periods), int(window_periods), int(max_windows), int(steps_per_period),
                         int(unroll), None if contact is None else int(contact))


@eqx.filter_jit
def _until_steady(chain, frequencies_hz, drive_amplitudes_m, rtol, bead, quantity, harmonics, ramp_periods,
                  window_periods, max_windows, steps_per_period, unroll, contact):
    n_freq, n_amp = frequencies_hz.shape[0], drive_amplitudes_m.shape[0]
    frequency = jnp.repeat(frequencies_hz, n_amp)
    amplitude = jnp.tile(drive_amplitudes_m, n_freq)
    p = kernel.kernel_params(chain)
    n = steps_per_period
    dt = 1.0 / (frequency * n)
    drive = drives.harmonic_segment(frequency, dt, n, 0.0 * amplitude, amplitude, ramp_periods * n,
                                    stroke=chain.drive_stroke)
    state, _ = kernel.advance(p, kernel.static_state(p, frequency), dt, drive, jnp.arange(1, ramp_periods * n + 1),
                              unroll=unroll)
    record = readout(chain, quantity, bead, contact)
    window = window_periods * n

    def read(state):
        # the phase of step j is 2 pi j / N: windows are whole periods, so every window's
        # first step has the phase of the step after the ramp
        state, samples = kernel.advance(p, state, dt, drive, jnp.arange(1, window + 1) + ramp_periods * n,
                                        record=record, unroll=unroll)
        first = ramp_periods * n + 1
        return state, jnp.stack([lockin_steps(samples, n, h, first).complex_amplitude for h in harmonics])

    state, first = read(state)
    batch = frequency.shape[0]

    def agree(new, old):
        scale = jnp.max(jnp.abs(new), axis=0)
        return jnp.all(jnp.abs(new - old) <= rtol * scale, axis=0)

    def unfinished(carry):
        count, _, _, ok, _ = carry
        return (count < max_windows) & ~jnp.all(ok)

    def body(carry):
        count, state, old, _, done = carry
        state, new = read(state)
        ok = agree(new, old)
        done = jnp.where((done > max_windows) & ok, count + 1, done)
        return count + 1, state, new, ok, done

    never = jnp.full((batch,), max_windows + 1)
    count, _, last, ok, done = jax.lax.while_loop(
        unfinished, body, (jnp.asarray(1), state, first, jnp.zeros((batch,), bool), never))
    return SteadyLockin(
        complex_amplitude=last.reshape(len(harmonics), n_freq, n_amp),
        windows=done.reshape(n_freq, n_amp),
        converged=ok.reshape(n_freq, n_amp),
        periods_run=count * window_periods,
        harmonics=harmonics,
    )
