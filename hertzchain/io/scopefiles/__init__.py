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

from pathlib import Path

from .binary_formats import _read_mat, _read_npz, _read_rigol_wfm, _read_tek_isf
from .common import (
    FORMATS,
    TIME_NAMES,
    TIME_UNITS_S,
    VOLTAGE_UNITS_V,
    ScopeFileError,
    Waveforms,
    _check_file,
    _decode,
    _formats_text,
)
from .merge import merge_waveforms
from .text_formats import (
    _csv_layout,
    _read_csv,
    _read_keysight_csv,
    _read_lecroy_csv,
    _read_pico_csv,
    _read_rigol_csv,
    _read_tek_csv,
)

__all__ = ["FORMATS", "TIME_NAMES", "TIME_UNITS_S", "VOLTAGE_UNITS_V", "ScopeFileError", "Waveforms",
           "detect_format", "merge_waveforms", "read_waveforms"]


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
