"""The trace-file format `hertzchain-trace/1`: recorded or synthetic experiments as CSV.

A file is a block of `# key = value` header lines followed by a CSV table::

    # format = hertzchain-trace/1
    # n_beads = 21
    # bead_radius_m = 0.013
    # bead_density_kg_m3 = 7780
    # bead_youngs_pa = 2.03e11
    # bead_poisson = 0.3
    # wall_youngs_pa = 2.03e11
    # wall_poisson = 0.3
    # striker_mass_kg = 0.0089
    # striker_velocity_m_s = 0.3
    # noise_std_n = 0.37
    # units: time_s in s; contact_K, sensor_K and wall are forces in N
    time_s,contact_6,contact_11,wall
    2.0e-06,0.22,0.82,0.37

It opens in any spreadsheet and with `pandas.read_csv(path, comment="#")`.

- Beads are numbered 1..N from the striker end. `contact_K` is the force (N) between bead K
  and bead K+1 (`contact_0`: striker on bead 1), `wall` the force on the wall,
  `sensor_K` the signal (N) of a sensor embedded in bead K (then `sensor_beta` and
  `sensor_f0_hz` are required).
- Time 0 is the impact (the trigger); samples are evenly spaced and increasing. Samples
  before the impact (a scope's pre-trigger segment) have negative times; the chain is at
  rest there (a static preload, if any, is the only force).
- The beads' density may be given as `bead_density_kg_m3`, as `bead_mass_kg`, or both if
  they agree (to `REDUNDANT_TOLERANCE`); likewise the striker's `striker_mass_kg` and
  `striker_radius_m` (a sphere of the beads' material unless `striker_density_kg_m3`,
  `striker_youngs_pa`, `striker_poisson` say otherwise). Values that disagree are an error
  naming both and the value the others imply. `striker_velocity_m_s` and `noise_std_n` may
  be absent (they are then estimated by the tools that need them).
- Measurement keys: `noise_std_n` holds for every channel unless `noise_std_n_<channel>`
  gives that channel's own; `ac_channels` lists (comma-separated) the channels that read
  changes of force since before the impact, as piezo sensors behind AC-coupled
  conditioners do: a static preload is not in them; `clipped_<channel>` lists the rows
  (0-based data rows, ranges `a-b` inclusive, comma-separated) where the digitiser was at
  its range limit: those samples are kept in the file and left out of fits.
- Further keys: see `HEADER_KEYS`. Unknown keys are an error unless prefixed `x_`
  (free-form, kept as text, e.g. the true parameters of a synthetic file).
"""

from __future__ import annotations

import dataclasses
import io
import math
import re
from pathlib import Path

import numpy as np

from ..chain import ChainSetup
from ..materials import sphere_mass_kg
from ..validation import RULES, check_plausible
from .atomic import write_text

FORMAT = "hertzchain-trace/1"
# Redundant header values (a mass and the density and radius it follows from) must agree to
# this relative difference: bead masses and diameters are quoted to about 0.1-0.5 % (the
# paper's beads: diameter +-125 um of 26 mm, i.e. +-0.5 %), so a larger gap is a mistake.
REDUNDANT_TOLERANCE = 5e-3


@dataclasses.dataclass(frozen=True)
class _Key:
    kind: type
    required: bool
    low: float = -math.inf
    high: float = math.inf
    meaning: str = ""


# key -> (type, required, plausible range in SI, meaning). The ranges catch values given in
# the wrong unit (a radius of 13 "m", a modulus of 203 "Pa"); for the fields of a setup they
# are those of `validation.RULES`, which is what a header is checked against.
HEADER_KEYS: dict[str, _Key] = {
    "format": _Key(str, True, meaning=f"must be {FORMAT}"),
    "n_beads": _Key(int, True, 1, 1e6, "number of beads"),
    "bead_radius_m": _Key(float, True, meaning="bead radius, m"),
    "bead_density_kg_m3": _Key(float, False, meaning="bead density, kg/m^3 (or bead_mass_kg)"),
    "bead_mass_kg": _Key(float, False, meaning="mass of one bead, kg (or bead_density_kg_m3)"),
    "bead_youngs_pa": _Key(float, True, meaning="bead Young's modulus, Pa"),
    "bead_poisson": _Key(float, True, meaning="bead Poisson ratio"),
    "wall_youngs_pa": _Key(float, True, meaning="wall Young's modulus, Pa (inf: rigid)"),
    "wall_poisson": _Key(float, True, meaning="wall Poisson ratio"),
    "striker_mass_kg": _Key(float, False, meaning="striker mass, kg"),
    "striker_radius_m": _Key(float, False, meaning="striker radius, m"),
    "striker_density_kg_m3": _Key(float, False, meaning="striker density, kg/m^3"),
    "striker_youngs_pa": _Key(float, False, meaning="striker Young's modulus, Pa"),
    "striker_poisson": _Key(float, False, meaning="striker Poisson ratio"),
    "striker_velocity_m_s": _Key(float, False, meaning="impact velocity, m/s (> 0)"),
    "noise_std_n": _Key(float, False, 0.0, 1e6, "standard deviation of the additive noise, N"),
    "precompression_n": _Key(float, False, meaning="static preload, N"),
    "sensor_beta": _Key(float, False, meaning="embedded sensor mass ratio beta"),
    "sensor_f0_hz": _Key(float, False, meaning="embedded sensor resonance, Hz"),
    "end": _Key(str, False, meaning="'wall' (default) or 'free'"),
    "ac_channels": _Key(str, False, meaning="channels that do not see a static force, comma-separated"),
}
# Per-channel keys: `<prefix><channel>`.
CHANNEL_KEYS: dict[str, _Key] = {
    "noise_std_n_": _Key(float, False, 0.0, 1e6, "noise standard deviation of the channel, N"),
    "clipped_": _Key(str, False, meaning="rows at the digitiser's range limit, e.g. 120-131,140"),
}

# The comment line before the table that states the columns' units (no "=": not a key).
UNITS_LINE = "units: time_s in s; contact_K, sensor_K and wall are forces in N"

_HEADER_LINE = re.compile(r"^#\s*([A-Za-z_][A-Za-z0-9_]*)\s*=\s*(.*?)\s*$")
_CHANNEL = re.compile(r"^(contact|sensor)_(\d+)$")
_CHANNEL_NAME = re.compile(r"^(?:(?:contact|sensor)_\d+|wall)$")


def _spec(key: str) -> _Key | None:
    """The specification of a header key (per-channel keys included), None if unknown."""
    if key in HEADER_KEYS:
        return HEADER_KEYS[key]
    for prefix, spec in CHANNEL_KEYS.items():
        if key.startswith(prefix) and _CHANNEL_NAME.match(key[len(prefix):]):
            return spec
    return None


def parse_rows(text: str, where: str = "<header>") -> np.ndarray:
    """Row indices (0-based, sorted) of a `clipped_<channel>` value such as `"3-5,9"`."""
    rows = []
    for part in str(text).split(","):
        part = part.strip()
        if not part:
            continue
        match = re.fullmatch(r"(\d+)(?:\s*-\s*(\d+))?", part)
        if not match:
            _fail(where, f"clipped rows must be numbers or ranges a-b, got {part!r}.")
        first = int(match.group(1))
        last = int(match.group(2)) if match.group(2) else first
        if last < first:
            _fail(where, f"clipped range {part!r} runs backwards.")
        rows.extend(range(first, last + 1))
    return np.unique(np.asarray(rows, dtype=int))


def format_rows(mask) -> str:
    """The `clipped_<channel>` text of a boolean row mask: runs as `a-b`, single rows as `a`."""
    rows = np.flatnonzero(np.asarray(mask, dtype=bool))
    if rows.size == 0:
        return ""
    breaks = np.flatnonzero(np.diff(rows) > 1)
    starts = np.concatenate([[rows[0]], rows[breaks + 1]])
    ends = np.concatenate([rows[breaks], [rows[-1]]])
    return ",".join(str(a) if a == b else f"{a}-{b}" for a, b in zip(starts, ends))


class TraceFileError(ValueError):
    """A trace file that does not follow the format; the message says where and how."""


@dataclasses.dataclass(frozen=True)
class TraceFile:
    """One experiment: header values (SI), the time axis and the force channels (N).

    **Fields:** `header` (key -> value; numbers as float/int, `x_` keys as text),
    `time_s` (n_samples,), `channels` (name -> (n_samples,) array, in file order),
    `path` (where it was read from, if anywhere).
    """

    header: dict
    time_s: np.ndarray
    channels: dict
    path: str | None = None

    def __post_init__(self):
        _validate(self.header, self.time_s, self.channels, self.path or "<trace>")

    @property
    def channel_names(self) -> tuple[str, ...]:
        return tuple(self.channels)

    @property
    def n_beads(self) -> int:
        return int(self.header["n_beads"])

    @property
    def sample_interval_s(self) -> float:
        return float(self.time_s[1] - self.time_s[0])

    @property
    def striker_velocity_m_s(self) -> float | None:
        return self.header.get("striker_velocity_m_s")

    @property
    def noise_std_n(self) -> float | None:
        """The file-wide noise standard deviation, N (None if not stated)."""
        return self.header.get("noise_std_n")

    def channel_noise_std_n(self, channel: str) -> float | None:
        """Noise standard deviation of one channel, N: its own key, else the file's, else None."""
        return self.header.get(f"noise_std_n_{channel}", self.header.get("noise_std_n"))

    @property
    def ac_channels(self) -> tuple[str, ...]:
        """Channels that read changes of force only (a static preload is not in them)."""
        return _ac_channel_names(self.header)

    def clipped(self, channel: str) -> np.ndarray:
        """Boolean mask (n_samples,) of the channel's samples at the digitiser's range limit."""
        mask = np.zeros(len(self.time_s), dtype=bool)
        mask[parse_rows(self.header.get(f"clipped_{channel}", ""))] = True
        return mask

    @property
    def sensor_beads(self) -> tuple[int, ...]:
        return tuple(int(name.split("_")[1]) for name in self.channels if name.startswith("sensor_"))

    @property
    def contacts(self) -> tuple[int, ...]:
        return tuple(int(name.split("_")[1]) for name in self.channels if name.startswith("contact_"))

    def setup(self, **overrides) -> ChainSetup:
        """The `ChainSetup` the header describes; `overrides` set or replace fields.

        A missing `striker_velocity_m_s` must be given in `overrides` (e.g. an estimate).
        """
        h = self.header
        values = {
            "bead_radius_m": h["bead_radius_m"],
            "bead_density_kg_m3": bead_density_kg_m3(h),
            "bead_youngs_pa": h["bead_youngs_pa"],
            "bead_poisson": h["bead_poisson"],
            "wall_youngs_pa": h["wall_youngs_pa"],
            "wall_poisson": h["wall_poisson"],
            "end": h.get("end", "wall"),
            "sensor_beads": self.sensor_beads,
        }
        for key in (
            "striker_mass_kg", "striker_radius_m", "striker_density_kg_m3", "striker_youngs_pa",
            "striker_poisson", "striker_velocity_m_s", "precompression_n", "sensor_beta",
            "sensor_f0_hz",
        ):
            if key in h:
                values[key] = h[key]
        values.update(overrides)
        if "striker_velocity_m_s" not in values:
            raise TraceFileError(
                f"{self.path or '<trace>'}: no striker_velocity_m_s in the header; give an estimate."
            )
        if "striker_mass_kg" in overrides or "striker_radius_m" in overrides:
            values.pop("striker_radius_m" if "striker_mass_kg" in overrides else "striker_mass_kg", None)
        elif "striker_mass_kg" in values and "striker_radius_m" in values:
            values.pop("striker_mass_kg")  # checked to agree with the radius on reading
        return ChainSetup(int(h["n_beads"]), **values)


def _fail(where: str, message: str):
    raise TraceFileError(f"{where}: {message}")


def _ac_channel_names(header: dict) -> tuple[str, ...]:
    return tuple(c.strip() for c in str(header.get("ac_channels", "")).split(",") if c.strip())


def bead_density_kg_m3(header: dict) -> float:
    """The beads' density, kg/m^3: `bead_density_kg_m3`, else from `bead_mass_kg` and the radius."""
    if "bead_density_kg_m3" in header:
        return float(header["bead_density_kg_m3"])
    return float(header["bead_mass_kg"]) / sphere_mass_kg(float(header["bead_radius_m"]), 1.0)


def _check_redundant(header: dict, where: str) -> None:
    """Redundant keys must agree to REDUNDANT_TOLERANCE; the error names both and the implied value."""
    def agree(given_key, given, implied, implied_from):
        if abs(given - implied) > REDUNDANT_TOLERANCE * abs(implied):
            _fail(
                where,
                f"{given_key} = {given:.6g} disagrees with {implied_from}, which imply {implied:.6g} "
                f"({100 * (given / implied - 1):+.3g} %, more than {100 * REDUNDANT_TOLERANCE:g} %): "
                f"correct one of them or give only one.",
            )

    radius = float(header["bead_radius_m"])
    if "bead_density_kg_m3" not in header and "bead_mass_kg" not in header:
        _fail(where, "missing header key '# bead_density_kg_m3 = ...' (or '# bead_mass_kg = ...').")
    if "bead_density_kg_m3" in header and "bead_mass_kg" in header:
        agree("bead_mass_kg", float(header["bead_mass_kg"]),
              sphere_mass_kg(radius, float(header["bead_density_kg_m3"])),
              f"bead_radius_m = {radius:.6g} and bead_density_kg_m3 = {header['bead_density_kg_m3']:.6g}")
    if "striker_mass_kg" in header and "striker_radius_m" in header:
        density = float(header.get("striker_density_kg_m3", bead_density_kg_m3(header)))
        source = ("striker_density_kg_m3" if "striker_density_kg_m3" in header else "the beads' density")
        agree("striker_mass_kg", float(header["striker_mass_kg"]),
              sphere_mass_kg(float(header["striker_radius_m"]), density),
              f"striker_radius_m = {header['striker_radius_m']:.6g} and {source} ({density:.6g} kg/m^3)")


def validate_header(header: dict, where: str = "<header>") -> None:
    """Check header keys and values (presence, type, plausible SI range); raises TraceFileError."""
    for key, spec in HEADER_KEYS.items():
        if spec.required and key not in header:
            _fail(where, f"missing header key '# {key} = ...' ({spec.meaning}).")
    if header["format"] != FORMAT:
        _fail(where, f"format is {header['format']!r}; this reader understands {FORMAT!r}.")
    for key, value in header.items():
        if key.startswith("x_"):
            continue
        spec = _spec(key)
        if spec is None:
            _fail(
                where,
                f"unknown header key {key!r}; known keys: {', '.join(HEADER_KEYS)}, and per channel "
                f"{', '.join(p + '<channel>' for p in CHANNEL_KEYS)} (prefix your own keys with 'x_').",
            )
        if spec.kind in (int, float):
            if not isinstance(value, (int, float)) or math.isnan(value):
                _fail(where, f"{key} must be a number, got {value!r}.")
            if key in RULES:
                try:
                    check_plausible(key, value)
                except ValueError as error:
                    _fail(where, str(error))
            elif not spec.low <= value <= spec.high:
                _fail(
                    where,
                    f"{key} = {value!r} is outside the plausible range [{spec.low:g}, {spec.high:g}] "
                    f"for {spec.meaning}: check the sign and that the value is in SI units.",
                )
    if header.get("end", "wall") not in ("wall", "free"):
        _fail(where, f"end must be 'wall' or 'free', got {header['end']!r}.")
    _check_redundant(header, where)


def _validate(header: dict, time_s: np.ndarray, channels: dict, where: str) -> None:
    validate_header(header, where)
    n_beads = int(header["n_beads"])
    if not channels:
        _fail(where, "no force channels after time_s.")
    for key in header:
        for prefix in CHANNEL_KEYS:
            if key.startswith(prefix) and key[len(prefix):] not in channels:
                _fail(where, f"header key {key} names a channel the table does not have "
                             f"({', '.join(channels)}).")
    for name in _ac_channel_names(header):
        if name not in channels:
            _fail(where, f"ac_channels names {name!r}, which the table does not have ({', '.join(channels)}).")
    time = np.asarray(time_s, dtype=float)
    if time.ndim != 1 or len(time) < 3:
        _fail(where, f"need at least 3 samples, got {len(time)}.")
    if not np.all(np.isfinite(time)):
        _fail(where, f"time_s has NaN or inf at row {int(np.argmin(np.isfinite(time))) + 1}.")
    step = np.diff(time)
    if np.any(step <= 0):
        _fail(where, f"time_s is not increasing at row {int(np.argmax(step <= 0)) + 2}.")
    if np.max(np.abs(step - step.mean())) > 1e-6 * step.mean() + 1e-15:
        _fail(
            where,
            f"time_s is not evenly spaced (steps from {step.min():.6g} to {step.max():.6g} s); "
            "resample to a uniform grid.",
        )
    for name, values in channels.items():
        match = _CHANNEL.match(name)
        if name != "wall" and not match:
            _fail(where, f"unknown channel {name!r}; channels are contact_K, sensor_K or wall.")
        if match:
            index = int(match.group(2))
            if match.group(1) == "contact" and not 0 <= index < n_beads:
                _fail(where, f"{name}: contacts run from 0 to {n_beads - 1} in a chain of {n_beads} beads.")
            if match.group(1) == "sensor":
                if not 1 <= index <= n_beads:
                    _fail(where, f"{name}: beads run from 1 to {n_beads}.")
                for key in ("sensor_beta", "sensor_f0_hz"):
                    if key not in header:
                        _fail(where, f"{name} needs the header key {key}.")
        array = np.asarray(values, dtype=float)
        if array.shape != time.shape:
            _fail(where, f"{name} has {array.size} values for {time.size} times.")
        rows = parse_rows(header.get(f"clipped_{name}", ""), where)
        if rows.size and rows[-1] >= time.size:
            _fail(where, f"clipped_{name} names row {rows[-1]}, but the table has rows 0..{time.size - 1}.")
        if not np.all(np.isfinite(array)):
            row = int(np.argmin(np.isfinite(array))) + 1
            _fail(where, f"{name} has NaN or inf at sample {row} (t = {time[row - 1]:.6g} s).")


def _parse_value(key: str, text: str, where: str):
    spec = _spec(key)
    if key.startswith("x_") or spec is None or spec.kind is str:
        return text
    try:
        number = float(text)
    except ValueError:
        decimal = " (write decimals with '.')" if re.fullmatch(r"\s*[-+]?\d+,\d+\s*", text) else ""
        _fail(where, f"header {key} = {text!r} is not a number{decimal}.")
    if spec.kind is int:
        if not math.isfinite(number) or number != int(number):
            _fail(where, f"header {key} must be an integer, got {text!r}.")
        return int(number)
    return number


def read_trace(path) -> TraceFile:
    """Read and validate a trace file; raises `TraceFileError` saying exactly what is wrong."""
    where = str(path)
    raw = Path(path).read_bytes()
    try:
        text = raw.decode("utf-8-sig")  # a byte-order mark, as some editors write, is no part of the text
    except UnicodeDecodeError as error:
        line = raw[:error.start].count(b"\n") + 1
        _fail(where, f"line {line}: not UTF-8 text (byte {raw[error.start:error.start + 1]!r}); a trace file is "
                     "plain text: save it as UTF-8.")
    header, table_lines, line_numbers = {}, [], []
    for number, line in enumerate(text.splitlines(), start=1):
        if line.startswith("#"):
            match = _HEADER_LINE.match(line)
            if match:
                key = match.group(1)
                if key in header:
                    _fail(where, f"line {number}: header key {key} given twice.")
                header[key] = _parse_value(key, match.group(2), f"{where}:{number}")
            continue
        if line.strip():
            table_lines.append(line)
            line_numbers.append(number)
    if "format" not in header:
        _fail(where, f"not a trace file: no '# format = {FORMAT}' header line.")
    if not table_lines:
        _fail(where, "no table: expected a 'time_s,...' column line and data rows.")
    if ";" in table_lines[0] and "," not in table_lines[0]:
        _fail(where, f"line {line_numbers[0]}: the columns are separated by ';'; a trace file separates them "
                     "by ',' and writes decimals with '.' (time_s,contact_5,...).")
    columns = [name.strip() for name in table_lines[0].split(",")]
    if columns[0] != "time_s":
        _fail(where, f"the first column must be time_s, got {columns[0]!r}.")
    if len(set(columns)) != len(columns):
        _fail(where, f"a column name appears twice: {columns}.")
    for number, line in zip(line_numbers[1:], table_lines[1:]):
        cells = line.count(",") + 1
        if cells != len(columns):
            decimal = " (is ',' the decimal point? write decimals with '.')" if cells > len(columns) else ""
            _fail(where, f"line {number} has {cells} values for the {len(columns)} columns "
                         f"{','.join(columns)}{decimal}; every row holds one value per column.")
    try:
        data = np.genfromtxt(io.StringIO("\n".join(table_lines[1:])), delimiter=",", dtype=float, ndmin=2)
    except ValueError as error:
        _fail(where, f"the table is not numeric CSV with {len(columns)} columns ({error}).")
    if data.size == 0:
        _fail(where, "the table has no data rows.")
    if data.shape[1] != len(columns):
        _fail(where, f"rows have {data.shape[1]} values for {len(columns)} columns.")
    channels = {name: data[:, i] for i, name in enumerate(columns[1:], start=1)}
    return TraceFile(header=header, time_s=data[:, 0], channels=channels, path=where)


def _format_value(value) -> str:
    if isinstance(value, float):
        return repr(value) if math.isfinite(value) else ("inf" if value > 0 else "nan")
    return str(value)


def format_trace(trace: TraceFile) -> str:
    """The text of a trace file (header in a fixed key order, then the table)."""
    keys = [k for k in HEADER_KEYS if k in trace.header]
    keys += [k for k in trace.header if k not in HEADER_KEYS and not k.startswith("x_")]
    keys += sorted(k for k in trace.header if k.startswith("x_"))
    lines = [f"# {key} = {_format_value(trace.header[key])}" for key in keys]
    lines.append(f"# {UNITS_LINE}")
    names = list(trace.channels)
    lines.append(",".join(["time_s"] + names))
    table = np.column_stack([trace.time_s] + [trace.channels[name] for name in names])
    buffer = io.StringIO()
    np.savetxt(buffer, table, delimiter=",", fmt="%.9g")
    return "\n".join(lines) + "\n" + buffer.getvalue()


def write_trace(path, trace: TraceFile) -> None:
    """Write a trace file atomically (whole or not at all)."""
    write_text(path, format_trace(trace))


def setup_header(setup: ChainSetup) -> dict:
    """Header keys describing a (non-batched) `ChainSetup` with identical beads.

    Raises `ValueError` for heterogeneous beads, which the format cannot describe.
    """
    def scalar(array, name):
        values = np.asarray(array, dtype=float).ravel()
        if np.ptp(values) > 1e-12 * np.max(np.abs(values)):
            raise ValueError(f"{name} varies along the chain; the trace format describes identical beads.")
        return float(values[0])

    header = {
        "format": FORMAT,
        "n_beads": setup.n_beads,
        "bead_radius_m": scalar(setup.bead_radius_m, "bead_radius_m"),
        "bead_density_kg_m3": scalar(setup.bead_density_kg_m3, "bead_density_kg_m3"),
        "bead_youngs_pa": scalar(setup.bead_youngs_pa, "bead_youngs_pa"),
        "bead_poisson": scalar(setup.bead_poisson, "bead_poisson"),
        "wall_youngs_pa": float(setup.wall_youngs_pa),
        "wall_poisson": float(setup.wall_poisson),
        "striker_mass_kg": float(setup.striker_mass_kg),
        "striker_velocity_m_s": float(setup.striker_velocity_m_s),
    }
    bead = {
        "striker_density_kg_m3": header["bead_density_kg_m3"],
        "striker_youngs_pa": header["bead_youngs_pa"],
        "striker_poisson": header["bead_poisson"],
    }
    for key, bead_value in bead.items():
        value = float(getattr(setup, key))
        if abs(value - bead_value) > 1e-12 * abs(bead_value):
            header[key] = value
    if float(setup.precompression_n) > 0:
        header["precompression_n"] = float(setup.precompression_n)
    if setup.sensor_beads:
        header["sensor_beta"] = float(setup.sensor_beta)
        header["sensor_f0_hz"] = float(setup.sensor_f0_hz)
    if setup.end != "wall":
        header["end"] = setup.end
    return header
