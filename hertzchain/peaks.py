"""Peaks and arrivals in sampled force traces: one finder per job, named for the job.

| job | finder |
|---|---|
| the sub-sample vertex of a peak (three samples) | `refine_peak` |
| the first pulse of a simulated trace, under `jit`/`vmap`, differentiable | `first_peak` (its sample: `first_peak_index`) |
| the samples of the first pulse (windows, starting points) | `first_run` |
| the first pulse of a measured, noisy trace | `measured_first_peak` |
| every pulse of one trace, labelled in time order | `find_pulses` (noise level: `estimate_noise_std_n`) |
| the resonances of a measured frequency response (a lock-in sweep's curve) | `frequency_response_peaks` |

The simulated-trace finders are written in `jax.numpy` (batches along leading axes); the
others work on concrete NumPy arrays (they decide how many samples or pulses there are).
`hertzchain.pulses` measures the pulses these find (cos^6 fits, speeds, restitution).
"""

from __future__ import annotations

import itertools
import math
from typing import NamedTuple

import jax.numpy as jnp
import numpy as np

# ----------------------------------------------------------------------------------------
# One pulse of a simulated trace


def refine_peak(time_s, force_n, index=None):
    """Peak time and force from a parabola through the largest sample and its neighbours.

    **Arguments:**

    - `time_s`: (n,) evenly spaced sample times, s (shared by a batch of traces).
    - `force_n`: (..., n) force samples, N.
    - `index`: the sample to refine around (default: the largest sample; it is kept one
      sample away from either end).

    **Returns:** `(peak_time_s, peak_force_n)`, each of shape (...). Differentiable in the
    force values (the index choice is piecewise constant).
    """
    time_s = jnp.asarray(time_s)
    force_n = jnp.asarray(force_n)
    n = force_n.shape[-1]
    if n < 3:
        raise ValueError(f"refine_peak needs at least 3 samples, got {n}.")
    if time_s.ndim != 1 or time_s.shape[0] != n:
        raise ValueError(
            f"refine_peak: time_s must be one (n,) axis shared by the traces; got {time_s.shape} "
            f"for forces {force_n.shape} (for a batched run pass time_s[0])."
        )
    if index is None:
        index = jnp.argmax(force_n, axis=-1)
    index = jnp.clip(jnp.asarray(index), 1, n - 2)
    take = lambda offset: jnp.take_along_axis(force_n, (index + offset)[..., None], axis=-1)[..., 0]
    left, middle, right = take(-1), take(0), take(1)
    curvature = left - 2.0 * middle + right
    safe = jnp.where(curvature < 0.0, curvature, -1.0)
    offset = jnp.where(curvature < 0.0, 0.5 * (left - right) / safe, 0.0)
    offset = jnp.clip(offset, -1.0, 1.0)
    step = time_s[1] - time_s[0]
    peak_time = time_s[index] + offset * step
    peak_force = middle - 0.25 * (left - right) * offset
    return peak_time, peak_force


def first_peak(time_s, force_n, *, rise_fraction=0.3):
    """The first pulse's peak: the first rise above `rise_fraction` of the trace maximum,
    then the next local maximum, refined by `refine_peak`.

    **Arguments:** `time_s` (n,), s; `force_n` (..., n), N; `rise_fraction` of the maximum.

    **Returns:** `(peak_time_s, peak_force_n)` of shape (...).
    """
    force_n = jnp.asarray(force_n)
    return refine_peak(time_s, force_n, first_peak_index(force_n, rise_fraction))


def first_peak_index(force_n, rise_fraction=0.3):
    """Sample index (...) of `first_peak`: the first sample not below its successor from the
    first rise above `rise_fraction` of the trace maximum on (the last sample if none).

    Works under `jit` and `vmap` and never raises: an index of 0 or n - 1 (a sample without
    a neighbour on one side) says that no interior peak was found. `force_n` (..., n), N."""
    n = force_n.shape[-1]
    top = jnp.max(force_n, axis=-1, keepdims=True)
    start = jnp.argmax(force_n >= rise_fraction * top, axis=-1)
    samples = jnp.arange(n - 1)
    falling = (force_n[..., :-1] >= force_n[..., 1:]) & (samples >= start[..., None])
    return jnp.where(jnp.any(falling, axis=-1), jnp.argmax(falling, axis=-1), n - 1)


def first_run(values, fraction):
    """Sample indices `(start, end, peak)` of the first run of samples above `fraction` of a
    trace's maximum: its first sample, one past its last, and its largest; None when the
    maximum is not positive or no sample exceeds the level (`fraction` >= 1).

    NumPy, not differentiable: for choosing samples (a window, the samples a parabola is
    fitted through), not for values that must carry a gradient.
    """
    values = np.asarray(values, dtype=float)
    top = float(np.max(values)) if values.size else 0.0
    if not top > 0:
        return None
    above = values > fraction * top
    start = int(np.argmax(above))
    if not above[start]:
        return None
    below_after = np.nonzero(~above[start:])[0]
    end = start + int(below_after[0]) if below_after.size else len(values)
    return start, end, start + int(np.argmax(values[start:end]))


def measured_first_peak(time_s, values, threshold: float = 0.3, top_fraction: float = 0.8):
    """(time s, force N) of the first pulse's maximum, or None if there is no clear pulse.

    Robust to measurement noise: the first pulse is the first run of samples above
    `threshold` times the channel's maximum; its peak is the vertex of a least-squares
    parabola through the contiguous samples around the run's largest one that stay above
    `top_fraction` of it (tens of samples for a pulse resolved as the fit needs, so
    the noise averages out; a cos^6 top is symmetric, so the vertex time is unbiased).

    Deliberately not `first_peak`: that one stops at the first sample not below its
    successor and fits a parabola through three samples, exact on simulated traces but
    stopped by any noise wiggle on a measured leading edge. The run is `first_run`'s.
    """
    time_s = np.asarray(time_s, dtype=float)
    values = np.asarray(values, dtype=float)
    run = first_run(values, threshold)
    if run is None:
        return None
    i = run[2]
    level = top_fraction * values[i]
    left, right = i, i
    while left > 0 and values[left - 1] >= level:
        left -= 1
    while right + 1 < len(values) and values[right + 1] >= level:
        right += 1
    if right - left < 2:
        return float(time_s[i]), float(values[i])
    t = time_s[left:right + 1] - time_s[i]
    a, b, c = np.polyfit(t, values[left:right + 1], 2)
    if a >= 0:
        return float(time_s[i]), float(values[i])
    vertex = float(np.clip(-b / (2 * a), t[0], t[-1]))
    return float(time_s[i] + vertex), float(c + vertex * (b + a * vertex))


# ----------------------------------------------------------------------------------------
# Several pulses in one trace


class Pulse(NamedTuple):
    """One pulse of a trace: `label` (see `find_pulses`), sample range `start`..`stop`
    (inclusive; the boundaries with neighbouring pulses are the minima between them),
    `peak_index`, parabolic `peak_time_s` and `peak_force_n`, and `window_s` (the time span
    to pass to `fit_cos6`)."""

    label: str
    start: int
    stop: int
    peak_index: int
    peak_time_s: float
    peak_force_n: float
    window_s: tuple[float, float]


def estimate_noise_std_n(force_n) -> float:
    """Noise standard deviation of a trace from its second differences, N.

    White noise of variance $\\sigma^2$ gives second differences of variance $6\\sigma^2$;
    the median absolute deviation makes the estimate robust to the samples where a finely
    sampled smooth pulse curves (they must be a minority of the trace). 0 for a trace of
    fewer than 3 samples. Works in any unit (the result is in the trace's).
    """
    diff = np.diff(np.asarray(force_n, dtype=float), n=2)
    if diff.size == 0:
        return 0.0
    mad = np.median(np.abs(diff - np.median(diff)))
    return float(1.4826 * mad / math.sqrt(6.0))


def find_pulses(time_s, force_n, *, channel="contact", min_fraction=0.05, noise_std_n=None):
    """Find the pulses of one trace and label them in time order.

    A pulse is a local maximum whose height and prominence exceed the larger of
    `min_fraction` times the trace maximum and 5 times the noise (`noise_std_n`, estimated
    from the trace when not given), and which is separated from its neighbours by a dip of
    at least that level (maxima made by noise on top of one pulse are merged). Labels: for a
    `"wall"` channel `wall`, then `wall_secondary_1`, ...; for a contact or sensor channel
    `incident`, `reflected`, then `secondary_1`, ... (after a wall the first pulse is the
    incident wave, the second the reflected primary and the rest secondary waves or tails).

    **Returns:** a list of `Pulse`.
    """
    from scipy.signal import find_peaks

    time = np.asarray(time_s, dtype=float)
    force = np.asarray(force_n, dtype=float)
    noise = estimate_noise_std_n(force) if noise_std_n is None else float(noise_std_n)
    level = max(min_fraction * float(np.max(force)), 5.0 * noise)
    if not np.max(force) > level:
        return []
    peaks, _ = find_peaks(force, height=level, prominence=level)
    if len(peaks) == 0:
        return []
    peaks = _merge_shallow(force, list(peaks), level)
    bounds = [int(np.argmax(force[: peaks[0]] >= level)) if peaks[0] > 0 else 0]
    for a, b in itertools.pairwise(peaks):
        bounds.append(int(a + np.argmin(force[a : b + 1])))
    after = force[peaks[-1] :] < level
    bounds.append(int(peaks[-1] + np.argmax(after)) if np.any(after) else len(force) - 1)
    names = ("wall",) if channel == "wall" else ("incident", "reflected")
    prefix = "wall_secondary" if channel == "wall" else "secondary"
    pulses = []
    for i, peak in enumerate(peaks):
        label = names[i] if i < len(names) else f"{prefix}_{i - len(names) + 1}"
        start, stop = bounds[i], bounds[i + 1]
        t, f = refine_peak(time, force, int(peak))
        pulses.append(
            Pulse(
                label,
                start,
                stop,
                int(peak),
                float(t),
                float(f),
                (float(time[start]), float(time[stop])),
            )
        )
    return pulses


def _merge_shallow(force, peaks, level):
    """Merge neighbouring maxima not separated by a dip of at least `level` below the lower
    of the two (noise on top of one pulse), keeping the higher one."""
    merged = True
    while merged and len(peaks) > 1:
        merged = False
        for i in range(len(peaks) - 1):
            a, b = peaks[i], peaks[i + 1]
            dip = float(np.min(force[a : b + 1]))
            if min(force[a], force[b]) - dip < level:
                peaks.pop(i + 1 if force[a] >= force[b] else i)
                merged = True
                break
    return np.asarray(peaks, dtype=int)


# ----------------------------------------------------------------------------------------
# Resonances of a frequency response

# A local maximum of a frequency response counts as a resonance when it stands out of its
# surroundings by this fraction of the curve's maximum (`frequency_response_peaks`).
RESONANCE_PROMINENCE = 0.05


def frequency_response_peaks(frequencies_hz, response, count: int, *,
                             prominence_fraction: float = RESONANCE_PROMINENCE) -> np.ndarray:
    """The frequencies (Hz, ascending) of the `count` most prominent local maxima of a
    frequency response `response` (F,) sampled at `frequencies_hz` (F,) (any positive
    quantity: a lock-in's RMS velocity, m/s), among those whose prominence is at least
    `prominence_fraction` of the curve's maximum.

    **Raises:** `ValueError` when fewer than `count` such peaks exist, naming how many."""
    from scipy.signal import find_peaks

    response = np.asarray(response, dtype=float)
    peaks, props = find_peaks(response, prominence=prominence_fraction * response.max())
    if peaks.size < count:
        raise ValueError(f"the frequency response shows {peaks.size} resonance peaks standing out by "
                         f"{100 * prominence_fraction:g} % of its maximum; {count} were expected (one per mode).")
    best = peaks[np.argsort(props["prominences"])[-count:]]
    return np.sort(np.asarray(frequencies_hz, dtype=float)[best])
