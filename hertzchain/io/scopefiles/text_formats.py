"""Readers of the text (CSV) scope formats: Tektronix, the generic CSV, and the tables of rows
written by Rigol, Keysight, LeCroy and PicoScope; `csv_layout` tells them apart."""

from __future__ import annotations

import csv
import io
import re
from pathlib import Path

import numpy as np

from .common import (
    TDS_CODE_RANGE,
    TDS_CODES_PER_DIVISION,
    TIME_UNITS_S,
    UNIT_WORDS,
    VOLTAGE_UNITS_V,
    ScopeFileError,
    Waveforms,
    _check_time,
    _decode,
    _number,
    _stem_channel_name,
    _unit_factor,
)


def _csv_layout(text: str) -> str:
    """The CSV format a file's first two non-blank rows show (see the module docstring)."""
    rows = [next(csv.reader([line])) for line in text.split("\n")[:40] if line.strip()][:2]
    first = [c.strip().strip('"').strip() for c in rows[0]] if rows else [""]
    second = [c.strip() for c in rows[1]] if len(rows) > 1 else []
    head = first[0].lower()
    if head == "record length":
        return "tek-csv"
    if head == "x" and "Start" in first and "Increment" in first:
        return "rigol-csv"
    if head == "x-axis" or head == "revision":
        return "keysight-csv"
    if head.startswith("lecroy"):
        return "lecroy-csv"
    if head == "time" and second and all(re.fullmatch(r"\(.*\)", c) for c in second if c):
        return "pico-csv"
    return "csv"


# --- tek-csv ------------------------------------------------------------------------------

def _read_tek_csv(path: Path) -> Waveforms:
    rows = list(csv.reader(io.StringIO(_decode(path))))
    info: dict[str, str] = {}
    info_rows: dict[str, int] = {}
    times, values, file_rows = [], [], []
    for number, row in enumerate(rows, start=1):
        cells = [c.strip() for c in row]
        while cells and not cells[-1] and len(cells) > 6:
            cells.pop()
        if not any(cells):
            continue
        if cells[0]:
            info[cells[0]] = cells[1] if len(cells) > 1 else ""
            info_rows[cells[0]] = number
        if len(cells) < 5:
            raise ScopeFileError(f"{path}: row {number} has {len(cells)} columns; a Tektronix TDS CSV row "
                                 f"has 6, with time in column 4 and the value in column 5 (is this a "
                                 f"generic CSV? use format 'csv').")
        times.append(_number(path, number, "4 (time)", cells[3]))
        values.append(_number(path, number, "5 (value)", cells[4]))
        file_rows.append(number)
    if not times:
        raise ScopeFileError(f"{path}: no data rows; the file holds settings only.")
    time_s = np.asarray(times, dtype=np.float64)
    volts = np.asarray(values, dtype=np.float64)
    horizontal = info.get("Horizontal Units", "s")
    time_s *= _unit_factor(path, f"Horizontal Units {horizontal!r}", horizontal, TIME_UNITS_S)
    vertical = info.get("Vertical Units", "V")
    to_volts = _unit_factor(path, f"Vertical Units {vertical!r} (the reader takes voltage records)",
                            vertical, VOLTAGE_UNITS_V)
    volts *= to_volts
    _check_time(path, time_s, file_rows)
    if "Record Length" in info:
        stated = _number(path, info_rows["Record Length"], "2 (Record Length)", info["Record Length"])
        if stated != len(times):
            raise ScopeFileError(f"{path}: Record Length says {stated:g} points but the file has "
                                 f"{len(times)} data rows; the file is truncated or edited.")
    name = info.get("Source") or _stem_channel_name(path)
    lsb, limits = None, None
    if "Vertical Scale" in info:
        scale = _number(path, info_rows["Vertical Scale"], "2 (Vertical Scale)", info["Vertical Scale"])
        lsb = scale * to_volts / TDS_CODES_PER_DIVISION
    if lsb is not None and "Vertical Offset" in info:
        offset = to_volts * _number(path, info_rows["Vertical Offset"], "2 (Vertical Offset)",
                                    info["Vertical Offset"])
        low, high = (TDS_CODE_RANGE[0] * lsb - offset, TDS_CODE_RANGE[1] * lsb - offset)
        if np.all((volts >= low - lsb / 2) & (volts <= high + lsb / 2)):
            limits = (float(low), float(high))
        else:
            info["range_v"] = (f"not given: samples lie outside ({low!r}, {high!r}) V, the range that "
                               f"Vertical Scale and Vertical Offset imply; state range_v for this channel")
    return Waveforms(str(path), "tek-csv", time_s, {name: volts}, {name: limits}, {name: lsb}, info)


# --- generic csv --------------------------------------------------------------------------

_BRACKETED = re.compile(r"^(.*?)\s*[\(\[]\s*([^\)\]]*?)\s*[\)\]]\s*$")


def _column(path: Path, header: str, is_time: bool) -> tuple[str, float]:
    """(name, factor to s or V) of a header cell."""
    table = TIME_UNITS_S if is_time else VOLTAGE_UNITS_V
    other = VOLTAGE_UNITS_V if is_time else TIME_UNITS_S
    match = _BRACKETED.match(header)
    if match:
        name, unit = match.group(1), match.group(2)
    elif "_" in header and (header.rsplit("_", 1)[1] in table or header.rsplit("_", 1)[1] in other):
        name, unit = header.rsplit("_", 1)
    else:
        name, unit = header, "s" if is_time else "V"
    kind = "time (first column)" if is_time else "a channel"
    if unit in other:
        raise ScopeFileError(f"{path}: header column {header!r} is {kind} but has the unit {unit!r}; "
                             f"the first column is time, the others volts.")
    factor = _unit_factor(path, f"header column {header!r}", unit, table)
    if not name:
        raise ScopeFileError(f"{path}: header column {header!r} has no name.")
    return name, factor


def _read_csv(path: Path) -> Waveforms:
    rows = [(number, cells) for number, cells in _csv_rows(path) if not cells[0].startswith("#")]
    if not rows:
        raise ScopeFileError(f"{path}: no header row; the file holds only comments or blank lines.")
    header_row, headers = rows[0][0], _trimmed(rows[0][1])
    if len(headers) < 2:
        raise ScopeFileError(f"{path}: row {header_row}: the header names {len(headers)} column(s); give "
                             f"time and at least one channel, e.g. 'time (ms), CH1 (mV)'.")
    columns = [_column(path, h, k == 0) for k, h in enumerate(headers)]
    table, numbers = _numeric_table(path, rows[1:], headers)
    return _table_waveforms(path, "csv", table[:, 0] * columns[0][1], numbers, [n for n, _ in columns[1:]],
                            table[:, 1:], [f for _, f in columns[1:]], {"columns": ", ".join(headers)})


# --- tables of rows (csv, rigol-csv, keysight-csv, lecroy-csv, pico-csv) ------------------

def _csv_rows(path: Path) -> list[tuple[int, list[str]]]:
    """(file row number, stripped cells) of every row with a non-empty cell."""
    rows = []
    for number, row in enumerate(csv.reader(io.StringIO(_decode(path))), start=1):
        cells = [c.strip() for c in row]
        if any(cells):
            rows.append((number, cells))
    return rows


def _trimmed(cells: list[str]) -> list[str]:
    """`cells` without trailing empty ones (Rigol ends every row with a comma)."""
    cells = list(cells)
    while cells and not cells[-1]:
        cells.pop()
    return cells


def _header_rows(path: Path, layout: str):
    """The rows of a CSV whose first two rows name the columns and give their units:
    (rows, (row number, names), (row number, units)), with trailing empty cells dropped."""
    rows = _csv_rows(path)
    if len(rows) < 3:
        raise ScopeFileError(f"{path}: a {layout} CSV needs a names row, a units row and data rows; "
                             f"the file has {len(rows)} rows.")
    (header_row, header), (units_row, units) = [(n, _trimmed(c)) for n, c in rows[:2]]
    return rows, (header_row, header), (units_row, units)


def _numeric_table(path: Path, rows, names: list[str]) -> tuple[np.ndarray, list[int]]:
    """(n, len(names)) floats from data rows, each with exactly one cell per name."""
    data, numbers = [], []
    for number, cells in rows:
        cells = list(cells)
        while len(cells) > len(names) and not cells[-1]:
            cells.pop()
        if len(cells) != len(names):
            raise ScopeFileError(f"{path}: row {number} has {len(cells)} cells and the header {len(names)} "
                                 f"({', '.join(names)}); every data row needs a value in every column.")
        data.append([_number(path, number, f"{k + 1} ({names[k]})", c) for k, c in enumerate(cells)])
        numbers.append(number)
    if not data:
        raise ScopeFileError(f"{path}: a header but no data rows.")
    return np.asarray(data, dtype=np.float64), numbers


def _table_waveforms(path: Path, format: str, time_s, file_rows, names, table, factors, info) -> Waveforms:
    """Waveforms of a CSV table whose channel columns `table[:, k]` are in volts x `factors[k]`."""
    _check_time(path, time_s, file_rows)
    for name in names:
        if names.count(name) > 1:
            raise ScopeFileError(f"{path}: channel {name!r} is named twice in the header.")
    channels = {name: table[:, k] * factors[k] for k, name in enumerate(names)}
    return Waveforms(str(path), format, time_s, channels, dict.fromkeys(names), dict.fromkeys(names), info)


def _read_rigol_csv(path: Path) -> Waveforms:
    rows, (header_row, header), (units_row, units) = _header_rows(path, "Rigol")
    if "Start" not in header or "Increment" not in header or header[0] != "X":
        raise ScopeFileError(f"{path}: row {header_row}: a Rigol CSV header reads 'X,CH1,...,Start,Increment,'; "
                             f"got {','.join(header)!r} (use format 'csv' for a generic CSV).")
    start_at, increment_at = header.index("Start"), header.index("Increment")
    names = header[1:min(start_at, increment_at)]
    if not names:
        raise ScopeFileError(f"{path}: row {header_row}: no channel columns between X and Start.")
    if len(units) <= max(start_at, increment_at):
        raise ScopeFileError(f"{path}: row {units_row}: the units row must give Start and Increment "
                             f"under their header columns (e.g. 'Sequence,Volt,-6.0e-03,2.0e-06,').")
    start = _number(path, units_row, f"{start_at + 1} (Start)", units[start_at])
    increment = _number(path, units_row, f"{increment_at + 1} (Increment)", units[increment_at])
    if not increment > 0:
        raise ScopeFileError(f"{path}: row {units_row}: Increment is {increment!r}; it is the sample "
                             f"interval in s and must be positive.")
    factors = [_unit_factor(path, f"row {units_row}, column {k + 2} ({n})", units[k + 1], VOLTAGE_UNITS_V)
               for k, n in enumerate(names)]
    x_unit = units[0]
    if x_unit != "Sequence" and UNIT_WORDS.get(x_unit, x_unit) not in TIME_UNITS_S:
        raise ScopeFileError(f"{path}: row {units_row}, column 1 (X): {x_unit!r}; expected 'Sequence' "
                             f"(sample indices) or a time unit ({', '.join(TIME_UNITS_S)}).")
    table, numbers = _numeric_table(path, [(n, c[:len(names) + 1]) for n, c in rows[2:]], ["X", *names])
    if x_unit == "Sequence":
        time_s = start + table[:, 0] * increment
    else:
        time_s = table[:, 0] * _unit_factor(path, f"row {units_row}, column 1 (X)", x_unit, TIME_UNITS_S)
    info = {"columns": ",".join(header), "units": ",".join(units[:len(names) + 1]),
            "start_s": repr(start), "increment_s": repr(increment)}
    return _table_waveforms(path, "rigol-csv", time_s, numbers, names, table[:, 1:], factors, info)


def _keysight_name(source: str) -> str:
    return f"CH{source}" if source.isdigit() else source


def _read_keysight_csv(path: Path) -> Waveforms:
    rows = _csv_rows(path)
    if rows and rows[0][1][0].lower() == "revision":
        return _read_infiniium_csv(path, rows)
    rows, (_, header), (units_row, units) = _header_rows(path, "Keysight InfiniiVision")
    if len(units) != len(header):
        raise ScopeFileError(f"{path}: row {units_row} gives {len(units)} units for {len(header)} columns.")
    names = [_keysight_name(h) for h in header[1:]]
    time_factor = _unit_factor(path, f"row {units_row}, column 1 (x-axis)", units[0], TIME_UNITS_S)
    factors = [_unit_factor(path, f"row {units_row}, column {k + 2} ({n})", units[k + 1], VOLTAGE_UNITS_V)
               for k, n in enumerate(names)]
    table, numbers = _numeric_table(path, rows[2:], [header[0], *names])
    info = {"sources": ",".join(header), "units": ",".join(units)}
    return _table_waveforms(path, "keysight-csv", table[:, 0] * time_factor, numbers, names,
                             table[:, 1:], factors, info)


def _read_infiniium_csv(path: Path, rows) -> Waveforms:
    data_at = next((k for k, (_, cells) in enumerate(rows) if cells[0].lower() == "data"), None)
    if data_at is None:
        raise ScopeFileError(f"{path}: an Infiniium CSV header (Revision, ..., XInc, XOrg) must end with a "
                             f"'Data' row before the samples; none found.")
    settings = {cells[0]: _trimmed(cells[1:]) for _, cells in rows[:data_at]}
    where = {cells[0]: number for number, cells in rows[:data_at]}
    for key in ("XInc", "XOrg"):
        if key not in settings or not settings[key]:
            raise ScopeFileError(f"{path}: the Infiniium header has no {key} row; it is needed for the "
                                 f"time axis (time = XOrg + k x XInc).")
    n_sources = len(settings["XInc"])
    x_unit = (settings.get("XUnits") or ["Second"])[0]
    time_factor = _unit_factor(path, f"XUnits {x_unit!r}", x_unit, TIME_UNITS_S)
    y_units = settings.get("YUnits") or ["Volt"] * n_sources
    factors = [_unit_factor(path, f"YUnits {u!r}", u, VOLTAGE_UNITS_V) for u in y_units[:n_sources]]
    increment = _number(path, where["XInc"], "2 (XInc)", settings["XInc"][0]) * time_factor
    origin = _number(path, where["XOrg"], "2 (XOrg)", settings["XOrg"][0]) * time_factor
    if not increment > 0:
        raise ScopeFileError(f"{path}: row {where['XInc']}: XInc is {increment!r}; it must be positive.")
    names = [f"CH{k + 1}" for k in range(n_sources)] if n_sources > 1 else [_stem_channel_name(path)]
    table, numbers = _numeric_table(path, rows[data_at + 1:], names)
    if "Points" in settings:
        stated = _number(path, where["Points"], "2 (Points)", settings["Points"][0])
        if stated != len(numbers):
            raise ScopeFileError(f"{path}: Points says {stated:g} but the file has {len(numbers)} data rows; "
                                 f"the file is truncated or edited.")
    time_s = origin + increment * np.arange(len(numbers))
    info = {key: ",".join(value) for key, value in settings.items()}
    return _table_waveforms(path, "keysight-csv", time_s, numbers, names, table, factors, info)


def _read_lecroy_csv(path: Path) -> Waveforms:
    rows = _csv_rows(path)
    at = next((k for k, (_, cells) in enumerate(rows) if [c.lower() for c in cells[:2]] == ["time", "ampl"]), None)
    if at is None:
        raise ScopeFileError(f"{path}: a LeCroy spreadsheet export has a 'Time,Ampl' row before the samples; "
                             f"none found.")
    settings = {cells[0]: cells for _, cells in rows[:at]}
    segments = settings.get("Segments")
    if segments and len(segments) > 1 and segments[1] not in ("1", "1.0"):
        raise ScopeFileError(f"{path}: {segments[1]} segments; one shot per file is read, save each "
                             f"segment to its own file.")
    header_row, header = rows[at][0], _trimmed(rows[at][1])
    if len(header) != 2:
        raise ScopeFileError(f"{path}: row {header_row}: {','.join(header)!r}; one channel per file "
                             f"(Time,Ampl) is read.")
    match = re.match(r"(C\d+|F\d+|M\d+|Z\d+)", path.stem, flags=re.IGNORECASE)
    name = match.group(1).upper() if match else path.stem
    table, numbers = _numeric_table(path, rows[at + 1:], ["Time", name])
    info = {"instrument": ",".join(rows[0][1]), **{k: ",".join(v[1:]) for k, v in settings.items()}}
    return _table_waveforms(path, "lecroy-csv", table[:, 0], numbers, [name], table[:, 1:], [1.0], info)


def _read_pico_csv(path: Path) -> Waveforms:
    rows, (_, header), (units_row, units) = _header_rows(path, "PicoScope")
    if len(units) != len(header):
        raise ScopeFileError(f"{path}: row {units_row} gives {len(units)} units for {len(header)} columns.")
    bare = [u.strip("()").strip() for u in units]
    time_factor = _unit_factor(path, f"row {units_row}, column 1 ({header[0]})", bare[0], TIME_UNITS_S)
    names = header[1:]
    factors = [_unit_factor(path, f"row {units_row}, column {k + 2} ({n})", bare[k + 1], VOLTAGE_UNITS_V)
               for k, n in enumerate(names)]
    data = rows[2:]
    for number, cells in data:
        for k, cell in enumerate(cells):
            if cell.lstrip("+-") in ("∞", "inf", "Infinity"):
                raise ScopeFileError(f"{path}: row {number}, column {k + 1}: {cell!r}, PicoScope's mark of a "
                                     f"sample beyond the range; record with a larger range or cut the record.")
    table, numbers = _numeric_table(path, data, header)
    info = {"columns": ",".join(header), "units": ",".join(units)}
    return _table_waveforms(path, "pico-csv", table[:, 0] * time_factor, numbers, names, table[:, 1:],
                             factors, info)
