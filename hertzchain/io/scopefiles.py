"""Oscilloscope files read into one in-memory form, `Waveforms` (seconds and volts, float64).

Formats (`FORMATS`; `read_waveforms(path, format="auto")` picks one with `detect_format`):

- ``tek-csv``: the CSV that Tektronix TDS1000/TDS2000-series scopes (and the TBS1000/TPS2000
  that share the layout) write. Every row has 6 columns; the first ~18 rows carry settings
  in columns 1-2 (``Record Length``, ``Sample Interval``, ``Trigger Point``, ``Source``,
  ``Vertical Units``, ``Vertical Scale``, ``Vertical Offset``, ``Horizontal Units``, ...,
  ``Model Number``, ``Firmware Version``); columns 4-5 of every row, settings rows included,
  hold time and value. The channel is named by the ``Source`` row; without one, by the file
  stem: its trailing ``CH<n>``, ``MATH`` or ``REF<x>`` (the scope's own file names end so,
  e.g. ``F0003CH2.CSV`` -> ``CH2``), else the whole stem. Units come from the ``Vertical
  Units`` and ``Horizontal Units`` rows (V, mV, uV, kV; s, ms, us, ns).

  Quantisation and range. The TDS200/1000/2000 Programmer Manual (Tektronix 071-1075,
  "Waveform Data Formats" and ``WFMPre:YMUlt``/``YOFf``) says the scope keeps one signed
  8-bit byte per point (-128..127), that ``value = (code - YOFF) * YMULT + YZERO`` with YOFF,
  the vertical position, in digitizer levels, and its example ``YMULT`` of 40 mV per level at
  1 V/div gives 25 levels per division; the graticule is 8 divisions high (+-100 levels about
  the centre). The CSV holds the converted values, so here ``lsb_v = Vertical Scale / 25``
  and ``range_v = (-128 * lsb_v - offset, 127 * lsb_v - offset)``, where ``offset`` is the
  ``Vertical Offset`` row read as the vertical position in volts (YOFF * YMULT): the limits of
  the digitiser codes (+-5.12 divisions), a little beyond the screen's +-4 divisions. That
  reading of ``Vertical Offset`` is inferred from the programmer manual's conversion, not
  stated by a Tektronix document found for the CSV; as a guard, if any sample lies outside
  the range it implies (by more than half a step), ``range_v`` is None and ``info["range_v"]``
  says why.
- ``csv``: a generic CSV. A header row of column names with units in brackets, parentheses
  or after an underscore (``time (ms), CH1 (mV), wall [V]`` or ``time_s,CH1_V``); the first
  column is time. Time units s, ms, us/µs, ns; value units V, mV, uV/µV, kV. A column without
  a unit is in s (the time column) or V (the others). Lines starting with ``#`` are skipped.
- ``rigol-csv``: the CSV that Rigol DS1000Z/MSO1000Z scopes save (Storage > CSV). The first
  row names the columns, ``X,CH1,CH2,...,Start,Increment,``; the second holds units under the
  channel names (``Sequence,Volt,Volt,...``) and, under ``Start`` and ``Increment``, the
  record's first time and sample interval in s; then one row per sample: the sample index
  and each channel's volts. Time = Start + index x Increment. (Layout: the DS1000Z exports
  reported by a lab in issue 29, and public readers of these files, which take Start and
  Increment from the second row's cells under those names; a file whose X column is in
  ``Second`` holds times instead of indices and is read so.) The CSV states no digitiser
  step or range: ``lsb_v`` is estimated from the values by the importer.
- ``keysight-csv``: Keysight/Agilent CSV. InfiniiVision (2000/3000/4000 X) writes two
  header rows, the sources (``x-axis,1,2``) and their units (``second,Volt,Volt``), then
  time and values per row (the header rows and the per-segment rows are described in the
  InfiniiVision 2000/3000 X-Series User's Guides, "CSV and ASCII XY file structure"; the
  header cells as these scopes write them); channels are named ``CH<n>`` from the source
  numbers. Infiniium writes a
  block of ``key,value`` rows (``Revision``, ``Type``, ``Points``, ``XInc``, ``XOrg``,
  ``XUnits``, ``YUnits``, ..., Infiniium 90000 Programmer's Reference, "CSV and TSV Header
  Format") and then, after a ``Data`` row, one value per row (one column per source);
  time = XOrg + k x XInc.
- ``lecroy-csv``: LeCroy "Spreadsheet" ASCII export (LeCroy 9300C manual, Appendix E,
  "ASCII Waveform Export"; MAUI scopes write the same block): ``LECROY<model>,<serial>``,
  ``Segments,<n>,SegmentSize,<m>``, a ``Segment,TrigTime,...`` table, then ``Time,Ampl``
  and rows of time (s) and volts. One segment is read (a multi-segment file is refused).
  The channel is named from the file stem's leading ``C<n>`` (LeCroy's ``C1--Trace--00000``),
  else the whole stem.
- ``pico-csv``: PicoScope 6/7 CSV export: a row of names (``Time,Channel A,Channel B``), a
  row of units in parentheses (``(ms),(mV),(V)``), an optional blank row, then the samples
  (the layout public readers of these exports check: names ``Time,Channel X...`` and units
  ``(s|ms|µs)``/``(V|mV|µV)``).
  Channels keep PicoScope's names (``Channel A``). A sample PicoScope marks over-range
  (``∞``/``-∞``) is an error naming the row (set a larger range, or cut the record).
- ``npz``: ``numpy.load``. The time array is ``time_s`` (or ``t``/``time``), in seconds;
  every other array that is 1-D after squeezing and has the time's length is a channel in
  volts, named by its key; ``<name>_range_v`` (2 values) gives that channel's range; other
  arrays of one element go to ``info``.
- ``mat``: ``scipy.io.loadmat`` (MATLAB v4-v7; v7.3 files are HDF5 and are refused with the
  fix, ``save(file, ..., '-v7')``). The npz names, plus the Tektronix/LeCroy export style of
  ``t``/``time`` with ``y``/``ch1``/... vectors (row or column vectors): ``ch<n>`` is named
  ``CH<n>``, and a lone ``y`` is named from the file stem as for tek-csv.
- ``tek-isf``: Tektronix ``.isf`` (``:WFMPRE:...;:CURVE #<n><len><binary>``). The header
  and the binary block are split and parsed by the ``isfreader`` package
  (``isfreader.split_isf_header``); its ``parse_isf_data`` calls ``numpy.fromstring`` in
  binary mode, which NumPy 2 removed, so the block is decoded here with ``numpy.frombuffer``
  in the dtype the header states (BYT_NR, BN_FMT, BYT_OR) and converted with the header's
  ``(code - YOFF) * YMULT + YZERO`` and ``t = (i - PT_OFF) * XINCR + XZERO``.
  ``lsb_v = YMULT``, or ``256 * YMULT`` when BYT_NR is 2 and every code is a multiple of 256
  (TDS200/1000/2000 send their 8-bit samples multiplied by 256 at width 2); ``range_v`` is
  the whole code range (-2^(8*BYT_NR-1) .. 2^(8*BYT_NR-1)-1 for RI, 0 .. 2^(8*BYT_NR)-1 for
  RP) through the same conversion, i.e. the digitiser's limits, not the screen's. The
  channel is named from ``WFID`` (``"Ch1, DC coupling, ..."`` -> ``CH1``), else from the
  stem. isfreader 1.0.2 requires the header fields VSCALE, HSCALE, VPOS, VOFFSET and HDELAY
  (written by TDS1000B/2000B-style scopes); a file without them is refused with a message
  naming the missing ones. ASCII-encoded curves and envelope records (``PT_FMT ENV``) are
  refused too.
- ``rigol-wfm``: Rigol ``.wfm`` through the ``RigolWFM`` package (``Wfm.from_file``, scope
  family detected from the file). Channels are named ``CH1``... (RigolWFM's ``"CH 1"``
  without the space); ``lsb_v`` is the volts per raw code of the linear map RigolWFM applies
  (None where it gives no raw codes); ``range_v`` is None, since RigolWFM does not state
  the digitiser's limits. Tested on one DS1000D file from RigolWFM's own test set
  (tests/data/DS1102D-A.wfm) only.

Every reader checks: the file exists and is not empty, time is strictly increasing, no
value is NaN or empty, and time and values have the same length. Errors are
`ScopeFileError` (a `ValueError`), naming the file, the row/column or key, and the fix.
"""

from __future__ import annotations

import csv
import dataclasses
import gc
import io
import math
import re
import warnings
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


def detect_format(path) -> str:
    """The format name of `path` (a key of `FORMATS`), by suffix and, for .csv/.txt, content
    (`_csv_layout`): .isf -> tek-isf, .wfm -> rigol-wfm, .npz, .mat, and .csv/.txt -> the
    vendor layout its first rows show, else csv."""
    path = Path(path)
    _check_file(path)
    suffix = path.suffix.lower()
    by_suffix = {".isf": "tek-isf", ".wfm": "rigol-wfm", ".npz": "npz", ".mat": "mat"}
    if suffix in by_suffix:
        return by_suffix[suffix]
    if suffix in (".csv", ".txt"):
        return _csv_layout(_decode(path))
    raise ScopeFileError(f"{path}: unknown suffix {path.suffix!r}; name the format "
                         f"(format = ...) as one of: {_formats_text()}.")


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


def read_waveforms(path, format: str = "auto") -> Waveforms:
    """Read the scope file `path` in `format` (a key of `FORMATS`, or "auto" for
    `detect_format`) into `Waveforms` (s, V)."""
    if format != "auto" and format not in FORMATS:
        raise ScopeFileError(f"{path}: unknown format {format!r}; use 'auto' or one of: {_formats_text()}.")
    path = Path(path)
    _check_file(path)
    name = detect_format(path) if format == "auto" else format
    readers = {"tek-csv": _read_tek_csv, "csv": _read_csv, "rigol-csv": _read_rigol_csv,
               "keysight-csv": _read_keysight_csv, "lecroy-csv": _read_lecroy_csv, "pico-csv": _read_pico_csv, "npz": _read_npz, "mat": _read_mat,
               "tek-isf": _read_tek_isf, "rigol-wfm": _read_rigol_wfm}
    return readers[name](path)


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


# --- npz and mat --------------------------------------------------------------------------

def _from_arrays(path: Path, format: str, arrays: dict[str, np.ndarray], rename) -> Waveforms:
    """Waveforms from named arrays: a time array (`TIME_NAMES`), channels, `<name>_range_v`."""
    found = [k for k in TIME_NAMES if k in arrays]
    if not found:
        raise ScopeFileError(f"{path}: no time array; name it one of {', '.join(TIME_NAMES)} (seconds). "
                             f"The file holds: {', '.join(arrays) or 'nothing'}.")
    if len(found) > 1:
        raise ScopeFileError(f"{path}: several time arrays ({', '.join(found)}); keep one.")
    time_s = np.asarray(arrays[found[0]]).squeeze()
    if time_s.ndim != 1 or not np.issubdtype(time_s.dtype, np.number):
        raise ScopeFileError(f"{path}: key {found[0]!r} has shape {time_s.shape}; time must be a 1-D "
                             f"numeric vector.")
    time_s = time_s.astype(np.float64)
    _check_time(path, time_s, what="sample")
    channels: dict[str, np.ndarray] = {}
    ranges: dict[str, np.ndarray] = {}
    info: dict[str, str] = {"time": found[0]}
    for key, raw in arrays.items():
        if key == found[0]:
            continue
        array = np.asarray(raw)
        if key.endswith("_range_v"):
            ranges[key[: -len("_range_v")]] = array
            continue
        if not np.issubdtype(array.dtype, np.number) or array.size == 1:
            info[key] = str(array.squeeze()) if array.size <= 16 else f"<{array.dtype} {array.shape}>"
            continue
        values = array.squeeze()
        if values.ndim != 1:
            raise ScopeFileError(f"{path}: key {key!r} has shape {array.shape}; a channel must be a "
                                 f"vector of {time_s.size} values.")
        name = rename(key)
        if name in channels:
            raise ScopeFileError(f"{path}: keys name channel {name!r} twice; rename one.")
        values = values.astype(np.float64)
        _check_values(path, name, values, time_s.size)
        channels[name] = values
    if not channels:
        raise ScopeFileError(f"{path}: no channel arrays besides {found[0]!r}; the file holds: "
                             f"{', '.join(arrays)}.")
    range_v: dict[str, tuple[float, float] | None] = dict.fromkeys(channels)
    for name, limits in ranges.items():
        channel = rename(name)
        limits = np.asarray(limits, dtype=np.float64).ravel()
        if channel not in channels:
            raise ScopeFileError(f"{path}: key {name}_range_v names no channel; channels: {', '.join(channels)}.")
        if limits.size != 2 or not limits[0] < limits[1]:
            raise ScopeFileError(f"{path}: key {name}_range_v = {limits}; give [low, high] in volts, low < high.")
        range_v[channel] = (float(limits[0]), float(limits[1]))
    return Waveforms(str(path), format, time_s, channels, range_v, dict.fromkeys(channels), info)


def _read_npz(path: Path) -> Waveforms:
    try:
        with np.load(path, allow_pickle=False) as archive:
            arrays = {key: archive[key] for key in archive.files}
    except (ValueError, OSError) as error:
        raise ScopeFileError(f"{path}: not a readable .npz ({error}); save it with numpy.savez.") from None
    return _from_arrays(path, "npz", arrays, lambda key: key)


def _read_mat(path: Path) -> Waveforms:
    import scipy.io

    try:
        contents = scipy.io.loadmat(path)
    except NotImplementedError:
        raise ScopeFileError(f"{path}: a MATLAB v7.3 (HDF5) file, which is not supported; save it as "
                             f"v7 in MATLAB: save('{path.name}', ..., '-v7').") from None
    except (ValueError, OSError, TypeError) as error:
        raise ScopeFileError(f"{path}: not a readable .mat file ({error}).") from None
    arrays = {k: v for k, v in contents.items() if not k.startswith("__")}

    def rename(key: str) -> str:
        if re.fullmatch(r"ch\d+", key, flags=re.IGNORECASE):
            return key.upper()
        return _stem_channel_name(path) if key == "y" else key

    return _from_arrays(path, "mat", arrays, rename)


# --- tek-isf ------------------------------------------------------------------------------

_ISFREADER_FIELDS = ("VSCALE", "HSCALE", "VPOS", "VOFFSET", "HDELAY")


def _read_tek_isf(path: Path) -> Waveforms:
    import isfreader

    data = path.read_bytes()
    try:
        header, block = isfreader.split_isf_header(data)
    except isfreader.py_isfreader.InvalidFileError as error:
        preamble = data.split(b":CURV", 1)[0].decode("latin-1")
        missing = [k for k in _ISFREADER_FIELDS if not re.search(rf"[:;]{k} ", preamble)]
        hint = (f"its header lacks {', '.join(missing)}, which isfreader requires; save the record as "
                f"CSV (format 'tek-csv') instead" if missing else "check that it is a Tektronix .isf file")
        raise ScopeFileError(f"{path}: isfreader cannot read it ({error}); {hint}.") from None
    except (ValueError, IndexError) as error:
        raise ScopeFileError(f"{path}: not a Tektronix .isf file ({error}); it needs a header "
                             f"':WFMPRE:...;:CURVE #<n><length><data>'.") from None
    info = {key: str(value) for key, value in header.items()}
    if not str(header["ENCDG"]).upper().startswith("BIN"):
        raise ScopeFileError(f"{path}: ENCDG {header['ENCDG']}; only binary curves are read, save the "
                             f"record with binary encoding or as CSV.")
    if str(header["PT_FMT"]).upper() != "Y":
        raise ScopeFileError(f"{path}: PT_FMT {header['PT_FMT']}; only sampled records (PT_FMT Y) are "
                             f"read, not envelopes; acquire in Sample mode.")
    if header["XUNIT"].lower() != "s" or header["YUNIT"] != "V":
        raise ScopeFileError(f"{path}: XUNIT {header['XUNIT']!r}, YUNIT {header['YUNIT']!r}; a time record "
                             f"in volts needs XUNIT \"s\" and YUNIT \"V\".")
    width = header["BYT_NR"]
    signed = str(header["BN_FMT"]).upper() == "RI"
    dtype = np.dtype(f"{'>' if header['BYT_OR'] == 'MSB' else '<'}{'i' if signed else 'u'}{width}")
    if len(block) != header["NR_PT"] * width:
        raise ScopeFileError(f"{path}: the curve block has {len(block)} bytes but NR_PT {header['NR_PT']} x "
                             f"BYT_NR {width} = {header['NR_PT'] * width}; the file is truncated.")
    codes = np.frombuffer(block, dtype=dtype).astype(np.float64)
    ymult, yoff, yzero = header["YMULT"], header["YOFF"], header["YZERO"]
    volts = (codes - yoff) * ymult + yzero
    time_s = (np.arange(codes.size) - header["PT_OFF"]) * header["XINCR"] + header["XZERO"]
    _check_time(path, time_s, what="sample")
    match = re.match(r"(CH\d+|MATH|REF\w)", str(header["WFID"]).strip('" '), flags=re.IGNORECASE)
    name = match.group(1).upper() if match else _stem_channel_name(path)
    bits = 8 * width
    low_code, high_code = (-(2 ** (bits - 1)), 2 ** (bits - 1) - 1) if signed else (0, 2**bits - 1)
    limits = sorted(((low_code - yoff) * ymult + yzero, (high_code - yoff) * ymult + yzero))
    lsb = abs(ymult) * (256 if width == 2 and np.all(codes % 256 == 0) else 1)
    return Waveforms(str(path), "tek-isf", time_s, {name: volts}, {name: (limits[0], limits[1])},
                     {name: float(lsb)}, info)


# --- rigol-wfm ----------------------------------------------------------------------------

def _read_rigol_wfm(path: Path) -> Waveforms:
    # RigolWFM's Kaitai parsers leave the file open inside the parsed record (a reference
    # cycle): the record is read and dropped, and collected, with that ResourceWarning muted.
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ResourceWarning)
        waves = _rigol_waveforms(path)
        gc.collect()
    return waves


def _rigol_waveforms(path: Path) -> Waveforms:
    import RigolWFM.wfm as rigol

    try:
        record = rigol.Wfm.from_file(str(path))
    except Exception as error:  # noqa: BLE001 - RigolWFM raises its own classes, struct and Kaitai errors
        raise ScopeFileError(f"{path}: RigolWFM cannot read it ({type(error).__name__}: {error}); check "
                             f"that it is a .wfm saved by a Rigol scope that RigolWFM supports.") from None
    if not record.channels:
        raise ScopeFileError(f"{path}: RigolWFM finds no enabled channel in it.")
    time_s = np.asarray(record.channels[0].times, dtype=np.float64)
    _check_time(path, time_s, what="sample")
    channels, lsb_v = {}, {}
    info = {"model": str(record.header_name), "parser": str(record.parser_name),
            "serial_number": str(record.serial_number)}
    for channel in record.channels:
        name = channel.name.replace(" ", "").upper()
        if not np.array_equal(np.asarray(channel.times, dtype=np.float64), time_s):
            raise ScopeFileError(f"{path}: channel {name} has another time grid than "
                                 f"{record.channels[0].name}; RigolWFM reads them apart.")
        volts = np.asarray(channel.volts, dtype=np.float64)
        _check_values(path, name, volts, time_s.size)
        channels[name] = volts
        lsb_v[name] = _rigol_step(channel.raw, volts)
        for key in ("volt_per_division", "volt_offset", "probe_value", "coupling"):
            info[f"{name} {key}"] = str(getattr(channel, key))
    return Waveforms(str(path), "rigol-wfm", time_s, channels, dict.fromkeys(channels), lsb_v, info)


def _rigol_step(raw, volts: np.ndarray) -> float | None:
    """Volts per raw code of the linear map from `raw` to `volts`, or None if there is none."""
    if raw is None:
        return None
    raw = np.asarray(raw, dtype=np.float64)
    if raw.shape != volts.shape or np.ptp(raw) == 0:
        return None
    i, j = int(np.argmin(raw)), int(np.argmax(raw))
    slope = (volts[j] - volts[i]) / (raw[j] - raw[i])
    linear = np.allclose(volts, volts[i] + slope * (raw - raw[i]), rtol=0, atol=1e-6 * abs(slope))
    return float(abs(slope)) if linear else None


# --- merging ------------------------------------------------------------------------------

def merge_waveforms(parts: list[Waveforms], where: str) -> Waveforms:
    """One shot's channels from several files (`where` names the shot in messages).

    The time grids must agree: same length, and first time and interval within 1e-9 of the
    interval. A channel named in two files is an error naming both."""
    if not parts:
        raise ScopeFileError(f"{where}: no files to merge; list the shot's files.")
    if len(parts) == 1:
        return parts[0]
    first = parts[0]
    n = first.time_s.size
    for part in parts[1:]:
        a, b = first.time_s, part.time_s
        if b.size != n:
            raise ScopeFileError(f"{where}: {first.path} has {n} samples and {part.path} has {b.size}; "
                                 f"one shot's files must share the time grid (same record length).")
        dt_a = (a[-1] - a[0]) / (n - 1) if n > 1 else 0.0
        dt_b = (b[-1] - b[0]) / (n - 1) if n > 1 else 0.0
        tolerance = 1e-9 * abs(dt_a)
        if abs(a[0] - b[0]) > tolerance:
            raise ScopeFileError(f"{where}: first times differ: {float(a[0])!r} s in {first.path}, {float(b[0])!r} s in "
                                 f"{part.path}; one shot's files must share the trigger and time grid.")
        if abs(dt_a - dt_b) > tolerance:
            raise ScopeFileError(f"{where}: sample intervals differ: {float(dt_a)!r} s in {first.path}, {float(dt_b)!r} s "
                                 f"in {part.path}; one shot's files must share the time base.")
    channels, range_v, lsb_v, info, owner = {}, {}, {}, {}, {}
    for part in parts:
        for name, values in part.channels.items():
            if name in channels:
                raise ScopeFileError(f"{where}: channel {name!r} is in both {owner[name]} and {part.path}; "
                                     f"each channel must come from one file.")
            owner[name] = part.path
            channels[name] = values
            range_v[name] = part.range_v.get(name)
            lsb_v[name] = part.lsb_v.get(name)
        info.update({f"{Path(part.path).name}: {key}": value for key, value in part.info.items()})
    formats = list(dict.fromkeys(p.format for p in parts))
    return Waveforms("; ".join(p.path for p in parts), "+".join(formats), first.time_s, channels,
                     range_v, lsb_v, info)
