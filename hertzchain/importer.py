"""Recorded shots described by an `experiment.toml`, turned into `hertzchain-trace/1` files.

A lab keeps, for a series of shots, the chain it built, how the scope was set, what each
scope channel measured and with which sensitivity, and which files belong to which shot.
That is the experiment file::

    [chain]                     # the trace header's keys (see hertzchain.tracefile)
    n_beads = 21
    bead_radius_m = 0.013
    bead_density_kg_m3 = 7780
    bead_youngs_pa = 203e9
    bead_poisson = 0.3
    wall_youngs_pa = 203e9
    wall_poisson = 0.3
    striker_mass_kg = 0.0716    # and/or striker_radius_m, if they agree

    [scope]
    format = "tek-csv"          # or "auto"; hertzchain.scopefiles.FORMATS lists them
    time_zero = "trigger"       # or a delay in s ("12us"), or "channel:CH3>2.5V" / "channel:CH3<-1V",
                                # or "channel:CH3>2.5V+40us" (a light gate 40 us before the impact)

    [[channel]]
    source = "CH1"              # the scope's name of the channel
    measures = "wall"           # "wall" | "contact_K" | "sensor_K"
    sensitivity_v_per_n = 0.1124
    coupling = "ac"             # "ac" (piezo: reads changes of force) | "dc"

    [[channel]]
    source = "CH2"
    measures = "sensor_11"
    sensitivity_v_per_n = 0.01124
    sensor_beta = 0.11
    sensor_f0_hz = 85000

    [[shot]]
    files = ["shot1_CH1.csv", "shot1_CH2.csv"]
    striker_velocity_m_s = 0.3  # optional: measured, else a fit's nuisance

Keys (unknown keys are an error naming the valid ones; quantities may carry units as
strings, e.g. `"11.24mV/N"` is not parsed but `"13mm"` is, for keys whose unit is a plain SI
unit):

- `[chain]`: `CHAIN_KEYS`.
- `[scope]`: `SCOPE_KEYS`: `format`, `time_zero`, and `baseline_end_s`, the end of the
  segment from which offsets and noise are taken (default 0: everything before the impact).
- `[[channel]]`: `CHANNEL_KEYS`: also `noise_std_n` and `offset_v` from a notebook (else
  estimated from the pre-trigger segment), `range_v = [low, high]` (the digitiser's
  limits, when the file does not state them), `invert` (a sensor wired with the opposite
  sign).
- `[[shot]]`: `SHOT_KEYS`: also `label` (a plain name, not a path: the shot's trace file is
  `<label>.csv`, named by `hertzchain.atomic.file_stem`), `nominal_velocity_m_s` (shots at
  the same nominal velocity are repeats, see `hertzchain analyze`), and any `[chain]` key
  that differs for this shot (another wall, say). A scope file outside the experiment file's
  folder may be named, but the content of such a file is never quoted in an error.
- `[prior]` (optional): the lab's tolerances, `name = "TEXT"` in the syntax of
  `fitting.priors` (`bead_youngs = "203GPa+-4GPa"`, `sensor_gain = "+-2%"`); `hertzchain
  fit` uses them as if given with `--prior`.

Conditioning (`hertzchain.conditioning`), each step written in the header as `x_import_*`
keys so a result can be traced back to the files: the time grid made exact; time zero set
as `time_zero` says, pre-trigger samples kept with negative times, and checked against the
pulse's arrivals (`check_time_zero`: a `TimeZeroWarning` that names the delay it sees when
they put the impact elsewhere); offset removed (the
notebook's `offset_v`, else the pre-trigger mean); volts to newtons by the sensitivity;
noise sigma per channel (the notebook's, else the pre-trigger standard deviation with the
quantisation floor) written as `noise_std_n_<channel>`, with the number of pre-trigger
samples it was estimated from as `x_import_<channel>_noise_samples` (0: the notebook's); samples at the range limit written
as `clipped_<channel>` (left out of fits). An `"ac"` channel, and a `"dc"` channel whose
zero comes from the pre-trigger segment, reads the change of force since before the
impact: it is listed in `ac_channels`, and the model compares it with that change.
"""

from __future__ import annotations

import dataclasses
import math
import re
import tomllib
import warnings
from pathlib import Path

import numpy as np

from . import conditioning
from .atomic import file_stem
from .scopefiles import FORMATS, ScopeFileError, merge_waveforms, read_waveforms
from .tracefile import FORMAT, HEADER_KEYS, TraceFile, TraceFileError, format_rows, write_trace
from .units import parse_field, parse_quantity

# Plausible sensitivities, V/N: from a 0.1 mV/N load cell to a 10 V/N amplified sensor.
SENSITIVITY_RANGE_V_PER_N = (1e-4, 10.0)
MEASURES = ("wall", "contact_K", "sensor_K")
COUPLINGS = ("ac", "dc")
# Analogue noise (in converter steps) below which a channel's quantisation error is taken as
# correlated and signal-dependent: the quantisation theorem's white, uniform error model holds
# for a normal input once its sigma reaches about half a step (Widrow & Kollar, Quantization
# Noise, 2008, ch. 11), not below. Measured on 8-bit AC-coupled files of a second generator
# (benchmarks/results/scope_files/noise*/): at 0.25 step the white-noise standard
# errors were 0.58-0.81 of the spread over seeds, at 1 step 0.85-1.13; the value is the
# theorem's, not fitted between the two.
DITHER_STEPS = 0.5

_MEASUREMENT_KEYS = ("format", "striker_velocity_m_s", "noise_std_n", "ac_channels", "sensor_beta",
                     "sensor_f0_hz")
CHAIN_KEYS = tuple(k for k in HEADER_KEYS if k not in _MEASUREMENT_KEYS)
SCOPE_KEYS = ("format", "time_zero", "baseline_end_s")
CHANNEL_KEYS = ("source", "measures", "sensitivity_v_per_n", "coupling", "noise_std_n", "offset_v",
                "range_v", "invert", "sensor_beta", "sensor_f0_hz")
SHOT_KEYS = ("files", "label", "striker_velocity_m_s", "nominal_velocity_m_s", "time_zero") + CHAIN_KEYS
_TOP_KEYS = ("chain", "scope", "channel", "shot", "prior")
# Units of keys that may be written as strings with a unit ("13mm").
class TimeZeroWarning(UserWarning):
    """A shot whose pulse arrivals put the impact far from its time zero (see
    `check_time_zero`)."""


class ExperimentFileError(ValueError):
    """An experiment file that cannot be imported; the message names the file, the key or
    shot, and the fix."""


@dataclasses.dataclass(frozen=True)
class Channel:
    """One scope channel: `source` (scope name), `measures` (trace channel name),
    `sensitivity_v_per_n`, `coupling`, and optional notebook values `noise_std_n` (N),
    `offset_v` (V), `range_v` (V, V), `invert`, `sensor_beta`, `sensor_f0_hz`."""

    source: str
    measures: str
    sensitivity_v_per_n: float
    coupling: str = "ac"
    noise_std_n: float | None = None
    offset_v: float | None = None
    range_v: tuple[float, float] | None = None
    invert: bool = False
    sensor_beta: float | None = None
    sensor_f0_hz: float | None = None


@dataclasses.dataclass(frozen=True)
class Shot:
    """One shot: `files` (paths), `label`, measured `striker_velocity_m_s` (or None),
    `nominal_velocity_m_s` (or None), `time_zero` (its own, or None), `chain` (overrides)."""

    files: tuple[Path, ...]
    label: str
    striker_velocity_m_s: float | None
    nominal_velocity_m_s: float | None
    time_zero: object
    chain: dict


@dataclasses.dataclass(frozen=True)
class ExperimentDescription:
    """A parsed and checked experiment file (see the module docstring)."""

    path: Path
    chain: dict
    format: str
    time_zero: object
    baseline_end_s: float
    channels: tuple[Channel, ...]
    shots: tuple[Shot, ...]
    priors: tuple[str, ...] = ()


def _fail(where, message):
    raise ExperimentFileError(f"{where}: {message}")


def _check_keys(table: dict, valid, where: str) -> None:
    for key in table:
        if key not in valid and not key.startswith("x_"):
            _fail(where, f"unknown key {key!r}; valid keys: {', '.join(valid)} (prefix your own with 'x_').")


def quantity_of_key(value, key: str, where: str) -> float:
    """The value of an experiment-file key in SI: a number, or a string with a unit matching
    the key's suffix ("13mm" for *_m); `where` names the place in errors."""
    if isinstance(value, bool):
        _fail(where, f"{key} must be a number, got {value!r}.")
    if isinstance(value, (int, float)):
        return float(value)
    try:
        return parse_field(key, str(value), where=f"{where}: {key}")
    except ValueError as error:
        raise ExperimentFileError(str(error)) from error


def _chain_values(table: dict, where: str) -> dict:
    values = {}
    for key, value in table.items():
        if key.startswith("x_"):
            values[key] = str(value)
        elif HEADER_KEYS[key].kind is str:
            values[key] = str(value)
        elif HEADER_KEYS[key].kind is int:
            if isinstance(value, bool) or not isinstance(value, int):
                _fail(where, f"{key} must be an integer, got {value!r}.")
            values[key] = value
        else:
            values[key] = quantity_of_key(value, key, where)
    return values


_TIME_ZERO_CHANNEL = re.compile(r"^channel:(?P<source>[^<>]+?)\s*(?P<sign>[<>])\s*(?P<level>[-+]?[^-+]+?)"
                                r"\s*(?:(?P<after>[-+])\s*(?P<delay>[^-+].*))?$")


def _time_zero(value, where: str):
    """'trigger', a delay in s (the impact's time on the scope's clock), or
    ('channel', source, level_v, rising, delay_s): the impact `delay_s` after the channel
    crosses the level (`"channel:CH3>2.5V+40us"`, a light gate 40 us before the impact)."""
    if value == "trigger":
        return value
    if isinstance(value, str) and value.startswith("channel:"):
        match = _TIME_ZERO_CHANNEL.match(value.strip())
        try:
            if match is None:
                raise ValueError(value)
            level = parse_quantity(match["level"].strip(), "V")
            delay = 0.0
            if match["delay"] is not None:
                delay = parse_quantity(match["delay"].strip(), "s")
                delay = -delay if match["after"] == "-" else delay
            return ("channel", match["source"].strip(), level, match["sign"] == ">", delay)
        except ValueError:
            _fail(where, f"time_zero = {value!r}: write 'channel:NAME>LEVEL' or 'channel:NAME<LEVEL' with "
                         "the level in volts, and, when the channel fires before the impact (a light "
                         "gate), '+DELAY' for the time from the crossing to the impact: "
                         "'channel:CH3>2.5V+40us'.")
    try:
        return quantity_of_key(value, "time_zero_s", where)
    except ExperimentFileError:
        _fail(where, f"time_zero = {value!r}: use 'trigger', a delay such as '12us', or "
                     "'channel:NAME>LEVEL' (optionally '+DELAY', e.g. 'channel:CH3>2.5V+40us').")


def _channel(table: dict, where: str) -> Channel:
    _check_keys(table, CHANNEL_KEYS, where)
    for key in ("source", "measures", "sensitivity_v_per_n"):
        if key not in table:
            _fail(where, f"missing key {key!r}.")
    measures = str(table["measures"])
    kind, _, index = measures.partition("_")
    if not (measures == "wall" or (kind in ("contact", "sensor") and index.isdigit())):
        _fail(where, f"measures = {measures!r}; use one of {', '.join(MEASURES)} (K a number).")
    sensitivity = quantity_of_key(table["sensitivity_v_per_n"], "sensitivity_v_per_n", where)
    low, high = SENSITIVITY_RANGE_V_PER_N
    if not sensitivity > 0:
        _fail(where, f"sensitivity_v_per_n = {sensitivity!r} must be positive (V/N); a sensor "
                     "wired with the opposite sign takes invert = true.")
    if not low <= sensitivity <= high:
        _fail(where, f"sensitivity_v_per_n = {sensitivity!r} V/N is outside the plausible range "
                     f"{low:g}-{high:g} V/N (0.1 mV/N to 10 V/N); give it in V/N (11.24 mV/N is 0.01124).")
    coupling = str(table.get("coupling", "ac"))
    if coupling not in COUPLINGS:
        _fail(where, f"coupling = {coupling!r}; use 'ac' (piezo sensors) or 'dc'.")
    range_v = table.get("range_v")
    if range_v is not None:
        if not (isinstance(range_v, list) and len(range_v) == 2 and float(range_v[0]) < float(range_v[1])):
            _fail(where, f"range_v = {range_v!r}; give [low, high] in volts with low < high.")
        range_v = (float(range_v[0]), float(range_v[1]))
    optional = {}
    for key in ("noise_std_n", "offset_v", "sensor_beta", "sensor_f0_hz"):
        if key in table:
            optional[key] = quantity_of_key(table[key], key, where)
    if "noise_std_n" in optional and not optional["noise_std_n"] > 0:
        _fail(where, f"noise_std_n = {optional['noise_std_n']!r} must be positive (N).")
    if kind == "sensor":
        for key in ("sensor_beta", "sensor_f0_hz"):
            if key not in optional:
                _fail(where, f"{measures} is an embedded sensor: give {key} "
                             "(the paper's: sensor_beta = 0.11, sensor_f0_hz = 85000).")
    return Channel(str(table["source"]), measures, sensitivity, coupling, range_v=range_v,
                   invert=bool(table.get("invert", False)), **optional)


def _read_document(path: Path) -> dict:
    try:
        document = tomllib.loads(path.read_text(encoding="utf-8"))
    except tomllib.TOMLDecodeError as error:
        _fail(str(path), f"not valid TOML ({error}).")
    except UnicodeDecodeError:
        _fail(str(path), "not UTF-8 text; an experiment file is TOML, saved as UTF-8.")
    if "kind" in document:
        _fail(str(path), f"kind = {document['kind']!r}: an experiment of shots (scope files) has no kind key; a "
                         "driven experiment (kind = \"driven\", lock-in sweeps) is read by `hertzchain fit` and "
                         "`hertzchain diagnose` with --data-dir.")
    _check_keys(document, _TOP_KEYS, str(path))
    if "chain" not in document:
        _fail(str(path), "missing [chain] table.")
    _check_keys(document["chain"], CHAIN_KEYS, f"{path} [chain]")
    return document


def load_chain(path) -> dict:
    """The `[chain]` table of a TOML file, quantities in SI (`"13mm"` -> 0.013): an experiment
    file's, or that of a setup file holding only a `[chain]` table (`hertzchain simulate
    --config`). Keys are those of `CHAIN_KEYS` (and `x_` keys, kept as text); raises
    `ExperimentFileError` naming the file and the key."""
    path = Path(path)
    return _chain_values(_read_document(path)["chain"], f"{path} [chain]")


def load_experiment(path) -> ExperimentDescription:
    """Read and check an experiment file; raises `ExperimentFileError` naming what is wrong."""
    path = Path(path)
    where = str(path)
    document = _read_document(path)
    for key in ("channel", "shot"):
        if key not in document:
            _fail(where, f"missing [{key}] entries ([[{key}]]).")
    chain = _chain_values(document["chain"], f"{where} [chain]")
    scope = document.get("scope", {})
    _check_keys(scope, SCOPE_KEYS, f"{where} [scope]")
    file_format = str(scope.get("format", "auto"))
    if file_format != "auto" and file_format not in FORMATS:
        _fail(f"{where} [scope]", f"format = {file_format!r} is not supported; formats: auto, "
                                  + ", ".join(f"{k} ({v})" for k, v in FORMATS.items()) + ".")
    time_zero = _time_zero(scope.get("time_zero", "trigger"), f"{where} [scope]")
    baseline_end = quantity_of_key(scope.get("baseline_end_s", 0.0), "baseline_end_s", f"{where} [scope]")

    channels = tuple(_channel(t, f"{where} [[channel]] #{k + 1}") for k, t in enumerate(document["channel"]))
    for attribute in ("source", "measures"):
        seen = {}
        for k, channel in enumerate(channels):
            value = getattr(channel, attribute)
            if value in seen:
                _fail(where, f"[[channel]] #{seen[value] + 1} and #{k + 1} both have {attribute} = "
                             f"{value!r}; each scope channel and each measured force appears once.")
            seen[value] = k
    sensors = [c for c in channels if c.measures.startswith("sensor_")]
    for key in ("sensor_beta", "sensor_f0_hz"):
        values = {getattr(c, key) for c in sensors}
        if len(values) > 1:
            _fail(where, f"the embedded sensors have different {key} ({sorted(values)}); the model "
                         "takes one value for all of them.")
    n_beads = chain.get("n_beads")
    for channel in channels:
        kind, _, index = channel.measures.partition("_")
        if n_beads and index and not (0 <= int(index) < n_beads if kind == "contact" else 1 <= int(index) <= n_beads):
            _fail(where, f"measures = {channel.measures!r} is outside a chain of {n_beads} beads.")

    shots, labels = [], set()
    for k, table in enumerate(document["shot"]):
        at = f"{where} [[shot]] #{k + 1}"
        _check_keys(table, SHOT_KEYS, at)
        files = table.get("files")
        if isinstance(files, str):
            files = [files]
        if not files or not all(isinstance(f, str) for f in files):
            _fail(at, "files = [...] must list the shot's scope files.")
        resolved = tuple((path.parent / f) for f in files)
        missing = [str(f) for f in resolved if not f.is_file()]
        if missing:
            _fail(at, f"no such file: {', '.join(missing)} (paths are relative to the experiment file).")
        label = str(table.get("label", Path(files[0]).stem))
        if re.search(r"[/\\]", label) or label.strip().startswith("."):
            _fail(at, f"label = {label!r} names a path; a label is a plain name (its trace file is "
                      f"written as <label>.csv in the output folder): write e.g. label = {file_stem(label)!r}.")
        if file_stem(label) in labels:
            label = f"{label}_{k + 1}"
        labels.add(file_stem(label))
        overrides = _chain_values({key: table[key] for key in table if key in CHAIN_KEYS}, at)
        velocity = table.get("striker_velocity_m_s")
        nominal = table.get("nominal_velocity_m_s")
        shots.append(Shot(
            files=resolved, label=label,
            striker_velocity_m_s=None if velocity is None else quantity_of_key(velocity, "striker_velocity_m_s", at),
            nominal_velocity_m_s=None if nominal is None else quantity_of_key(nominal, "nominal_velocity_m_s", at),
            time_zero=None if "time_zero" not in table else _time_zero(table["time_zero"], at),
            chain=overrides,
        ))
    priors = document.get("prior", {})
    if not isinstance(priors, dict) or not all(isinstance(v, str) for v in priors.values()):
        _fail(f"{where} [prior]", 'each entry is name = "TEXT", e.g. bead_youngs = "203GPa+-4GPa" '
                                  'or sensor_gain = "+-2%".')
    return ExperimentDescription(path, chain, file_format, time_zero, baseline_end, channels, tuple(shots),
                                 tuple(f"{key}={value}" for key, value in priors.items()))


def _read_shot(description: ExperimentDescription, shot: Shot, where: str):
    parts = []
    folder = description.path.parent.resolve()
    for file in shot.files:
        try:
            parts.append(read_waveforms(file, description.format))
        except ScopeFileError as error:
            if not file.resolve().is_relative_to(folder):
                # the reader's message quotes the file's lines: not of a file outside the experiment's folder
                raise ExperimentFileError(
                    f"{where}: {file} is not a scope file of format {description.format!r}; it lies outside the "
                    f"experiment's folder {folder}, so its content is not shown: check files = [...] of the shot."
                ) from None
            raise ExperimentFileError(f"{where}: {error}") from error
    try:
        return merge_waveforms(parts, where)
    except ScopeFileError as error:
        raise ExperimentFileError(str(error)) from error


def condition_shot(description: ExperimentDescription, shot: Shot) -> TraceFile:
    """The trace file of one shot: its scope files read, merged and conditioned."""
    where = f"{description.path} shot {shot.label!r}"
    waves = _read_shot(description, shot, where)
    missing = [c.source for c in description.channels if c.source not in waves.channels]
    if missing:
        _fail(where, f"no channel {', '.join(missing)} in {', '.join(str(f) for f in shot.files)} "
                     f"(they hold {', '.join(waves.channels) or 'none'}); every shot needs every [[channel]].")
    try:
        time, deviation = conditioning.regular_time_grid(waves.time_s, where)
        time_zero = description.time_zero if shot.time_zero is None else shot.time_zero
        if time_zero == "trigger":
            zero = 0.0
        elif isinstance(time_zero, tuple):
            _, source, level, rising, delay = time_zero
            if source not in waves.channels:
                _fail(where, f"time_zero names channel {source!r}, which the files do not have "
                             f"({', '.join(waves.channels)}).")
            zero = delay + conditioning.crossing_time_s(time, waves.channels[source], level, rising,
                                                        f"{where} {source}")
        else:
            zero = float(time_zero)
        time = time - zero
        before = time < description.baseline_end_s
        header = {"format": FORMAT, **description.chain, **shot.chain}
        info = {"experiment": str(description.path), "files": ";".join(str(f) for f in shot.files),
                "format": waves.format, "time_zero_s": repr(zero),
                "time_grid_deviation_samples": f"{deviation:.3g}"}
        if shot.striker_velocity_m_s is not None:
            header["striker_velocity_m_s"] = shot.striker_velocity_m_s
        if shot.nominal_velocity_m_s is not None:
            info["nominal_velocity_m_s"] = repr(shot.nominal_velocity_m_s)
        channels, ac, noise = {}, [], {}
        for channel in description.channels:
            name, at = channel.measures, f"{where} channel {channel.source} ({channel.measures})"
            volts = np.asarray(waves.channels[channel.source], dtype=float)
            step_v = conditioning.quantisation_step(volts, waves.lsb_v.get(channel.source))
            range_v = channel.range_v or waves.range_v.get(channel.source)
            clipped = conditioning.clipped_mask(volts, range_v, step_v)
            needs_baseline = channel.offset_v is None or channel.noise_std_n is None
            base = conditioning.baseline(volts, before & ~clipped, step_v, at) if needs_baseline else None
            offset = channel.offset_v if channel.offset_v is not None else base.offset
            sign = -1.0 if channel.invert else 1.0
            force = sign * (volts - offset) / channel.sensitivity_v_per_n
            if channel.noise_std_n is not None:
                sigma, noise_source = channel.noise_std_n, "notebook"
            else:
                sigma, noise_source = base.noise_std / channel.sensitivity_v_per_n, "pre-trigger"
            referenced_at_rest = channel.coupling == "ac" or channel.offset_v is None
            if referenced_at_rest:
                ac.append(name)
            channels[name] = force
            noise[name] = sigma
            header[f"noise_std_n_{name}"] = sigma
            if clipped.any():
                header[f"clipped_{name}"] = format_rows(clipped)
            if name.startswith("sensor_"):
                header["sensor_beta"] = channel.sensor_beta
                header["sensor_f0_hz"] = channel.sensor_f0_hz
            prefix = f"{name}_"
            if base is not None and base.quantisation_floor > 0 and channel.noise_std_n is None:
                analogue = math.sqrt(max(base.noise_std**2 - base.quantisation_floor**2, 0.0)) / step_v
                info[prefix + "analogue_noise_steps"] = repr(analogue)
                if analogue < DITHER_STEPS:
                    info[prefix + "noise_note"] = (
                        f"analogue noise {analogue:.2f} of a converter step: the converter's error of a slowly "
                        "changing signal is correlated from sample to sample, so standard errors from this "
                        "white-noise sigma come out too small (0.6-0.8x the seed-to-seed spread for 0.25 step); "
                        "hertzchain fit uses the covariance for correlated residuals then")
            info |= {
                prefix + "source": channel.source,
                prefix + "sensitivity_v_per_n": repr(channel.sensitivity_v_per_n),
                prefix + "coupling": channel.coupling,
                prefix + "invert": str(channel.invert),
                prefix + "offset_v": repr(float(offset)),
                prefix + "offset_source": "notebook" if channel.offset_v is not None else
                f"pre-trigger mean of {base.n_samples} samples",
                prefix + "noise_source": noise_source,
                prefix + "noise_samples": str(base.n_samples if noise_source == "pre-trigger" else 0),
                prefix + "quantisation_step_v": "unknown" if step_v is None else repr(step_v),
                prefix + "range_v": "unknown" if range_v is None else f"{range_v[0]!r};{range_v[1]!r}",
                prefix + "clipped_samples": str(int(clipped.sum())),
                prefix + "reads": "change of force since before the impact" if referenced_at_rest
                else "force (zero from the notebook's offset_v)",
            }
        header["noise_std_n"] = max(noise.values())
        info["time_zero_check"] = check_time_zero(time, channels, header.get("n_beads"), where,
                                                  time_zero, zero)
        if ac:
            header["ac_channels"] = ",".join(ac)
        header |= {f"x_import_{k}": v for k, v in info.items()}
        header["x_shot"] = shot.label
        return TraceFile(header=header, time_s=time, channels=channels, path=where)
    except (conditioning.ConditioningError, TraceFileError) as error:
        raise ExperimentFileError(str(error)) from error


def _position(name: str, n_beads: int | None) -> float | None:
    """Position of a trace channel in bead diameters from the striker contact."""
    kind, _, index = name.partition("_")
    if kind in ("contact", "sensor") and index.isdigit():
        return float(index)
    return float(n_beads) if name == "wall" and n_beads else None


def check_time_zero(time_s, channels: dict, n_beads, where: str, time_zero, zero_s: float) -> str:
    """Whether the shot's pulse arrivals agree with its time zero; the text for the header.

    The half-rise times of the first pulse at two or more positions, extrapolated to the
    striker contact (`conditioning.impact_time_s`), give the impact time on the new clock:
    from the contacts and sensors when two or more show the pulse, else with the wall's
    channel as well (its rise depends on the wall's stiffness: a wider band,
    `conditioning.IMPACT_BAND_WITH_WALL_TRANSITS`). Beyond the band (in one-bead transit
    times about 0) a `TimeZeroWarning` names the delay seen and the fix (for a trigger
    channel: the delay to add, `'channel:CH3>2.5V+40us'`)."""
    inside = {p: force for name, force in channels.items()
              if name != "wall" and (p := _position(name, n_beads)) is not None}
    found = conditioning.impact_time_s(time_s, inside)
    low, high = conditioning.IMPACT_BAND_TRANSITS
    if found is None and "wall" in channels and n_beads:
        found = conditioning.impact_time_s(time_s, inside | {float(n_beads): channels["wall"]})
        low, high = conditioning.IMPACT_BAND_WITH_WALL_TRANSITS
    if found is None:
        return "not checked: fewer than two channels at different positions show the pulse"
    impact, transit = found
    text = (f"the arrivals put the impact at {impact * 1e6:+.1f} us ({impact / transit:+.2f} transits of "
            f"one bead, {transit * 1e6:.1f} us); expected {low:+g} to {high:+g}")
    if not low * transit <= impact <= high * transit:
        if isinstance(time_zero, tuple):
            _, source, level, rising, delay = time_zero
            fix = (f"if {source} fires {impact * 1e6:.0f} us before the impact (a light gate), write "
                   f"time_zero = 'channel:{source}{'>' if rising else '<'}{level:g}V"
                   f"{delay * 1e6 + impact * 1e6:+.0f}us'")
        else:
            fix = f"give the impact's time on the scope's clock, e.g. time_zero = '{(zero_s + impact) * 1e6:.0f}us'"
        warnings.warn(f"{where}: time zero looks wrong: {text}; {fix}. A wrong time zero shows in a fit "
                      "as a large chi^2 and a biased striker velocity.", TimeZeroWarning, stacklevel=3)
        return "off: " + text
    return "ok: " + text


def import_experiment(path) -> list[TraceFile]:
    """Every shot of an experiment file as a `TraceFile` (in memory; forces in N)."""
    description = load_experiment(path)
    return [condition_shot(description, shot) for shot in description.shots]


def write_imported(path, out_dir) -> list[Path]:
    """`import_experiment` written as one trace file per shot, `out_dir/<label>.csv`.

    Every shot is conditioned before anything is written, so a bad shot leaves no files;
    each file is written atomically.
    """
    traces = import_experiment(path)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    written = []
    for trace in traces:
        target = out / f"{file_stem(trace.header['x_shot'])}.csv"
        write_trace(target, trace)
        written.append(target)
    return written


def is_experiment_file(path) -> bool:
    """Whether a path given where trace files are accepted is an experiment file (`.toml`)."""
    return str(path).lower().endswith(".toml")


def experiment_priors(paths) -> tuple[str, ...]:
    """The `[prior]` entries (`"name=TEXT"`) of the experiment files among `paths`; the same
    entry in several files counts once, different ones for one name are an error naming both."""
    found: dict[str, tuple[str, Path]] = {}
    for path in paths:
        if not is_experiment_file(path):
            continue
        for text in load_experiment(path).priors:
            key = text.split("=", 1)[0]
            if key in found and found[key][0] != text:
                raise ExperimentFileError(
                    f"{path} [prior]: {text!r} differs from {found[key][0]!r} in {found[key][1]}; "
                    "one experiment's tolerances must agree."
                )
            found[key] = (text, Path(path))
    return tuple(text for text, _ in found.values())


def expand_sources(paths) -> list:
    """Paths of trace files as given, with each experiment file replaced by its shots'
    `TraceFile`s (imported in memory)."""
    sources = []
    for path in paths:
        if is_experiment_file(path):
            sources.extend(import_experiment(path))
        else:
            sources.append(path)
    return sources


__all__ = [
    "COUPLINGS", "Channel", "ExperimentDescription", "ExperimentFileError", "MEASURES", "Shot", "TimeZeroWarning",
    "check_time_zero",
    "condition_shot", "expand_sources", "experiment_priors", "import_experiment", "is_experiment_file", "load_experiment",
    "write_imported",
]
