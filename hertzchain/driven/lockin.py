"""Lock-in demodulation over whole periods: the complex amplitude of a signal at a frequency.

For samples $y_k = y(t_0 + k\\Delta t)$, $k = 0..K-1$, whose window $K\\Delta t$ holds whole
periods of $f$, the complex amplitude is

$c = \\frac{2}{K}\\sum_k y_k\\,e^{-i 2\\pi f t_k}$,

so that $y = A\\cos(2\\pi f t + \\varphi)$ gives $c = A e^{i\\varphi}$ exactly (for a signal made
of harmonics of the window below the Nyquist frequency: the rectangle rule is exact on
whole periods). The lab's lock-in reports $R = |c|/\\sqrt2$ (RMS) and the phase $\\varphi$
against its reference $\\cos(2\\pi f t)$; here the reference is the drive's own phase.
"""

from __future__ import annotations

from fractions import Fraction

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ..validation import is_concrete


class AbstractReading(eqx.Module):
    """Lock-in readings held as complex amplitudes $c = Ae^{i\\varphi}$ (the signal's unit),
    with the lab's RMS $|c|/\\sqrt2$ and phase $\\varphi$ (rad, against the reference's cos)."""

    complex_amplitude: eqx.AbstractVar[jax.Array]

    @property
    def rms(self) -> jax.Array:
        return jnp.abs(self.complex_amplitude) / jnp.sqrt(2.0)

    @property
    def phase_rad(self) -> jax.Array:
        return jnp.angle(self.complex_amplitude)


class LockIn(AbstractReading):
    """A lock-in reading: `complex_amplitude` $c = Ae^{i\\varphi}$, `.rms`, `.phase_rad`
    (against $\\cos(2\\pi f t)$)."""

    complex_amplitude: jax.Array


def lockin(signal, sample_interval_s, frequency_hz, *, start_time_s=0.0, axis: int = -1,
           whole_periods_rtol: float = 1e-9) -> LockIn:
    """Demodulate `signal` (samples along `axis`, every `sample_interval_s` seconds from
    `start_time_s`) at `frequency_hz` (any frequency: the drive's, its half, a harmonic).

    The window must hold whole periods of the frequency (checked, to `whole_periods_rtol`,
    where the numbers are concrete): over a fraction of a period the reading would depend
    on where the window starts. `frequency_hz`, `sample_interval_s` and `start_time_s` may be
    arrays that broadcast against the signal with `axis` removed (e.g. one frequency per
    run). **Returns:** `LockIn` over the remaining axes.
    """
    signal = jnp.moveaxis(jnp.asarray(signal), axis, -1)
    count = signal.shape[-1]
    frequency = jnp.asarray(frequency_hz)[..., None]
    interval = jnp.asarray(sample_interval_s)[..., None]
    concrete = is_concrete(frequency_hz) and is_concrete(sample_interval_s)
    cycles = np.asarray(frequency_hz) * np.asarray(sample_interval_s) * count if concrete else None
    if cycles is not None:
        if np.any(np.asarray(frequency_hz) <= 0):
            raise ValueError(f"frequency_hz: must be > 0 Hz, got {np.asarray(frequency_hz)}.")
        if np.any(np.abs(cycles - np.round(cycles)) > whole_periods_rtol * np.maximum(cycles, 1.0)) or np.any(
                np.round(cycles) < 1):
            raise ValueError(
                f"lockin: the window ({count} samples of {np.asarray(sample_interval_s)} s) holds "
                f"{cycles} periods of {np.asarray(frequency_hz)} Hz; it must hold a whole number: trim the "
                "signal or choose the sample interval so that it does."
            )
    time = jnp.asarray(start_time_s)[..., None] + interval * jnp.arange(count)
    return LockIn(2.0 / count * jnp.sum(signal * jnp.exp(-2j * jnp.pi * frequency * time), axis=-1))


def lockin_steps(samples, steps_per_period: int, harmonic: float, first_step) -> LockIn:
    """Demodulate per-step samples of a harmonic drive (`drive.harmonic_segment`) at
    `harmonic` × the drive frequency, with the drive's own phase as reference.

    `samples`: (K, ...) at the global steps `first_step`, `first_step` + 1, ..., whose phase
    is $\\theta_j = 2\\pi j/N$; K × `harmonic` / N must be a whole number (whole periods of the
    demodulated component; checked by the callers, which know K and N statically)."""
    count = samples.shape[0]
    reference = jnp.asarray(step_reference(count, steps_per_period, harmonic, first_step))
    reference = reference.reshape((count,) + (1,) * (samples.ndim - 1))
    return LockIn(2.0 / count * jnp.sum(samples * reference, axis=0))


def step_reference(count: int, steps_per_period: int, harmonic: float, first_step: int) -> np.ndarray:
    """The lock-in's reference $e^{-i\\,2\\pi h j/N}$ at the steps j = `first_step` ..
    `first_step` + `count` - 1 of a harmonic drive of N = `steps_per_period` steps a period,
    (count,) complex: `lockin_steps` sums the samples against it."""
    # Steps reduced modulo a whole number of the component's periods (N × the harmonic's
    # denominator steps), so the phases are exact whatever the run's length.
    period_steps = steps_per_period * Fraction(harmonic).limit_denominator(1000).denominator
    steps = (first_step + np.arange(count)) % period_steps
    phase = (2.0 * np.pi * harmonic / steps_per_period) * steps
    return np.exp(-1j * phase)
