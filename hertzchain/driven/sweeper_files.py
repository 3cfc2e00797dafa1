"""The files a lock-in sweeper writes, read as they are; units converted at the edge.

Three kinds of file come out of a lock-in amplifier's sweeper (Zurich Instruments HF2LI as
used by Lydon et al.):

- **sweeper text files** (`read_sweeper_table`): tab-separated; the first line is the label of
  the row variable with its unit in brackets (`Frequency (Hz)`, `Reference Amplitude (V)`),
  then the column values, each with its unit (`6300Hz`, `0.001V`); each next line is the row
  value, then one number per column. The file name is `<run> <quantity><date>.txt`, e.g.
  `SingleBead_Bending Signal Amplitude_02013Jul3_10h29m15s.txt`: the quantity (`Signal
  Amplitude_0`: the lock-in R at the drive frequency, V RMS) is read from it.
- **scope files** (`read_scope_shots`): tab-separated, no header; column 1 the time (s) from
  the trigger, then one record (V) per step of the sweep.
- **MATLAB files** (`read_mat_variables`): the lab's processed arrays (scipy.io).

A table keeps the instrument's units (V, rad); `lockin_sweep` turns an amplitude table into a
`LockinSweep` in SI: the drive's lock-in output volts times the drive calibration (m/V) give
the piezo amplitude, the vibrometer's volts times its calibration ((m/s)/V) the bead's RMS
velocity. Every problem raises `SweeperFileError` naming the file, the line and the fix.
"""

from __future__ import annotations

import dataclasses
import re
from pathlib import Path

import numpy as np

from ..units import parse_quantity


class SweeperFileError(ValueError):
    """A lock-in or scope file that cannot be read; the message names the file, where, and the fix."""


# `<run> <quantity><date>.txt`: the date as the HF2LI writes it (2013Jul3_10h29m15s).
_NAME = re.compile(r"^(?P<run>\S+) (?P<quantity>.+?)(?P<date>\d{4}[A-Z][a-z]{2}\d{1,2}_\d{1,2}h\d{1,2}m\d{1,2}s)$")
_LABEL = re.compile(r"^(?P<name>.*?)\s*\((?P<unit>[^()]*)\)\s*$")
_AXIS_UNITS = ("Hz", "V", "s")


@dataclasses.dataclass(frozen=True)
class SweeperTable:
    """One sweeper text file as it is.

    **Fields:** `path`; `run`, `quantity`, `date` (from the file name; `quantity` is the
    whole stem when the name does not follow the sweeper's pattern); `row_name`, `row_unit`
    (`"Frequency"`, `"Hz"`: the SI unit, whatever prefix the file wrote); `row_values` (R,) in
    that unit (Hz, V, s); `column_unit`
    and `column_values` (C,) likewise; `values` (R, C) in the instrument's unit of the
    quantity (V for amplitudes, rad for phases), NaN where the file leaves a cell empty.
    """

    path: Path
    run: str
    quantity: str
    date: str
    row_name: str
    row_unit: str
    row_values: np.ndarray
    column_unit: str
    column_values: np.ndarray
    values: np.ndarray


@dataclasses.dataclass(frozen=True)
class ScopeShots:
    """A scope file: `time_s` (N,) from the trigger and `signals_v` (N, K), one record per step."""

    path: Path
    time_s: np.ndarray
    signals_v: np.ndarray


@dataclasses.dataclass(frozen=True)
class LockinSweep:
    """A lock-in frequency x drive sweep in SI units.

    **Fields:** `frequencies_hz` (F,); `drive_amplitudes_m` (A,) the piezo's displacement
    amplitude (nominal: the lock-in output volts times `drive_m_per_v`); `rms_velocity_m_s`
    (F, A) the bead's velocity, RMS at the drive frequency; `drive_m_per_v`,
    `sensor_m_s_per_v` the calibrations used; `source` the file it came from.
    """

    frequencies_hz: np.ndarray
    drive_amplitudes_m: np.ndarray
    rms_velocity_m_s: np.ndarray
    drive_m_per_v: float
    sensor_m_s_per_v: float
    source: str


def _text(path: Path) -> str:
    if not path.is_file():
        raise SweeperFileError(f"{path}: no such file; check the path (and --data-dir).")
    try:
        return path.read_text(encoding="utf-8-sig")
    except UnicodeDecodeError:
        return path.read_text(encoding="latin-1")


def _number(path: Path, line: int, column: int, text: str) -> float:
    try:
        return float(text)
    except ValueError:
        raise SweeperFileError(
            f"{path}: line {line}, column {column}: {text!r} is not a number; a sweeper file holds "
            "one number per tab-separated cell after the header line."
        ) from None


def _axis_value(path: Path, column: int, text: str) -> tuple[float, str]:
    match = re.match(r"^\s*([-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)\s*([a-zA-Zµ]*)\s*$", text)
    if not match:
        raise SweeperFileError(
            f"{path}: line 1, column {column}: {text!r} is not a value with a unit (e.g. 6300Hz, 0.001V)."
        )
    suffix = match.group(2)
    for unit in _AXIS_UNITS:
        if suffix.endswith(unit):
            return parse_quantity(text.strip(), unit, name=f"{path} line 1 column {column}"), unit
    raise SweeperFileError(
        f"{path}: line 1, column {column}: unit of {text!r} is not one of {', '.join(_AXIS_UNITS)} "
        "(with an SI prefix); write the column values as e.g. 6300Hz or 0.001V."
    )


def _cells(line: str) -> list[str]:
    cells = line.rstrip("\r\n").split("\t")
    while cells and not cells[-1].strip():  # the HF2LI ends every line with a tab
        cells.pop()
    return cells


def read_sweeper_table(path) -> SweeperTable:
    """Read a lock-in sweeper text file (see the module docstring) as it is.

    **Raises:** `SweeperFileError` for a missing file, a header without units, a cell that
    is not a number, a line with more cells than the header has columns, or no data lines.
    """
    path = Path(path)
    lines = [line for line in _text(path).splitlines() if line.strip()]
    if not lines:
        raise SweeperFileError(f"{path}: the file is empty; a sweeper file starts with a header line.")
    header = _cells(lines[0])
    label = _LABEL.match(header[0])
    row_unit = next((u for u in _AXIS_UNITS if label and label.group("unit").endswith(u)), None)
    try:
        row_factor = parse_quantity(f"1{label.group('unit')}", row_unit) if row_unit else None
    except ValueError:
        row_factor = None
    if row_factor is None:
        raise SweeperFileError(
            f"{path}: line 1: the row label {header[0]!r} does not name its unit in brackets as one of "
            f"{', '.join(_AXIS_UNITS)}, SI prefixes allowed (e.g. 'Frequency (Hz)'); is this a sweeper text file?"
        )
    if len(header) < 2:
        raise SweeperFileError(f"{path}: line 1 has no column values after the row label {header[0]!r}.")
    parsed = [_axis_value(path, k + 2, text) for k, text in enumerate(header[1:])]
    column_units = {unit for _, unit in parsed}
    if len(column_units) != 1:
        raise SweeperFileError(f"{path}: line 1: the column values mix units ({', '.join(sorted(column_units))}).")
    n_columns = len(parsed)
    rows, values = [], []
    for number, line in enumerate(lines[1:], start=2):
        cells = _cells(line)
        if len(cells) > n_columns + 1:
            raise SweeperFileError(
                f"{path}: line {number} has {len(cells) - 1} values but the header names {n_columns} columns."
            )
        rows.append(_number(path, number, 1, cells[0]) * row_factor)
        row = [np.nan] * n_columns
        for k, text in enumerate(cells[1:]):
            if text.strip():
                row[k] = _number(path, number, k + 2, text)
        values.append(row)
    if not rows:
        raise SweeperFileError(f"{path}: no data lines after the header.")
    name = _NAME.match(path.stem)
    return SweeperTable(
        path=path,
        run=name.group("run") if name else "",
        quantity=name.group("quantity") if name else path.stem,
        date=name.group("date") if name else "",
        row_name=label.group("name"),
        row_unit=row_unit,
        row_values=np.asarray(rows, dtype=float),
        column_unit=column_units.pop(),
        column_values=np.asarray([value for value, _ in parsed]),
        values=np.asarray(values, dtype=float),
    )


def read_scope_shots(path) -> ScopeShots:
    """Read a scope file (`.txt.txt`): time (s) in column 1, one record (V) per further column.

    **Raises:** `SweeperFileError` for a missing file, a non-number, ragged lines, fewer than
    two columns, or times that do not increase.
    """
    path = Path(path)
    rows = []
    width = None
    for number, line in enumerate(_text(path).splitlines(), start=1):
        if not line.strip():
            continue
        cells = _cells(line)
        if width is None:
            width = len(cells)
            if width < 2:
                raise SweeperFileError(f"{path}: line {number}: a scope file needs a time column and at least one record.")
        if len(cells) != width:
            raise SweeperFileError(f"{path}: line {number} has {len(cells)} columns, the first line {width}.")
        rows.append([_number(path, number, k + 1, text) for k, text in enumerate(cells)])
    if not rows:
        raise SweeperFileError(f"{path}: the file is empty.")
    table = np.asarray(rows, dtype=float)
    if np.any(np.diff(table[:, 0]) <= 0):
        first = int(np.argmax(np.diff(table[:, 0]) <= 0)) + 2
        raise SweeperFileError(f"{path}: the time (column 1) does not increase at row {first}; is column 1 the time?")
    return ScopeShots(path=path, time_s=table[:, 0], signals_v=table[:, 1:])


def read_mat_variables(path, names) -> dict[str, np.ndarray]:
    """The arrays `names` of a MATLAB file, as float64 and squeezed.

    **Raises:** `SweeperFileError` naming the missing variables and the ones the file has.
    """
    import scipy.io

    path = Path(path)
    if not path.is_file():
        raise SweeperFileError(f"{path}: no such file; check the path (and --data-dir).")
    try:
        content = scipy.io.loadmat(path)
    except (ValueError, OSError, NotImplementedError) as error:
        raise SweeperFileError(f"{path}: not a MATLAB file scipy.io can read ({error}).") from None
    present = sorted(k for k in content if not k.startswith("__"))
    missing = [name for name in names if name not in content]
    if missing:
        raise SweeperFileError(f"{path}: no variable {', '.join(missing)}; the file holds {', '.join(present)}.")
    return {name: np.asarray(content[name], dtype=float).squeeze() for name in names}


def lockin_sweep(table: SweeperTable, *, drive_m_per_v: float, sensor_m_s_per_v: float) -> LockinSweep:
    """A frequency x drive sweep in SI from an amplitude table (lock-in R, V RMS).

    The table's frequency axis (unit Hz) may be its rows or its columns; the other axis is
    the lock-in's output amplitude (V), times `drive_m_per_v` (m/V) the piezo's amplitude;
    the values times `sensor_m_s_per_v` ((m/s)/V; 21.25 (mm/s)/V is 0.02125) the bead's RMS
    velocity.

    **Raises:** `SweeperFileError` when the table has no frequency axis and drive-volt axis,
    or a calibration is not positive.
    """
    for name, value in (("drive_m_per_v", drive_m_per_v), ("sensor_m_s_per_v", sensor_m_s_per_v)):
        if not (np.isfinite(value) and value > 0):
            raise SweeperFileError(f"{table.path}: {name} = {value!r} must be a positive calibration.")
    if (table.row_unit, table.column_unit) == ("Hz", "V"):
        frequencies, volts, values = table.row_values, table.column_values, table.values
    elif (table.row_unit, table.column_unit) == ("V", "Hz"):
        frequencies, volts, values = table.column_values, table.row_values, table.values.T
    else:
        raise SweeperFileError(
            f"{table.path}: a frequency x drive sweep needs one axis in Hz and one in V; this table has "
            f"rows in {table.row_unit} and columns in {table.column_unit}."
        )
    if np.any(np.isnan(values)):
        raise SweeperFileError(f"{table.path}: {int(np.sum(np.isnan(values)))} empty cells in the sweep.")
    return LockinSweep(
        frequencies_hz=np.asarray(frequencies, dtype=float),
        drive_amplitudes_m=np.asarray(volts, dtype=float) * drive_m_per_v,
        rms_velocity_m_s=np.asarray(values, dtype=float) * sensor_m_s_per_v,
        drive_m_per_v=float(drive_m_per_v),
        sensor_m_s_per_v=float(sensor_m_s_per_v),
        source=str(table.path),
    )
