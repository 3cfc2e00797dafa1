"""The data model of a fit: experiments (trace files) and the checks they must pass.

An `Experiment` is one trace file (`hertzchain.tracefile.TraceFile`) plus the choice of
channels to fit and the noise level of each channel. The noise standard deviation whitens
the residuals. It comes from the file's `noise_std_n_<channel>` or `noise_std_n` header
when there is one; otherwise
it is estimated from the channel itself with a robust high-pass estimate: the median
absolute second difference, $\\sigma \\approx 1.4826\\,\\mathrm{MAD}(\\Delta^2 y)/\\sqrt{6}$
(white noise of variance $\\sigma^2$ gives second differences of variance $6\\sigma^2$; a
pulse sampled finely enough adds almost nothing to them).

Samples the file marks as clipped (`clipped_<channel>`: the digitiser was at its range
limit) stay in the record but are left out of the fit, with a `DataWarning` naming the
file, the channel and the count. Channels listed in `ac_channels` are compared with the
model's change of force since before the impact (`fitting.model`).
"""

from __future__ import annotations

import dataclasses
import hashlib
import warnings
from pathlib import Path

import numpy as np

from hertzchain.pulses import estimate_noise_std_n
from hertzchain.theory import discrete_fwhm_s
from hertzchain.tracefile import TraceFile, read_trace

from .parameters import bare_speed_constant

# The fit needs at least this many samples across the half-maximum width of the pulse.
MIN_SAMPLES_PER_PULSE = 6
MIN_SAMPLES = 20
# A channel must show a pulse above this many noise standard deviations.
MIN_PEAK_SNR = 5.0


class FitInputError(ValueError):
    """Data that cannot be fitted; the message names the file, the channel and the fix."""


class DataWarning(UserWarning):
    """Data the fit uses only in part (clipped samples); the message says which and why."""


# Robust estimate of white-noise standard deviation from second differences, same units.
estimate_noise_std = estimate_noise_std_n


@dataclasses.dataclass(frozen=True)
class Experiment:
    """One trace file prepared for fitting.

    **Fields:**

    - `trace`: the `TraceFile`.
    - `label`: short name used in reports (the file name without suffix by default).
    - `channels`: names of the channels fitted (default: all of the file's channels).
    - `noise_std_n`: channel -> noise standard deviation, N.
    - `noise_source`: `"header"` (the file's `noise_std_n` keys) or `"estimated"`.
    - `excluded`: channel -> (n_samples,) bool, the samples left out of the fit (clipped).
    """

    trace: TraceFile
    label: str
    channels: tuple[str, ...]
    noise_std_n: dict
    noise_source: str
    excluded: dict = dataclasses.field(default_factory=dict)

    @property
    def time_s(self) -> np.ndarray:
        return np.asarray(self.trace.time_s, dtype=float)

    def data(self, channel: str) -> np.ndarray:
        return np.asarray(self.trace.channels[channel], dtype=float)

    @property
    def n_residuals(self) -> int:
        return len(self.channels) * len(self.time_s)

    @property
    def n_fitted(self) -> int:
        """Samples that enter the fit (every channel's, clipped samples left out)."""
        return self.n_residuals - sum(int(np.sum(self.excluded.get(c, False))) for c in self.channels)

    def used(self, channel: str) -> np.ndarray:
        """(n_samples,) bool: the channel's samples that enter the fit."""
        return ~np.asarray(self.excluded.get(channel, np.zeros(len(self.time_s), bool)))

    def analogue_noise_steps(self, channel: str) -> float | None:
        """The channel's analogue noise in converter steps, as the importer measured it on the
        pre-trigger segment (`x_import_<channel>_analogue_noise_steps`), or None (unquantised,
        or noise stated in the file)."""
        value = self.trace.header.get(f"x_import_{channel}_analogue_noise_steps")
        return None if value is None else float(value)

    @property
    def ac_channels(self) -> tuple[str, ...]:
        """Fitted channels that read changes of force only (see `TraceFile.ac_channels`)."""
        return tuple(c for c in self.channels if c in self.trace.ac_channels)


def make_experiment(trace: TraceFile, *, label: str | None = None, channels=None,
                    noise_std_n: float | None = None, striker_velocity_m_s: float | None = None
                    ) -> Experiment:
    """Check a trace for fitting and wrap it as an `Experiment`.

    **Arguments:**

    - `trace`: a `TraceFile` (e.g. from `hertzchain.tracefile.read_trace`).
    - `label`: name in reports (default: the file stem, or `trace<k>`).
    - `channels`: channels to fit (default all).
    - `noise_std_n`: noise standard deviation, N (default: the header's, else estimated).
    - `striker_velocity_m_s`: used only for the sampling check when the header has none.

    **Raises:** `FitInputError` for NaN samples, unknown channels, records that are too
    short or show no pulse above the noise, and sampling too coarse for the pulse.
    """
    where = trace.path or label or "<trace>"
    if label is None:
        label = trace.header.get("x_shot") or (Path(trace.path).stem if trace.path else "trace")
    time = np.asarray(trace.time_s, dtype=float)
    if time.size < MIN_SAMPLES:
        raise FitInputError(
            f"{where}: only {time.size} samples; a fit needs at least {MIN_SAMPLES} covering the pulse."
        )
    if channels is None:
        channels = trace.channel_names
    channels = tuple(channels)
    for name in channels:
        if name not in trace.channels:
            raise FitInputError(
                f"{where}: no channel {name!r}; the file has {', '.join(trace.channel_names)}."
            )
        values = np.asarray(trace.channels[name], dtype=float)
        if not np.all(np.isfinite(values)):
            bad = int(np.argmin(np.isfinite(values)))
            raise FitInputError(
                f"{where}: channel {name} has NaN or inf at sample {bad + 1} (t = {time[bad]:.6g} s); "
                "remove or interpolate the bad samples first."
            )
    excluded = {name: trace.clipped(name) for name in channels}
    for name in channels:
        count = int(np.sum(excluded[name]))
        if count:
            warnings.warn(
                f"{where}: channel {name} has {count} samples at the digitiser's range limit "
                "(clipped); they are left out of the fit. A larger vertical range avoids this.",
                DataWarning, stacklevel=3,
            )
    if noise_std_n is not None:
        if not (np.isfinite(noise_std_n) and noise_std_n > 0):
            raise FitInputError(f"noise_std_n = {noise_std_n!r}: the noise sigma must be positive and finite (N), "
                                "e.g. --noise-std 0.02N; leave it out to use the file's or an estimate.")
        noise = {name: float(noise_std_n) for name in channels}
        source = "header"
    elif all(trace.channel_noise_std_n(name) is not None for name in channels):
        noise = {name: float(trace.channel_noise_std_n(name)) for name in channels}
        source = "header"
        for name, sigma in noise.items():
            if not (np.isfinite(sigma) and sigma > 0):
                key = f"noise_std_n_{name}" if f"noise_std_n_{name}" in trace.header else "noise_std_n"
                raise FitInputError(
                    f"{where}: header {key} = {sigma!r}: a noise sigma must be positive (N); give the recorded "
                    "noise, remove the key (the noise is then estimated from the record) or give --noise-std."
                )
    else:
        noise = {name: estimate_noise_std(trace.channels[name]) for name in channels}
        source = "estimated"
    for name in channels:
        values = np.asarray(trace.channels[name], dtype=float)[~excluded[name]]
        if values.size < MIN_SAMPLES:
            raise FitInputError(
                f"{where}: channel {name} keeps only {values.size} samples that are not clipped; "
                "record it again with a larger vertical range."
            )
        peak = float(np.max(values))
        floor = max(noise[name], 1e-12 * max(abs(peak), 1.0))
        if noise[name] <= 0:
            noise[name] = floor
        if peak < MIN_PEAK_SNR * noise[name]:
            raise FitInputError(
                f"{where}: channel {name} shows no pulse above {MIN_PEAK_SNR:g} x its noise "
                f"({noise[name]:.3g} N) in {time[0]:.6g}..{time[-1]:.6g} s: the record is too "
                "short for the pulse to reach it, or the channel is dead."
            )
    _check_sampling(trace, channels, where, striker_velocity_m_s)
    return Experiment(trace=trace, label=label, channels=channels, noise_std_n=noise,
                      noise_source=source, excluded=excluded)


def _check_sampling(trace: TraceFile, channels, where: str, striker_velocity_m_s) -> None:
    """Refuse a sampling interval too coarse for the narrowest pulse of the record."""
    header = trace.header
    velocity = trace.striker_velocity_m_s or striker_velocity_m_s
    try:
        setup = trace.setup(**({} if trace.striker_velocity_m_s else {"striker_velocity_m_s": velocity or 1.0}))
    except ValueError as error:
        raise FitInputError(f"{where}: {error}") from error
    speed_constant = float(bare_speed_constant(setup))
    peak = max(float(np.max(trace.channels[name])) for name in channels)
    # the incident pulse's amplitude sets its speed; the wall force is up to ~2.3x larger
    incident = peak / (2.3 if channels == ("wall",) else 1.0)
    speed = speed_constant * max(incident, 1e-6) ** (1.0 / 6.0)
    fwhm = discrete_fwhm_s(float(header["bead_radius_m"]), speed)
    interval = trace.sample_interval_s
    if interval * MIN_SAMPLES_PER_PULSE > fwhm:
        raise FitInputError(
            f"{where}: sampled too coarsely for the pulse: interval {interval * 1e6:.3g} us, but a "
            f"pulse of {peak:.3g} N lasts only about {fwhm * 1e6:.3g} us (half-maximum width); "
            f"the fit needs an interval <= {fwhm / MIN_SAMPLES_PER_PULSE * 1e6:.3g} us."
        )


def as_experiments(sources) -> list[Experiment]:
    """`Experiment`s as given, or loaded from trace files, experiment files (paths) or
    `TraceFile`s (one or a sequence; see `load_experiments`)."""
    if isinstance(sources, (Experiment, TraceFile, str, Path)):
        sources = [sources]
    sources = list(sources)
    if sources and all(isinstance(e, Experiment) for e in sources):
        return sources
    if any(isinstance(e, Experiment) for e in sources):
        raise ValueError("Give either Experiments or trace files/paths, not a mixture.")
    return load_experiments(sources)


def _refuse_repeats(paths) -> None:
    """Refuse a file given twice (by the same or another path, or as a byte-for-byte copy): its
    samples would count twice and every standard error shrink by sqrt(2)."""
    seen = {}
    for path in paths:
        path = Path(path)
        if not path.is_file():
            continue
        key = hashlib.sha256(path.read_bytes()).hexdigest()
        if key in seen:
            same = "the same file" if seen[key].resolve() == path.resolve() else "the same content"
            raise FitInputError(
                f"{path}: {same} as {seen[key]}, given twice; each record counts once (a repeat would "
                "shrink every standard error by sqrt(2)): give it once."
            )
        seen[key] = path


def load_experiments(sources, *, channels=None, noise_std_n=None) -> list[Experiment]:
    """Read trace files (paths) or take `TraceFile`s and check them for fitting.

    An experiment file (`.toml`, see `hertzchain.importer`) stands for its shots, imported
    in memory. Labels are the shot labels or file stems, made unique with a suffix when two
    share one. A file given twice (or a byte-for-byte copy of one) is refused.
    """
    sources = list(sources)
    _refuse_repeats([s for s in sources if isinstance(s, (str, Path))])
    if any(isinstance(s, (str, Path)) and str(s).lower().endswith(".toml") for s in sources):
        # experiment files (`hertzchain.importer.is_experiment_file`): the scope-file readers
        # and their packages load only when one is given
        from hertzchain.importer import expand_sources

        sources = expand_sources(sources)
    experiments, used = [], set()
    for k, source in enumerate(sources):
        trace = source if isinstance(source, TraceFile) else read_trace(source)
        label = trace.header.get("x_shot") or (Path(trace.path).stem if trace.path else f"trace{k}")
        base, n = label, 2
        while label in used:
            label, n = f"{base}_{n}", n + 1
        used.add(label)
        experiments.append(
            make_experiment(trace, label=label, channels=channels, noise_std_n=noise_std_n)
        )
    if not experiments:
        raise FitInputError("No trace files to fit.")
    return experiments
