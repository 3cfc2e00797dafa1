"""What an oscilloscope records of a simulated experiment: synthetic data that look measured.

The chain of the paper's acquisition (force sensor -> conditioner -> oscilloscope) is
modelled in this order, on a simulation sampled much finer than the recording:

1. **Bandwidth limit** of the sensor and amplifier: a causal low-pass (`"bessel"`, 4th
   order, nearly constant group delay $\\approx$ 0.33/f_c, as in analogue front ends, or
   `"first_order"`, an RC with time constant $1/(2\\pi f_c)$), applied on the fine grid.
2. **Coupling**: a `"dc"` channel reads the force itself; an `"ac"` channel (a piezo
   sensor behind an AC-coupled conditioner, as the paper's PCB sensors) reads its change
   since long before the impact, so the static force before the impact (`static_n`, a
   preload) is not in it.
3. **Trigger**: time 0 of the record is the trigger. The paper triggers on the impact
   itself (a contact circuit, 1 us RC), so by default the trigger is the impact; a
   `trigger_delay_s` and a random `trigger_jitter_s` (standard deviation, seeded) shift it.
   A sample at record time $t$ holds the signal at $t$ + delay + jitter after the impact.
4. **Sampling** every `sample_interval_s`, `record_length` samples by linear
   interpolation of the fine signal: the first at one interval after the trigger, or, with
   `pre_trigger_samples`, that many before it (negative record times, the chain at rest)
   and one at the trigger.
5. **Volts**: force times the channel's `sensitivity_v_per_n` (paper: 11.24 mV/N for the
   embedded PCB 200B02, 112.40 mV/N for the wall PCB 208A11), plus the channel's
   `dc_offset_v` (the conditioner's and scope's zero error).
6. **Noise**: additive white Gaussian noise (seeded), given in newtons per channel.
7. **Quantisation**: `bits` over the range $\\pm$`full_scale_v` about 0 V (default: the
   smallest 1-2-5 value of volts that holds the signal; a signal beyond it is clipped and
   reported).

`Record.volts` holds what the scope stores (for writing scope files). A trace file is
written in newtons: the recorded volts less the offset, divided by the sensitivity (a
quantisation step is `2 * full_scale_v / 2**bits / sensitivity` newtons). Its header
`noise_std_n` is the total noise of the worst channel, additive and quantisation
($\\Delta^2/12$, the uniform-error model, valid when the noise is at least half a
step and dithers the converter) combined; each channel's own value and every
acquisition setting are kept as `x_acq_*` keys.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from .io.tracefile import TraceFile, format_rows, setup_header

# Sensitivities of the paper's sensors, V/N.
EMBEDDED_SENSITIVITY_V_PER_N = 11.24e-3
WALL_SENSITIVITY_V_PER_N = 112.40e-3
FILTERS = ("bessel", "first_order")
COUPLINGS = ("dc", "ac")


def paper_sensitivity_v_per_n(channel: str) -> float:
    """The paper's sensitivity for a channel: the wall sensor's for `wall`, the embedded
    sensor's for every other channel, V/N."""
    return WALL_SENSITIVITY_V_PER_N if channel == "wall" else EMBEDDED_SENSITIVITY_V_PER_N


def _per_channel(value, channel, name):
    if isinstance(value, dict):
        if channel not in value:
            raise ValueError(
                f"{name} has no value for channel {channel!r} (given for {sorted(value)})."
            )
        return value[channel]
    return value


@dataclasses.dataclass(frozen=True)
class Acquisition:
    """Settings of the recording (see the module docstring for the order of the steps).

    **Fields:**

    - `sample_interval_s`: interval between recorded samples, s (1 us: 1 MS/s).
    - `record_length`: number of samples (default: as many as the simulation covers).
    - `trigger_delay_s`: trigger time after the impact, s (negative: before it).
    - `trigger_jitter_s`: standard deviation of a random trigger offset, s.
    - `bandwidth_hz`: low-pass cut-off, Hz (None: no limit); `bandwidth_filter`: `"bessel"`
      or `"first_order"`.
    - `noise_std_n`: additive noise, N: a number for every channel or a dict per channel.
    - `bits`: resolution of the converter (None: no quantisation; the TDS340 has 8).
    - `full_scale_v`: the range is +-full_scale_v, V (number or dict; None: automatic).
    - `sensitivity_v_per_n`: V/N, number or dict (None: the paper's sensors).
    - `pre_trigger_samples`: samples recorded before the trigger (negative times).
    - `dc_offset_v`: a constant added to the volts, V (number or dict).
    - `coupling`: `"dc"` or `"ac"` (number or dict per channel; see the module docstring).
    """

    sample_interval_s: float = 1e-6
    record_length: int | None = None
    trigger_delay_s: float = 0.0
    trigger_jitter_s: float = 0.0
    bandwidth_hz: float | None = None
    bandwidth_filter: str = "bessel"
    noise_std_n: float | dict = 0.0
    bits: int | None = None
    full_scale_v: float | dict | None = None
    sensitivity_v_per_n: float | dict | None = None
    pre_trigger_samples: int = 0
    dc_offset_v: float | dict = 0.0
    coupling: str | dict = "dc"

    def __post_init__(self):
        if not (math.isfinite(self.sample_interval_s) and self.sample_interval_s > 0):
            raise ValueError(
                f"sample_interval_s must be a positive time (s), got {self.sample_interval_s!r}."
            )
        if self.record_length is not None and self.record_length < 3:
            raise ValueError(
                f"record_length must be at least 3 samples, got {self.record_length!r}."
            )
        if not math.isfinite(self.trigger_delay_s):
            raise ValueError("trigger_delay_s must be finite (s).")
        if not self.trigger_jitter_s >= 0:
            raise ValueError(f"trigger_jitter_s must be >= 0 (s), got {self.trigger_jitter_s!r}.")
        if self.bandwidth_hz is not None and not self.bandwidth_hz > 0:
            raise ValueError(
                f"bandwidth_hz must be positive (Hz) or None, got {self.bandwidth_hz!r}."
            )
        if self.bandwidth_filter not in FILTERS:
            raise ValueError(
                f"bandwidth_filter must be one of {FILTERS}, got {self.bandwidth_filter!r}."
            )
        noises = (
            self.noise_std_n.values() if isinstance(self.noise_std_n, dict) else [self.noise_std_n]
        )
        if any(not (math.isfinite(n) and n >= 0) for n in noises):
            raise ValueError(f"noise_std_n must be >= 0 (N), got {self.noise_std_n!r}.")
        if self.bits is not None and not (isinstance(self.bits, int) and 2 <= self.bits <= 32):
            raise ValueError(f"bits must be an integer from 2 to 32 or None, got {self.bits!r}.")
        if not (isinstance(self.pre_trigger_samples, int) and self.pre_trigger_samples >= 0):
            raise ValueError(
                f"pre_trigger_samples must be an integer >= 0, got {self.pre_trigger_samples!r}."
            )
        couplings = self.coupling.values() if isinstance(self.coupling, dict) else [self.coupling]
        if any(c not in COUPLINGS for c in couplings):
            raise ValueError(f"coupling must be one of {COUPLINGS} (or a dict of them), got {self.coupling!r}.")

    def sensitivity(self, channel: str) -> float:
        value = self.sensitivity_v_per_n
        value = (
            paper_sensitivity_v_per_n(channel)
            if value is None
            else _per_channel(value, channel, "sensitivity_v_per_n")
        )
        if not value > 0:
            raise ValueError(
                f"sensitivity_v_per_n of {channel} must be positive (V/N), got {value!r}."
            )
        return float(value)


@dataclasses.dataclass(frozen=True)
class Record:
    """A recording: `time_s` (n,) since the trigger, `channels` name -> (n,) forces in N (the
    volts less the offset over the sensitivity), `volts` name -> (n,) what the scope stores, V,
    `noise_std_n` name -> total noise (additive and quantisation), N, `full_scale_v` name ->
    range used, V, `clipped` name -> (n,) bool, the samples beyond the range (stored at its limit), and `trigger_offset_s`, the
    actual trigger time after the impact (delay plus the jitter drawn), s."""

    time_s: np.ndarray
    channels: dict
    volts: dict
    noise_std_n: dict
    full_scale_v: dict
    clipped: dict
    trigger_offset_s: float


def _lowpass(time_s, signal, acquisition: Acquisition):
    if acquisition.bandwidth_hz is None:
        return signal
    from scipy import signal as sp

    step = float(time_s[1] - time_s[0])
    nyquist = 0.5 / step
    if acquisition.bandwidth_hz >= nyquist:
        raise ValueError(
            f"bandwidth_hz = {acquisition.bandwidth_hz:g} Hz is not below the simulation's Nyquist "
            f"frequency {nyquist:g} Hz; simulate with a finer sample_interval_s."
        )
    if acquisition.bandwidth_filter == "first_order":
        decay = math.exp(-2.0 * math.pi * acquisition.bandwidth_hz * step)
        return sp.lfilter([1.0 - decay], [1.0, -decay], signal)
    sos = sp.bessel(
        4, acquisition.bandwidth_hz, btype="low", norm="mag", fs=1.0 / step, output="sos"
    )
    return sp.sosfilt(sos, signal)


def _auto_full_scale_v(peak_v: float) -> float:
    """Smallest value of the 1-2-5 sequence (V) at or above 1.1 times the peak."""
    target = max(1.1 * peak_v, 1e-6)
    decade = 10.0 ** math.floor(math.log10(target))
    for mantissa in (1.0, 2.0, 5.0, 10.0):
        if mantissa * decade >= target * (1 - 1e-12):
            return mantissa * decade
    return 10.0 * decade


def acquire(time_s, forces_n: dict, acquisition: Acquisition = Acquisition(), *, seed=0,
            static_n: float = 0.0) -> Record:
    """Record force traces as an oscilloscope would.

    **Arguments:**

    - `time_s`: (n,) times since the impact of the (finely sampled) forces, s; forces are
      taken as `static_n` before the first sample and at the impact.
    - `forces_n`: channel name -> (n,) force, N.
    - `acquisition`: the settings; `seed`: seed of the noise and jitter (reproducible).
    - `static_n`: the force every channel carries at rest before the impact (the chain's
      static preload), N; an AC-coupled channel does not see it.

    **Returns:** `Record`.
    """
    time = np.asarray(time_s, dtype=float)
    if time.ndim != 1 or len(time) < 3 or np.any(np.diff(time) <= 0):
        raise ValueError("acquire: time_s must be increasing with at least 3 samples.")
    fine_step = float(time[1] - time[0])
    if acquisition.sample_interval_s < fine_step * (1 - 1e-9):
        raise ValueError(
            f"sample_interval_s ({acquisition.sample_interval_s:g} s) is finer than the "
            f"simulation's samples ({fine_step:g} s); simulate with a finer sample_interval_s."
        )
    rng = np.random.default_rng(seed)
    offset = acquisition.trigger_delay_s + acquisition.trigger_jitter_s * float(
        rng.standard_normal()
    )
    if acquisition.record_length is None:
        length = int(
            math.floor((time[-1] - max(offset, 0.0)) / acquisition.sample_interval_s + 1e-9)
        )
        if length < 3:
            raise ValueError(
                "acquire: the simulation is too short for the trigger delay and sampling."
            )
        length += acquisition.pre_trigger_samples + (1 if acquisition.pre_trigger_samples else 0)
    else:
        length = int(acquisition.record_length)
    pre = acquisition.pre_trigger_samples
    first = -pre if pre else 1  # a record with a pre-trigger segment has a sample at the trigger
    record_time = acquisition.sample_interval_s * np.arange(first, first + length)
    physical = record_time + offset
    if physical[-1] > time[-1] * (1 + 1e-12):
        raise ValueError(
            f"acquire: the record reaches {physical[-1]:.6g} s after the impact but the simulation "
            f"ends at {time[-1]:.6g} s; simulate longer or shorten record_length."
        )
    grid = np.concatenate([[0.0], time])
    channels, raw, noise_total, full_scales, clipped = {}, {}, {}, {}, {}
    for name, force in forces_n.items():
        force = np.asarray(force, dtype=float)
        if force.shape != time.shape:
            raise ValueError(
                f"acquire: channel {name} has {force.size} samples for {time.size} times."
            )
        coupling = _per_channel(acquisition.coupling, name, "coupling")
        seen = force - static_n if coupling == "ac" else force
        rest = 0.0 if coupling == "ac" else static_n
        # the low-pass starts from rest: filter the change from the resting force
        filtered = rest + _lowpass(grid, np.concatenate([[0.0], seen - rest]), acquisition)
        sampled = np.interp(physical, grid, filtered, left=rest)
        sensitivity = acquisition.sensitivity(name)
        offset_v = float(_per_channel(acquisition.dc_offset_v, name, "dc_offset_v"))
        noise_n = float(_per_channel(acquisition.noise_std_n, name, "noise_std_n"))
        volts = (sampled + noise_n * rng.standard_normal(length)) * sensitivity + offset_v
        scale = acquisition.full_scale_v
        scale = None if scale is None else _per_channel(scale, name, "full_scale_v")
        if scale is None:
            scale = _auto_full_scale_v(
                float(np.max(np.abs(sampled * sensitivity + offset_v))) + 3 * noise_n * sensitivity
            )
        total = noise_n
        if acquisition.bits is not None:
            lsb = 2.0 * scale / 2**acquisition.bits
            codes = np.round(volts / lsb)
            low, high = -(2 ** (acquisition.bits - 1)), 2 ** (acquisition.bits - 1) - 1
            clipped[name] = (codes < low) | (codes > high)
            volts = np.clip(codes, low, high) * lsb
            total = math.sqrt(noise_n**2 + (lsb / sensitivity) ** 2 / 12.0)
        else:
            clipped[name] = np.abs(volts) > scale
            volts = np.clip(volts, -scale, scale)
        raw[name] = volts
        channels[name] = (volts - offset_v) / sensitivity
        noise_total[name] = total
        full_scales[name] = float(scale)
    return Record(record_time, channels, raw, noise_total, full_scales, clipped, offset)


def acquire_trace(
    setup,
    time_s,
    forces_n: dict,
    acquisition: Acquisition = Acquisition(),
    *,
    seed=0,
    truth: dict | None = None,
) -> TraceFile:
    """Record a simulation of `setup` and return it as a `TraceFile` (forces in N).

    The header describes `setup` (`setup_header`), carries `noise_std_n` (the worst
    channel's total noise), each channel's own `noise_std_n_<channel>`, `ac_channels`, the
    `clipped_<channel>` rows, and the acquisition as `x_acq_*` keys; `truth` adds free-form
    `x_true_<key>` entries (e.g. the parameters a fit should recover).
    """
    record = acquire(time_s, forces_n, acquisition, seed=seed, static_n=float(setup.precompression_n))
    header = setup_header(setup)
    header["noise_std_n"] = max(record.noise_std_n.values())
    ac = [name for name in record.channels if _per_channel(acquisition.coupling, name, "coupling") == "ac"]
    if ac:
        header["ac_channels"] = ",".join(ac)
    for name in record.channels:
        header[f"noise_std_n_{name}"] = record.noise_std_n[name]
        if record.clipped[name].any():
            header[f"clipped_{name}"] = format_rows(record.clipped[name])
    info = {
        "sample_interval_s": acquisition.sample_interval_s,
        "trigger_offset_s": record.trigger_offset_s,
        "trigger_delay_s": acquisition.trigger_delay_s,
        "trigger_jitter_s": acquisition.trigger_jitter_s,
        "bandwidth_hz": acquisition.bandwidth_hz,
        "bandwidth_filter": acquisition.bandwidth_filter if acquisition.bandwidth_hz else None,
        "bits": acquisition.bits,
        "seed": seed,
    }
    for name in record.channels:
        info[f"sensitivity_v_per_n_{name}"] = acquisition.sensitivity(name)
        info[f"full_scale_v_{name}"] = record.full_scale_v[name]
        info[f"dc_offset_v_{name}"] = float(_per_channel(acquisition.dc_offset_v, name, "dc_offset_v"))
    for key, value in info.items():
        if value is not None:
            header[f"x_acq_{key}"] = repr(value) if isinstance(value, float) else str(value)
    for key, value in (truth or {}).items():
        header[f"x_true_{key}"] = (
            repr(float(value)) if isinstance(value, (float, int)) else str(value)
        )
    return TraceFile(header=header, time_s=record.time_s, channels=record.channels)


def record_simulation(
    setup, traces, acquisition: Acquisition = Acquisition(), *, seed=0, truth: dict | None = None
) -> TraceFile:
    """`acquire_trace` of every channel of a `Traces` from `simulate(setup, ...)`.

    Simulate with a `sample_interval_s` several times finer than the recording's (10 times
    is plenty for a 1 us recording) and long enough to cover the record after the trigger.
    """
    if np.ndim(traces.time_s) != 1:
        raise ValueError("record_simulation takes the traces of one run, not of a batch.")
    forces = {name: np.asarray(traces.forces_n[name]) for name in traces.channel_names}
    return acquire_trace(
        setup, np.asarray(traces.time_s), forces, acquisition, seed=seed, truth=truth
    )
