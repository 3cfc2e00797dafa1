"""Conditioning of recorded channels: from a scope's volts to forces on the model's clock.

Each step is a small pure function on numpy arrays, so that an importer (see
`hertzchain.io.importer`) can apply them in order and record what each one did:

1. `regular_time_grid`: times as written by a scope carry a few significant digits; a grid
   that is uniform to within `TIME_ROUNDING` of a sample interval is replaced by the exact
   uniform grid of the same first sample and interval (the trace format needs an even grid).
2. `crossing_time_s`: the time a trigger channel first crosses a level (linear
   interpolation between the two samples around it), to set time zero at an impact
   recorded on a channel of its own; `impact_time_s` checks a time zero afterwards: the
   impact time that the pulse's arrivals at two or more positions imply.
3. `clipped_mask`: samples at the digitiser's range limit (within half a quantisation step,
   or one part in 10^9 of the range when the step is unknown).
4. `quantisation_step`: the converter's step, estimated from the values themselves when the
   file does not state it (8-bit data sit on a lattice of at most 256 levels).
5. `baseline`: offset and noise from the pre-trigger segment: the mean (not the median:
   quantised values dithered by noise average to the true level, their median sits on a
   code), and the noise. Without a known step, the noise is the standard deviation about
   the mean. With one, the analogue noise sigma_a is the maximum-likelihood width of a
   normal distribution seen through the converter's bins (each sample a count in the bin
   of its code: interval-censored data), which holds from sigma_a below a step, where the
   spread of a resting record says little, to many steps (on one or two codes the width
   is not identifiable: the posterior mean of its square, see `binned_noise_std`);
   the channel's noise is then sigma^2 = sigma_a^2 + step^2/12, the error of a moving
   signal through a uniform converter. (The resting parts of a record have their own
   error, between 0 and step/2 depending on where the level sits between two codes; over
   channels with independent offsets it averages to the same sigma^2.)
"""

from __future__ import annotations

import dataclasses
import math
import warnings

import numpy as np

# A scope's time column is taken as uniform when every time lies within this fraction of a
# sample interval of the uniform grid (Tektronix CSV prints about 4-6 significant digits).
TIME_ROUNDING = 0.05
# Fewest pre-trigger samples from which an offset and a noise level are estimated.
MIN_BASELINE_SAMPLES = 20
# Values on fewer distinct levels than this share of the samples are taken as quantised.
_QUANTISED_SHARE = 0.25


class ConditioningError(ValueError):
    """A record that cannot be conditioned; the message says where and what to do."""


def regular_time_grid(time_s, where: str) -> tuple[np.ndarray, float]:
    """The uniform grid closest to `time_s` (s) and the largest deviation from it, in intervals.

    **Raises:** `ConditioningError` when the times are not increasing or not uniform to
    within `TIME_ROUNDING` of an interval (the message gives the row and the steps).
    """
    time = np.asarray(time_s, dtype=float)
    if time.ndim != 1 or time.size < 3:
        raise ConditioningError(f"{where}: need at least 3 samples, got {time.size}.")
    step = np.diff(time)
    if np.any(step <= 0):
        row = int(np.argmax(step <= 0)) + 1
        raise ConditioningError(
            f"{where}: time does not increase at sample {row + 1} ({time[row - 1]:.9g} s then "
            f"{time[row]:.9g} s); the record must be in time order."
        )
    index = np.arange(time.size, dtype=float)
    slope, intercept = np.polyfit(index, time, 1)
    grid = intercept + slope * index
    deviation = float(np.max(np.abs(time - grid)) / slope)
    if deviation > TIME_ROUNDING:
        raise ConditioningError(
            f"{where}: samples are not evenly spaced (steps from {step.min():.6g} to "
            f"{step.max():.6g} s, up to {deviation:.3g} intervals off a uniform grid); "
            "resample the record to a uniform grid first."
        )
    return grid, deviation


def crossing_time_s(time_s, values, level: float, rising: bool, where: str) -> float:
    """First time (s) at which `values` cross `level` upwards (`rising`) or downwards.

    **Raises:** `ConditioningError` when they never do (the message gives their range).
    """
    time = np.asarray(time_s, dtype=float)
    v = np.asarray(values, dtype=float) - level
    beyond = v > 0 if rising else v < 0
    if beyond[0]:
        raise ConditioningError(
            f"{where}: the trigger channel is already {'above' if rising else 'below'} {level:g} V "
            "at the first sample; set the level between its resting and its triggered value."
        )
    if not beyond.any():
        raise ConditioningError(
            f"{where}: the trigger channel never goes {'above' if rising else 'below'} {level:g} V "
            f"(its values run from {np.min(values):.4g} to {np.max(values):.4g} V)."
        )
    k = int(np.argmax(beyond))
    fraction = v[k - 1] / (v[k - 1] - v[k])
    return float(time[k - 1] + fraction * (time[k] - time[k - 1]))


# Where the arrivals put the impact, in transit times of one bead (see `impact_time_s`): on
# simulations of three chains (brass R = 5 mm and 10 mm, 12-16 beads; R = 13 mm, 21
# beads; striker 0.03-0.5 m/s) the half-rise times extrapolate to 0 ... +0.5 transit (the
# wave forms over the first beads); a time zero is called off beyond this band.
IMPACT_BAND_TRANSITS = (-0.5, 1.0)
# The same when the wall's channel is one of only two positions: a wall softer than the
# beads loads more slowly and its half-rise comes later, which moves the extrapolated impact
# earlier (16 brass beads of 4 mm, contact 8 and a 20 GPa wall: -0.53 ... -0.82 transits at
# the true time zero); the band's lower side is widened for it.
IMPACT_BAND_WITH_WALL_TRANSITS = (-2.0, 1.0)


def half_rise_time_s(time_s, force_n) -> float | None:
    """Time (s) at which the first pulse (the first run above 30 % of the trace maximum)
    rises through half its peak, interpolated between samples; None without a pulse."""
    from .peaks import first_run

    force = np.asarray(force_n, dtype=float)
    run = first_run(force, 0.3)
    if run is None:
        return None
    start, _, peak = run
    level = 0.5 * force[peak]
    k = start + int(np.argmax(force[start:peak + 1] >= level))
    if k == 0:
        return None
    fraction = (level - force[k - 1]) / (force[k] - force[k - 1])
    return float(time_s[k - 1] + fraction * (time_s[k] - time_s[k - 1]))


def impact_time_s(time_s, forces_by_position: dict) -> tuple[float, float] | None:
    """The impact time that the pulse's arrivals imply, and the transit time of one bead.

    `forces_by_position`: position along the chain in bead diameters from the striker
    contact (contact_K and sensor_K at K, the wall at N) -> (n,) force, N. The half-rise
    times of the first pulse are fitted by a line in position (least squares); its value
    at position 0 is the impact time (s), its slope the transit time of one bead (s).
    None with fewer than two distinct positions that show a pulse, or a slope that is not
    positive (no travelling pulse)."""
    points = [(p, half_rise_time_s(time_s, f)) for p, f in forces_by_position.items()]
    points = [(p, t) for p, t in points if t is not None]
    if len({p for p, _ in points}) < 2:
        return None
    positions, times = np.array(points, dtype=float).T
    slope, intercept = np.polyfit(positions, times, 1)
    if not slope > 0:
        return None
    return float(intercept), float(slope)


def quantisation_step(values, stated: float | None = None) -> float | None:
    """The converter's step (same unit as `values`): `stated` if given, else the smallest
    gap between the distinct values when they are few (quantised data), else None."""
    if stated is not None:
        return float(stated)
    levels = np.unique(np.asarray(values, dtype=float))
    if levels.size < 2 or levels.size > _QUANTISED_SHARE * np.size(values):
        return None
    gaps = np.diff(levels)
    return float(np.min(gaps[gaps > 1e-12 * np.max(np.abs(levels))]))


def clipped_mask(values, range_v: tuple[float, float] | None, step: float | None) -> np.ndarray:
    """(n,) bool: samples at or beyond the range limits `range_v` (V), within half a step."""
    values = np.asarray(values, dtype=float)
    if range_v is None:
        return np.zeros(values.shape, dtype=bool)
    low, high = float(range_v[0]), float(range_v[1])
    tolerance = 0.5 * step if step else 1e-9 * (high - low)
    return (values >= high - tolerance) | (values <= low + tolerance)


@dataclasses.dataclass(frozen=True)
class Baseline:
    """What the pre-trigger segment says of a channel: `offset` (its mean), `noise_std` (the
    noise of the channel, quantisation error included, see the module docstring),
    `n_samples` used, and `quantisation_floor` (step/sqrt(12), 0 if unknown); same unit as
    the values."""

    offset: float
    noise_std: float
    n_samples: int
    quantisation_floor: float


def baseline(values, before: np.ndarray, step: float | None, where: str) -> Baseline:
    """Offset and noise of a channel from its samples where `before` is True.

    **Raises:** `ConditioningError` when fewer than `MIN_BASELINE_SAMPLES` samples lie
    there (the message names the channel and how to give the values instead).
    """
    segment = np.asarray(values, dtype=float)[np.asarray(before, dtype=bool)]
    if segment.size < MIN_BASELINE_SAMPLES:
        raise ConditioningError(
            f"{where}: only {segment.size} samples before the impact, and the offset or the noise "
            f"must come from them (at least {MIN_BASELINE_SAMPLES}); record a pre-trigger segment, "
            "or give the channel's offset_v and noise_std_n in the experiment file."
        )
    offset = float(np.mean(segment))
    if not step:
        return Baseline(offset, float(np.std(segment, ddof=1)), int(segment.size), 0.0)
    floor = step / math.sqrt(12.0)
    return Baseline(offset, math.hypot(binned_noise_std(segment, step), floor), int(segment.size), floor)


class NoiseEstimateWarning(UserWarning):
    """The maximum-likelihood noise fit did not converge; a moment estimate was used."""


def binned_noise_std(values, step: float) -> float:
    """Standard deviation of normal noise about a constant level, from samples quantised to
    multiples of `step` (same unit).

    Each sample counts in the bin [k - 1/2, k + 1/2) step of its code k, so the level and the
    width have the likelihood sum_k n_k log(Phi(b_k) - Phi(a_k)) (interval-censored data).

    - Three or more codes: the maximum-likelihood width (scipy's Nelder-Mead on the level
      and the log width). If it does not converge, a `NoiseEstimateWarning` says so and
      the codes' variance less step^2/12 (Sheppard's correction) is used.
    - One or two codes: the width is not identifiable (two bins fix only (boundary -
      level)/width, and the likelihood grows as the width shrinks to 0); what the record
      says is that no third code appeared. The estimate is the posterior mean of the
      width's square under flat priors on the level and the width (`_few_codes_width_sq`).
      On simulated 200-sample records it lies within 0.83-1.17 of the truth in
      sqrt(width^2 + step^2/12) for noise of 0.05-0.35 steps, where the codes' spread,
      taken before, was 1.2-1.8 times too large (it holds the quantisation error that the
      step^2/12 term adds again).
    """
    from scipy import optimize, special

    values = np.asarray(values, dtype=float)
    codes = np.round((values - np.median(values)) / step)
    levels, counts = np.unique(codes, return_counts=True)
    if levels.size <= 2:
        return step * math.sqrt(_few_codes_width_sq(levels, counts))

    def negative_log_likelihood(theta):
        level, width = theta[0], math.exp(theta[1])
        upper = special.ndtr((levels + 0.5 - level) / width)
        lower = special.ndtr((levels - 0.5 - level) / width)
        return -float(np.sum(counts * np.log(np.maximum(upper - lower, 1e-300))))

    spread = max(float(np.std(codes)), 0.1)
    best = optimize.minimize(negative_log_likelihood, [float(np.mean(codes)), math.log(spread)],
                             method="Nelder-Mead", options={"xatol": 1e-6, "fatol": 1e-9})
    if not best.success:
        sheppard = max(float(np.var(codes, ddof=1)) - 1.0 / 12.0, 0.0)
        warnings.warn(f"the noise fit on {codes.size} quantised samples did not converge ({best.message}); "
                      f"using the codes' variance less step^2/12: {step * math.sqrt(sheppard):.4g}.",
                      NoiseEstimateWarning, stacklevel=2)
        return step * math.sqrt(sheppard)
    return step * math.exp(float(best.x[1]))


def _few_codes_width_sq(levels, counts, grid: int = 400) -> float:
    """Posterior mean of the noise width squared (in steps^2) from the counts of one or two
    adjacent codes: flat priors on the level (within half a step of the codes seen) and on
    the width (0 to 1 step; wider noise would have shown a third code), on a grid."""
    from scipy import special

    level = np.linspace(levels[0] - 0.5, levels[-1] + 0.5, grid)[:, None]
    width = np.linspace(1.0 / grid, 1.0, grid)[None, :]
    log_likelihood = np.zeros((grid, grid))
    for code, count in zip(levels, counts):
        mass = special.ndtr((code + 0.5 - level) / width) - special.ndtr((code - 0.5 - level) / width)
        log_likelihood += count * np.log(np.maximum(mass, 1e-300))
    weight = np.exp(log_likelihood - log_likelihood.max())
    return float(np.sum(weight * width**2) / np.sum(weight))
