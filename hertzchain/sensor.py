"""The embedded force sensor of Job et al. (Eq. 4): forward model and FFT deconvolution.

A sensor inside bead K splits it into a back half of mass $(1-\\beta)m$ (touched by contact
K-1, force $F_-$, hit first) and a front half of mass $\\beta m$ (touched by contact K,
force $F_+$) joined by a stiff spring. The spring force $F_s$ obeys

$$\\ddot F_s + \\omega_0^2F_s = \\omega_0^2[(1-\\beta)F_+ + \\beta F_-],\\qquad
\\omega_0 = 2\\pi f_0$$

(paper: $\\beta$ = 0.11, $f_0$ = 85 kHz). For a wave travelling at speed $v$,
$F_-(t) = F_+(t + t_0)$ with $t_0 = 2R/v$, so $F_s$ is a known linear filter of $F_+$ alone
and can be inverted. The core simulator models the sensor mechanically
(`ChainSetup(sensor_beads=...)`, channel `sensor_K`); `sensor_signal` is the same equation
applied to given contact forces, and `deconvolve_sensor` recovers $F_+$ from a measured
$F_s$.
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np

from .pulses import estimate_noise_std_n


def sensor_delay_s(bead_radius_m, speed_m_s):
    """The delay $t_0 = 2R/v$ between the two contacts of a sensor bead, s."""
    return 2.0 * bead_radius_m / speed_m_s


def sensor_signal(time_s, front_force_n, back_force_n, *, beta, f0_hz):
    """Sensor force $F_s$ of Eq. (4) driven by the contact forces of the sensor bead, N.

    Exact discretisation: the drive $u = (1-\\beta)F_+ + \\beta F_-$ is taken as linear between
    samples (first-order hold), and over each interval the oscillator is advanced with its
    exact solution ($F_s - u$ oscillates freely at $\\omega_0$ when $u$ is linear), so the only
    error is the interpolation of the drive (second order in the sampling interval; exact
    for piecewise-linear forces, with no stability limit). The sensor starts at rest and in
    equilibrium with the first sample ($F_s = u$, $\\dot F_s$ = the drive's slope), which is
    the state of a sensor before the pulse arrives.

    **Arguments:**

    - `time_s`: (n,) evenly spaced times, s.
    - `front_force_n`: (..., n) $F_+$, the force at contact K (the wall side), N.
    - `back_force_n`: (..., n) $F_-$, the force at contact K-1 (the striker side), N.
    - `beta`: mass fraction of the front half; `f0_hz`: resonance $f_0$, Hz.

    **Returns:** (..., n) $F_s$, N. Differentiable in every argument.
    """
    time_s = jnp.asarray(time_s, dtype=jnp.float64)
    drive = (1.0 - beta) * jnp.asarray(front_force_n) + beta * jnp.asarray(back_force_n)
    step = time_s[1] - time_s[0]
    omega = 2.0 * jnp.pi * jnp.asarray(f0_hz, dtype=jnp.float64)
    cos, sin = jnp.cos(omega * step), jnp.sin(omega * step)
    drive_t = jnp.moveaxis(drive, -1, 0)
    slopes = (drive_t[1:] - drive_t[:-1]) / step

    def advance(state, inputs):
        value, rate = state
        u0, u1, slope = inputs
        e, e_rate = value - u0, rate - slope
        e, e_rate = e * cos + e_rate * sin / omega, -e * omega * sin + e_rate * cos
        new = (e + u1, e_rate + slope)
        return new, new[0]

    state0 = (drive_t[0], slopes[0])
    _, values = jax.lax.scan(advance, state0, (drive_t[:-1], drive_t[1:], slopes))
    return jnp.moveaxis(jnp.concatenate([drive_t[:1], values], axis=0), 0, -1)


def sensor_transfer(frequency_hz, *, beta, f0_hz, delay_s):
    """Transfer function $\\hat F_s/\\hat F_+$ of the sensor for a travelling wave.

    $H(\\omega) = [(1-\\beta) + \\beta e^{i\\omega t_0}]/(1 - \\omega^2/\\omega_0^2)$, for the
    $e^{-i\\omega t}$ forward Fourier convention of `numpy.fft` (the back force leads by
    $t_0$). It never vanishes below $f_0$ because $|1 - 2\\beta| > 0$ for $\\beta < 1/2$.
    """
    omega = 2.0 * jnp.pi * jnp.asarray(frequency_hz)
    omega0 = 2.0 * jnp.pi * f0_hz
    mix = (1.0 - beta) + beta * jnp.exp(1j * omega * delay_s)
    return mix / (1.0 - (omega / omega0) ** 2)


def wiener_cutoff_hz(time_s, sensor_n, noise_std_n, *, pad_factor=4, smooth_bins=9):
    """Frequency above which the signal's spectrum is below the noise, Hz.

    The periodogram of the zero-padded signal is smoothed over `smooth_bins` bins and
    compared with the white-noise level $n\\sigma^2$ (n: samples of the record); the cutoff is
    the lowest frequency where it falls below twice that level (signal-to-noise power 1).
    Returns the Nyquist frequency when the noise is zero.
    """
    time = np.asarray(time_s, dtype=float)
    signal = np.asarray(sensor_n, dtype=float)
    step = time[1] - time[0]
    nyquist = 0.5 / step
    if not noise_std_n > 0:
        return float(nyquist)
    n_fft = pad_factor * signal.shape[-1]
    power = np.abs(np.fft.rfft(signal, n=n_fft)) ** 2
    kernel = np.ones(smooth_bins) / smooth_bins
    smoothed = np.convolve(power, kernel, mode="same")
    level = 2.0 * signal.shape[-1] * noise_std_n**2
    frequencies = np.fft.rfftfreq(n_fft, step)
    below = np.nonzero(smoothed < level)[0]
    return float(frequencies[below[0]]) if below.size else float(nyquist)


def deconvolve_sensor(
    time_s,
    sensor_n,
    *,
    beta,
    f0_hz,
    delay_s,
    noise_std_n=None,
    cutoff_hz=None,
    pad_factor=4,
    which="front",
):
    """Recover the contact force $F_+$ (or $F_-$) from the sensor signal by FFT, N.

    $\\hat F_+ = L(f)\\,\\hat F_s/H(\\omega)$ with `sensor_transfer` $H$. The exact inverse
    multiplies by $1 - \\omega^2/\\omega_0^2$, which amplifies noise as $f^2$; the low-pass
    $L(f) = 1/(1 + (f/f_c)^8)$ suppresses it. Its cutoff $f_c$ is `cutoff_hz`, or else the
    frequency where the signal spectrum meets the noise floor (`wiener_cutoff_hz`, noise
    from `noise_std_n` or estimated from the signal), at most $2f_0$: a Wiener-type choice
    that keeps every frequency where the signal dominates (the cap stops the $f^2$ gain
    acting on round-off and on ringing at the record's ends, and Eq. 4, a single
    resonance, says nothing reliable far above $f_0$). A solitary pulse of $2\\tau$ = 150 us
    has no power worth keeping above a few tens of kHz, so the low-pass leaves the pulse
    itself intact (peak error 1e-3 without noise, mostly from $t_0$). The signal is
    zero-padded `pad_factor` times so that the circular shift by $t_0$ does not wrap around;
    it should return to zero at both ends.

    **Arguments:**

    - `time_s`: (n,) evenly spaced times, s; `sensor_n`: (n,) sensor force $F_s$, N.
    - `beta`, `f0_hz`: the sensor's mass ratio and resonance, Hz.
    - `delay_s`: $t_0 = 2R/v$ (`sensor_delay_s`, with $v$ from the time of flight), s.
    - `noise_std_n`, `cutoff_hz`: see above (`cutoff_hz = inf` disables the low-pass).
    - `which`: `"front"` for $F_+$ (contact K), `"back"` for $F_-$ (contact K-1).

    **Returns:** (n,) the force, N. Differentiable in `sensor_n`, `beta`, `f0_hz`,
    `delay_s` for a given cutoff.
    """
    if which not in ("front", "back"):
        raise ValueError(f"which must be 'front' or 'back', got {which!r}.")
    if not 0.0 < float(beta) < 0.5:
        raise ValueError(f"beta must be in (0, 0.5) for the inverse to exist, got {beta!r}.")
    time = np.asarray(time_s, dtype=float)
    n = time.shape[0]
    step = float(time[1] - time[0])
    if cutoff_hz is None:
        noise = estimate_noise_std_n(sensor_n) if noise_std_n is None else float(noise_std_n)
        cutoff_hz = min(
            wiener_cutoff_hz(time, sensor_n, noise, pad_factor=pad_factor), 2.0 * float(f0_hz)
        )
    n_fft = pad_factor * n
    frequency = jnp.asarray(np.fft.rfftfreq(n_fft, step))
    spectrum = jnp.fft.rfft(jnp.asarray(sensor_n, dtype=jnp.float64), n=n_fft)
    lowpass = 1.0 if math.isinf(cutoff_hz) else 1.0 / (1.0 + (frequency / cutoff_hz) ** 8)
    front = spectrum * lowpass / sensor_transfer(frequency, beta=beta, f0_hz=f0_hz, delay_s=delay_s)
    if which == "back":
        front = front * jnp.exp(1j * 2.0 * jnp.pi * frequency * delay_s)
    return jnp.fft.irfft(front, n=n_fft)[:n]
