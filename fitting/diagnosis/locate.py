"""Where model and data disagree: whitened residuals broken down by channel, time window,
amplitude (file) and frequency band.

Every cell reports its number of samples n, $\\chi^2$ (sum of squared whitened residuals),
$\\chi^2/n$ (1 for a model that explains the data to the noise level), and the excess in
noise units, $(\\chi^2 - n)/\\sqrt{2n}$ (about N(0, 1) when the residual is white noise);
where a channel's noise level was estimated from $m$ samples (`noise_estimate_samples`),
its $n$ samples' $\\chi^2$ scale by that estimate's error, of relative variance $2/(m-1)$,
and $2n^2/(m-1)$ joins the variance: $(\\chi^2 - n)/\\sqrt{2n + \\sum 2n^2/(m-1)}$.

Time windows are defined from the model's own prediction of each channel: with $A$ the
main pulse's peak and $w$ its half-maximum width,

- `before`: before the model first reaches 10 % of $A$ (the pulse has not arrived),
- `leading_edge`: from there to $t_{peak} - w/4$,
- `peak`: $|t - t_{peak}| \\le w/4$,
- `trailing_edge`: from $t_{peak} + w/4$ until the model falls below 10 % of $A$,
- `after`: the rest of the record (reflected pulse, secondary waves, tails).

Frequency bands split the residual's periodogram (normalised so that white noise gives
1 in every band) into `FREQUENCY_BANDS_HZ`.
"""

from __future__ import annotations

import math

import numpy as np

from hertzchain.peaks import first_run

WINDOWS = ("before", "leading_edge", "peak", "trailing_edge", "after")
FREQUENCY_BANDS_HZ = ((0.0, 5e3), (5e3, 20e3), (20e3, 60e3), (60e3, 200e3), (200e3, math.inf))


def noise_estimate_samples(experiment, channel: str) -> int:
    """The number of samples a channel's noise level was estimated from (the importer's
    pre-trigger segment, `x_import_<channel>_noise_samples`); 0 where the file states it."""
    return int(experiment.trace.header.get(f"x_import_{channel}_noise_samples", 0) or 0)


def estimate_variance(n: int, samples: int) -> float:
    """The variance a noise level estimated from `samples` samples adds to the chi^2 of `n`
    residuals it whitens: 2 n^2 / (samples - 1) (0 for a stated noise level)."""
    return 2.0 * n**2 / (samples - 1) if samples > 1 else 0.0


def cell(residuals, noise_estimate_variance: float = 0.0) -> dict:
    """n, chi2, chi2_per_sample and excess_sigma of a set of whitened residuals;
    `noise_estimate_variance`: what the noise levels' estimates add to chi^2's variance."""
    r = np.asarray(residuals, dtype=float)
    n = int(r.size)
    chi2 = float(r @ r)
    return {
        "n": n,
        "chi2": chi2,
        "chi2_per_sample": chi2 / n if n else math.nan,
        "excess_sigma": (chi2 - n) / math.sqrt(2 * n + noise_estimate_variance) if n else 0.0,
    }


def window_masks(model_values) -> dict:
    """Boolean masks of the time windows (see module docstring) for one channel's model."""
    m = np.asarray(model_values, dtype=float)
    n = m.size
    masks = {name: np.zeros(n, bool) for name in WINDOWS}
    if n == 0:
        return masks
    # the first pulse: its maximum before the model drops back to 10 % of the largest
    run = first_run(m, 0.1)
    if run is None:
        masks["after"][:] = True
        return masks
    start, end, first_peak = run
    half = m[first_peak] / 2
    left = first_peak
    while left > 0 and m[left] > half:
        left -= 1
    right = first_peak
    while right < n - 1 and m[right] > half:
        right += 1
    quarter = max(1, (right - left) // 4)
    index = np.arange(n)
    masks["before"] = index < start
    masks["leading_edge"] = (index >= start) & (index < first_peak - quarter)
    masks["peak"] = np.abs(index - first_peak) <= quarter
    masks["trailing_edge"] = (index > first_peak + quarter) & (index < end)
    masks["after"] = index >= end
    return masks


def band_power(residuals, sample_interval_s: float) -> dict:
    """Mean periodogram of whitened residuals in each frequency band (white noise: 1)."""
    r = np.asarray(residuals, dtype=float)
    if r.size < 4:
        return {}
    power = np.abs(np.fft.rfft(r)) ** 2 / r.size
    freq = np.fft.rfftfreq(r.size, sample_interval_s)
    out = {}
    for low, high in FREQUENCY_BANDS_HZ:
        sel = (freq >= low) & (freq < high) & (freq > 0)
        if sel.any():
            out[band_label(low, high)] = float(np.mean(power[sel]))
    return out


def band_label(low: float, high: float) -> str:
    def khz(v):
        return f"{v / 1e3:g}"
    return f">{khz(low)} kHz" if not math.isfinite(high) else f"{khz(low)}-{khz(high)} kHz"


def locate(problem, x, residuals, predictions=None) -> dict:
    """The residual breakdown of a fitted `fitting.Problem` at parameter values `x`.

    **Returns** a JSON-ready dict:

    - `total`: the cell of all residuals;
    - `by_channel`: channel name -> cell (all files pooled);
    - `by_channel_window`: channel -> window -> cell (all files pooled);
    - `by_file`: file label -> {`amplitude_n` (largest data value), `cell`, `channels`:
      channel -> cell} (ordered by amplitude);
    - `by_frequency`: channel -> band -> mean normalised power (1 = white noise);
    - `worst`: the five channel/window cells with the largest excess, largest first.
    """
    r = np.asarray(residuals, dtype=float)
    if predictions is None:
        predictions = problem.predictions(np.asarray(x))
    pooled: dict = {}
    pooled_windows: dict = {}
    window_variance: dict = {}  # channel -> window -> what the noise estimates add
    by_file = []
    band_sum: dict = {}
    band_count: dict = {}
    for experiment, slices, predicted in zip(problem.experiments, problem.residual_slices(), predictions):
        channels = {}
        file_parts = []
        amplitude = 0.0
        for name, part in slices.items():
            res = r[part]
            file_parts.append(res)
            channels[name] = cell(res)
            amplitude = max(amplitude, float(np.max(experiment.data(name))))
            pooled.setdefault(name, []).append(res)
            masks = window_masks(predicted[name])
            samples = noise_estimate_samples(experiment, name)
            for window, mask in masks.items():
                pooled_windows.setdefault(name, {}).setdefault(window, []).append(res[mask])
                window_variance.setdefault(name, {}).setdefault(window, 0.0)
                window_variance[name][window] += estimate_variance(int(np.sum(mask)), samples)
            bands = band_power(res, experiment.trace.sample_interval_s)
            for band, value in bands.items():
                band_sum.setdefault(name, {}).setdefault(band, 0.0)
                band_sum[name][band] += value
                band_count.setdefault(name, {}).setdefault(band, 0)
                band_count[name][band] += 1
        by_file.append({"file": experiment.label, "amplitude_n": amplitude,
                        "cell": cell(np.concatenate(file_parts)), "channels": channels})
    by_file.sort(key=lambda item: item["amplitude_n"])
    by_channel = {name: cell(np.concatenate(parts)) for name, parts in pooled.items()}
    by_window = {
        name: {w: cell(np.concatenate(parts), window_variance[name][w]) for w, parts in windows.items()}
        for name, windows in pooled_windows.items()
    }
    by_frequency = {
        name: {band: band_sum[name][band] / band_count[name][band] for band in bands}
        for name, bands in band_sum.items()
    }
    cells = [(name, w, c) for name, windows in by_window.items() for w, c in windows.items() if c["n"]]
    cells.sort(key=lambda item: -item[2]["excess_sigma"])
    worst = [{"channel": n, "window": w, **c} for n, w, c in cells[:5]]
    return {
        "total": cell(r),
        "by_channel": by_channel,
        "by_channel_window": by_window,
        "by_file": by_file,
        "by_frequency": by_frequency,
        "worst": worst,
    }


def describe(location: dict, *, limit_sigma: float = 3.0) -> list[str]:
    """Sentences saying where the gap is (cells above `limit_sigma` noise units of excess)."""
    lines = []
    for item in location["worst"]:
        if item["excess_sigma"] <= limit_sigma:
            break
        lines.append(
            f"{item['channel']} / {item['window']}: chi^2/n = {item['chi2_per_sample']:.3g} over "
            f"{item['n']} samples ({item['excess_sigma']:.1f} sigma of excess)"
        )
    for name, bands in location["by_frequency"].items():
        if not bands:
            continue
        band, value = max(bands.items(), key=lambda kv: kv[1])
        if value > 2.0:
            lines.append(f"{name}: residual power concentrated at {band} ({value:.3g} x white noise)")
    if not lines:
        lines.append("no cell shows an excess above the noise level")
    return lines
