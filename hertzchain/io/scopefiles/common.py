"""What every scope-file reader shares: the formats' names, unit tables, the `Waveforms`
record, `ScopeFileError`, and the checks each reader applies to what it read."""

from __future__ import annotations

import dataclasses
import math
import re
from pathlib import Path

import numpy as np

FORMATS: dict[str, str] = {
    "tek-csv": "Tektronix TDS1000/TDS2000-series CSV: settings in columns 1-2, time and value in columns 4-5",
    "rigol-csv": "Rigol DS1000Z CSV: 'X,CH1,...,Start,Increment,' then 'Sequence,Volt,...' and sample indices",
    "keysight-csv": "Keysight InfiniiVision CSV ('x-axis,1,2' / 'second,Volt,Volt') or Infiniium CSV (header rows, then Data)",
    "lecroy-csv": "LeCroy spreadsheet ASCII: 'LECROY...' header, Segments, then 'Time,Ampl' rows",
    "pico-csv": "PicoScope 6/7 CSV: 'Time,Channel A,...' then a units row '(ms),(mV),...'",
    "csv": "generic CSV: a header row of names with units, e.g. 'time (ms), CH1 (mV)'; first column is time",
    "npz": "NumPy .npz: time_s (or t/time) in s and one 1-D array per channel in V; <name>_range_v optional",
    "mat": "MATLAB .mat v4-v7 (not v7.3): names as for npz, or t/time with y/ch1/... vectors",
    "tek-isf": "Tektronix .isf binary (:WFMPRE:...;:CURVE #<n><len><data>), read with isfreader",
    "rigol-wfm": "Rigol .wfm binary, read with RigolWFM",
}

TIME_UNITS_S = {"s": 1.0, "ms": 1e-3, "us": 1e-6, "µs": 1e-6, "μs": 1e-6, "ns": 1e-9}
VOLTAGE_UNITS_V = {"V": 1.0, "mV": 1e-3, "uV": 1e-6, "µV": 1e-6, "μV": 1e-6, "kV": 1e3}
TIME_NAMES = ("time_s", "t", "time")
# Unit words of Rigol and Keysight exports, as the unit symbols of the tables above.
UNIT_WORDS = {"Volt": "V", "volt": "V", "Second": "s", "second": "s"}
# TDS1000/2000: 8-bit codes, 25 codes per vertical division (Programmer Manual 071-1075).
TDS_CODES_PER_DIVISION = 25
TDS_CODE_RANGE = (-128, 127)


class ScopeFileError(ValueError):
    """A scope file that cannot be read; the message names the file, where, and the fix."""


@dataclasses.dataclass(frozen=True)
class Waveforms:
    """One record of one or more channels on a shared time grid.

    `time_s`: (n,) s as the file gives them (scopes: 0 = trigger, negative = pre-trigger).
    `channels`: source name (e.g. "CH1") -> (n,) V. `range_v`: the digitiser's (low, high)
    limits in V where the file states them, else None. `lsb_v`: the quantisation step in V
    where known, else None. `info`: the file's settings as text, for provenance."""

    path: str
    format: str
    time_s: np.ndarray
    channels: dict[str, np.ndarray]
    range_v: dict[str, tuple[float, float] | None]
    lsb_v: dict[str, float | None]
    info: dict[str, str]


def _formats_text() -> str:
    return "; ".join(f"{name} ({text})" for name, text in FORMATS.items())


def _stem_channel_name(path: Path) -> str:
    """The channel named by a file stem: its trailing CH<n>/MATH/REF<x>, else the stem."""
    match = re.search(r"(CH\d+|MATH|REF[A-Z0-9])$", path.stem, flags=re.IGNORECASE)
    return match.group(1).upper() if match else path.stem


def _check_file(path: Path) -> None:
    if not path.is_file():
        raise ScopeFileError(f"{path}: no such file; check the path (relative paths are taken from "
                             f"the current directory or the experiment file's folder).")
    if path.stat().st_size == 0:
        raise ScopeFileError(f"{path}: the file is empty; save the record from the scope again.")


# --- shared checks ------------------------------------------------------------------------

def _check_time(path: Path, time_s: np.ndarray, rows=None, what: str = "row") -> None:
    """Time finite and strictly increasing; `rows[k]` is sample k's row in the file."""
    if time_s.size == 0:
        raise ScopeFileError(f"{path}: no samples; the file holds no data rows.")
    bad = np.flatnonzero(~np.isfinite(time_s))
    if bad.size:
        k = int(bad[0])
        raise ScopeFileError(f"{path}: {what} {rows[k] if rows else k}: time is {float(time_s[k])}; "
                             f"every sample needs a finite time.")
    step = np.diff(time_s)
    bad = np.flatnonzero(step <= 0)
    if bad.size:
        k = int(bad[0]) + 1
        raise ScopeFileError(f"{path}: {what} {rows[k] if rows else k}: time {float(time_s[k])!r} s does not "
                             f"increase (previous {float(time_s[k - 1])!r} s); time must be strictly increasing "
                             f"(a file with records appended, or a sorted/edited copy?).")


def _check_values(path: Path, name: str, values: np.ndarray, n: int, what: str = "sample") -> None:
    if values.shape != (n,):
        raise ScopeFileError(f"{path}: channel {name!r} has {values.size} values and time has {n}; "
                             f"time and value columns must have the same length.")
    bad = np.flatnonzero(~np.isfinite(values))
    if bad.size:
        raise ScopeFileError(f"{path}: {what} {int(bad[0])}: channel {name!r} is {float(values[bad[0]])}; "
                             f"every value must be a finite number.")


def _decode(path: Path) -> str:
    data = path.read_bytes()
    try:
        text = data.decode("utf-8-sig")
    except UnicodeDecodeError:
        text = data.decode("latin-1")
    return text.replace("\r\n", "\n").replace("\r", "\n")


def _number(path: Path, row: int, column: str, text: str) -> float:
    cell = text.strip()
    if not cell:
        raise ScopeFileError(f"{path}: row {row}, column {column}: empty cell; every data row needs "
                             f"a number in every column.")
    try:
        value = float(cell)
    except ValueError:
        raise ScopeFileError(f"{path}: row {row}, column {column}: {cell!r} is not a number.") from None
    if not math.isfinite(value):
        raise ScopeFileError(f"{path}: row {row}, column {column}: {cell!r}; values must be finite "
                             f"(a gap in the record? cut the file before it).")
    return value


def _unit_factor(path: Path, where: str, unit: str, table: dict[str, float]) -> float:
    unit = UNIT_WORDS.get(unit, unit)
    if unit not in table:
        raise ScopeFileError(f"{path}: {where}: unknown unit {unit!r}; known units: "
                             f"{', '.join(table)}.")
    return table[unit]
