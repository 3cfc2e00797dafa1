"""The measurements a lab makes on a driven chain, read from its instruments' files, in SI.

Four kinds, each read from the lock-in sweeper's text files (`sweeper_files`), each refusing a
file of another kind with the reason:

- **bending** (`read_bending`): the lock-in R at the drive frequency over a frequency sweep
  (the rows, swept fastest, in Hz) at fixed drive amplitudes (the columns, V): the resonance
  and how it bends with amplitude.
- **tongue** (`read_tongue`): drive-amplitude sweeps (the rows, V, swept upward) at fixed
  frequencies (the columns, Hz), with the lock-in at the drive frequency and at half of it
  (`Signal Amplitude_0`, `Signal Amplitude_3`): where the period-doubled (f/2) response
  appears, frequency by frequency.
- **loop** (`read_loop`): one drive-amplitude sweep up then down at one frequency, the same two
  lock-in readings: where f/2 appears going up and where it disappears coming down.
- **scope** (`read_scope`): the vibrometer's time series at each step of such a sweep
  (`read_scope_shots`), with their spectra's components at f and f/2.

**The subharmonic rule.** f/2 is present where its lock-in R exceeds `SUBHARMONIC_RULE` = 0.1
× the fundamental's: the rule of the data's README (Lydon et al. 2015). On the single-bead
files the ratio jumps at the onset from the noise floor (a few 0.001) to 0.4-4.6, so the onsets
do not depend on the rule: the tongue's are the same for any rule from 0.03 to 0.12 (only its
edge at 7500 Hz, where f/2 stays weak, 0.14-0.17, moves above that), the loop's from 0.01 to
0.35 (the tests check both). A threshold is the first
amplitude of an upward sweep where the rule holds; the true onset lies between it and the step
below (the lab steps 3 mV = 2.3 nm: a quantisation of `step / sqrt(12)` in amplitude).
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np

from .sweeper_files import (
    LockinSweep,
    ScopeShots,
    SweeperFileError,
    SweeperTable,
    lockin_sweep,
    read_scope_shots,
    read_sweeper_table,
)

SUBHARMONIC_RULE = 0.1
FUNDAMENTAL = "Signal Amplitude_0"
SUBHARMONIC = "Signal Amplitude_3"
KINDS = ("bending", "tongue", "loop", "scope")


@dataclasses.dataclass(frozen=True)
class Bending:
    """A bending sweep: `sweep` (`LockinSweep`, SI), `run` (the run it belongs to)."""

    run: str
    sweep: LockinSweep


@dataclasses.dataclass(frozen=True)
class Tongue:
    """Drive-amplitude sweeps at fixed frequencies (a period-doubling tongue).

    **Fields:** `run`; `frequencies_hz` (F,); `drive_amplitudes_m` (A,) nominal (lock-in volts ×
    `drive_m_per_v`), swept upward; `fundamental_v`, `subharmonic_v` (A, F) the lock-in R at f
    and f/2 (V RMS, as the instrument wrote them); `onset_m` (F,) the first amplitude where f/2
    is present (NaN where it never is: the onset lies above `drive_amplitudes_m[-1]`);
    `step_m` the amplitude step; `source`.
    """

    run: str
    frequencies_hz: np.ndarray
    drive_amplitudes_m: np.ndarray
    fundamental_v: np.ndarray
    subharmonic_v: np.ndarray
    onset_m: np.ndarray
    step_m: float
    drive_m_per_v: float
    source: str


@dataclasses.dataclass(frozen=True)
class Loop:
    """One drive-amplitude sweep up then down at `frequency_hz` (hysteresis).

    **Fields:** `run`; `drive_amplitudes_m` (S,) nominal, in sweep order; `fundamental_v`,
    `subharmonic_v` (S,); `turn` the index of the highest step; `onset_up_m` the first
    amplitude going up with f/2 present, `last_down_m` the last amplitude coming down where it
    still is, `gone_down_m` the first where it is not (NaN where there is none); `step_m`.
    """

    run: str
    frequency_hz: float
    drive_amplitudes_m: np.ndarray
    fundamental_v: np.ndarray
    subharmonic_v: np.ndarray
    turn: int
    onset_up_m: float
    last_down_m: float
    gone_down_m: float
    step_m: float
    drive_m_per_v: float
    source: str


@dataclasses.dataclass(frozen=True)
class Scope:
    """Scope records at each step of a sweep at `frequency_hz`: `shots` (`ScopeShots`, V),
    `drive_amplitudes_m` (K,) each record's drive (nominal, from the sweep's sweeper file),
    `fundamental_v`, `subharmonic_v` (K,) the records' spectral amplitudes at f and f/2
    (Hann-windowed, V amplitude), `subharmonic_present` (K,) by `SUBHARMONIC_RULE`."""

    run: str
    frequency_hz: float
    shots: ScopeShots
    drive_amplitudes_m: np.ndarray
    fundamental_v: np.ndarray
    subharmonic_v: np.ndarray
    subharmonic_present: np.ndarray
    source: str


def subharmonic_present(fundamental, subharmonic, rule: float = SUBHARMONIC_RULE) -> np.ndarray:
    """Where f/2 is present: its amplitude above `rule` × the fundamental's."""
    return np.asarray(subharmonic) > rule * np.asarray(fundamental)


def _describe(table: SweeperTable) -> str:
    columns = table.column_values
    if table.column_unit == "Hz":
        at = f"{columns[0]:g} Hz" if columns.size == 1 else f"{columns.size} frequencies, {columns.min():g}-{columns.max():g} Hz"
    else:
        at = f"{columns.size} columns in {table.column_unit}"
    order = "up then down" if table.row_values.size > 2 and np.any(np.diff(table.row_values) < 0) else "upward"
    return f"{table.path.name} sweeps the {table.row_name.lower() or 'row variable'} ({table.row_unit}, {order}) at {at}"


def _kind_of(table: SweeperTable) -> str:
    """The kind a sweeper table's axes say it is (bending, tongue, loop or unknown)."""
    if table.row_unit == "Hz" and table.column_unit == "V":
        return "bending"
    if table.row_unit == "V" and table.column_unit == "Hz":
        rising = np.all(np.diff(table.row_values) > 0)
        if table.column_values.size == 1 and not rising:
            return "loop"
        return "tongue" if rising else "unknown"
    return "unknown"


_NAMES = {"bending": "bending sweep", "tongue": "period-doubling tongue", "loop": "amplitude loop"}


def _article(kind: str) -> str:
    name = _NAMES[kind]
    return f"{'an' if name[0] in 'aeiou' else 'a'} {name}"


_WHAT = {
    "bending": "a frequency sweep (rows in Hz, swept fastest) at fixed drive amplitudes (columns in V)",
    "tongue": "upward drive-amplitude sweeps (rows in V, rising) at fixed frequencies (columns in Hz)",
    "loop": "one drive-amplitude sweep up then down (rows in V) at one frequency (one column in Hz)",
}


def _expect(table: SweeperTable, kind: str, quantity: str) -> None:
    got = _kind_of(table)
    if got != kind:
        named = _article(got) if got != "unknown" else "no measurement kind hertzchain knows"
        raise SweeperFileError(f"{_describe(table)}: {named}, not {_article(kind)}; {_article(kind)} file is "
                               f"{_WHAT[kind]}.")
    if table.date and table.quantity.strip() != quantity:
        raise SweeperFileError(f"{table.path.name} holds {table.quantity.strip()!r}; this file should be the "
                               f"sweeper's {quantity!r} file.")
    if np.any(np.isnan(table.values)):
        raise SweeperFileError(f"{table.path}: {int(np.isnan(table.values).sum())} empty cells.")


def _pair(fundamental_file, subharmonic_file, kind):
    fundamental = read_sweeper_table(fundamental_file)
    _expect(fundamental, kind, FUNDAMENTAL)
    subharmonic = read_sweeper_table(subharmonic_file)
    _expect(subharmonic, kind, SUBHARMONIC)
    if (not np.array_equal(fundamental.row_values, subharmonic.row_values)
            or not np.array_equal(fundamental.column_values, subharmonic.column_values)):
        raise SweeperFileError(f"{subharmonic.path.name} and {fundamental.path.name} do not share their axes: "
                               "the f and f/2 readings must come from the same sweep.")
    return fundamental, subharmonic


def _check_calibration(drive_m_per_v):
    if not (np.isfinite(drive_m_per_v) and drive_m_per_v > 0):
        raise SweeperFileError(f"drive_m_per_v = {drive_m_per_v!r} must be a positive calibration (m/V).")


def read_bending(amplitude_file, *, run: str, drive_m_per_v: float, sensor_m_s_per_v: float) -> Bending:
    """A bending sweep from its `Signal Amplitude_0` file. **Raises:** `SweeperFileError`
    (a tongue or loop file names itself as such)."""
    table = read_sweeper_table(amplitude_file)
    _expect(table, "bending", FUNDAMENTAL)
    return Bending(run, lockin_sweep(table, drive_m_per_v=drive_m_per_v, sensor_m_s_per_v=sensor_m_s_per_v))


def read_tongue(amplitude_file, subharmonic_file, *, run: str, drive_m_per_v: float,
                rule: float = SUBHARMONIC_RULE) -> Tongue:
    """A tongue from its f and f/2 lock-in files (`Signal Amplitude_0`, `_3`), onsets by `rule`."""
    _check_calibration(drive_m_per_v)
    fundamental, subharmonic = _pair(amplitude_file, subharmonic_file, "tongue")
    drives = fundamental.row_values * drive_m_per_v
    present = subharmonic_present(fundamental.values, subharmonic.values, rule)
    first = np.argmax(present, axis=0)
    onset = np.where(present.any(axis=0), drives[first], np.nan)
    return Tongue(run, fundamental.column_values, drives, fundamental.values, subharmonic.values, onset,
                  float(np.median(np.diff(drives))), float(drive_m_per_v), str(fundamental.path))


def tongue_fundamental(tongue: Tongue, *, sensor_m_s_per_v: float, levels: int = 3) -> Bending:
    """The tongue's lock-in at f on its `levels` lowest drive amplitudes as a frequency sweep at
    fixed drives: a `Bending` of the tongue run (RMS velocity, m/s, with `sensor_m_s_per_v`,
    (m/s)/V). Far above the chain's resonance the bead's response there is linear and measures
    the drive's true amplitude at the tongue's frequencies.

    **Raises:** `ValueError` when a chosen level is at or above an onset (its fundamental would
    mix in the period-doubled motion): choose fewer `levels`."""
    levels = int(levels)
    onsets = tongue.onset_m[np.isfinite(tongue.onset_m)]
    if levels < 1 or levels > tongue.drive_amplitudes_m.size:
        raise ValueError(f"levels: expected 1..{tongue.drive_amplitudes_m.size} drive levels, got {levels}.")
    if onsets.size and tongue.drive_amplitudes_m[levels - 1] >= onsets.min():
        raise ValueError(f"levels: the tongue's level {levels} ({tongue.drive_amplitudes_m[levels - 1]:.3g} m) is at "
                         f"or above its lowest onset ({onsets.min():.3g} m); choose fewer levels.")
    sweep = LockinSweep(np.asarray(tongue.frequencies_hz, dtype=float), np.asarray(tongue.drive_amplitudes_m[:levels]),
                        np.asarray(tongue.fundamental_v[:levels], dtype=float).T * sensor_m_s_per_v,
                        tongue.drive_m_per_v, float(sensor_m_s_per_v), tongue.source)
    return Bending(tongue.run, sweep)


def loop_thresholds(drive_amplitudes_m, present) -> tuple[float, float, float]:
    """(onset going up, last amplitude with f/2 coming down, first without it) of a sweep up to
    its highest step and back, from where f/2 is `present` (S,) (NaN where there is none)."""
    drives = np.asarray(drive_amplitudes_m, dtype=float)
    present = np.asarray(present, dtype=bool)
    turn = int(np.argmax(drives))
    up, down = present[:turn + 1], present[turn:]
    onset = drives[np.argmax(up)] if up.any() else np.nan
    last, gone = np.nan, np.nan
    if down[0]:
        end = int(np.argmin(down)) if not down.all() else down.size
        last = drives[turn + end - 1]
        gone = drives[turn + end] if end < down.size else np.nan
    return float(onset), float(last), float(gone)


def read_loop(amplitude_file, subharmonic_file, *, run: str, drive_m_per_v: float,
              rule: float = SUBHARMONIC_RULE) -> Loop:
    """An up/down loop from its f and f/2 lock-in files, onset and disappearance by `rule`."""
    _check_calibration(drive_m_per_v)
    fundamental, subharmonic = _pair(amplitude_file, subharmonic_file, "loop")
    drives = fundamental.row_values * drive_m_per_v
    f1, f2 = fundamental.values[:, 0], subharmonic.values[:, 0]
    turn = int(np.argmax(drives))
    if turn == drives.size - 1 or np.any(np.diff(drives[:turn + 1]) <= 0) or np.any(np.diff(drives[turn:]) >= 0):
        raise SweeperFileError(f"{_describe(fundamental)}: a loop rises to one highest step, then falls.")
    onset, last, gone = loop_thresholds(drives, subharmonic_present(f1, f2, rule))
    return Loop(run, float(fundamental.column_values[0]), drives, f1, f2, turn, onset, last, gone, float(np.median(np.abs(np.diff(drives)))), float(drive_m_per_v), str(fundamental.path))


def spectral_amplitude(time_s, signals, frequency_hz) -> np.ndarray:
    """Amplitude of the component at `frequency_hz` of each column of `signals` (N, K) sampled at
    `time_s` (N,): a Hann-windowed single-frequency Fourier sum, normalised so that
    $A\\cos(2\\pi f t)$ gives A (for records of many periods). **Returns:** (K,)."""
    t = np.asarray(time_s, dtype=float)
    window = np.hanning(t.size)
    phasor = window * np.exp(-2j * np.pi * frequency_hz * (t - t[0]))
    return 2.0 * np.abs(phasor @ np.asarray(signals, dtype=float)) / window.sum()


def read_scope(scope_file, levels_file, *, run: str, drive_m_per_v: float,
               rule: float = SUBHARMONIC_RULE) -> Scope:
    """Scope records (`read_scope_shots`) and the drive of each from the sweep's sweeper file
    `levels_file` (rows V, one column Hz: the frequency). **Raises:** `SweeperFileError` where
    the record count is not the sweep's step count, or a record spans under 8 periods of f/2."""
    _check_calibration(drive_m_per_v)
    shots = read_scope_shots(scope_file)
    levels = read_sweeper_table(levels_file)
    if levels.row_unit != "V" or levels.column_unit != "Hz" or levels.column_values.size != 1:
        raise SweeperFileError(f"{_describe(levels)}: the levels of scope records come from a sweep at one frequency "
                               "(rows in V, one column in Hz).")
    if shots.signals_v.shape[1] != levels.row_values.size:
        raise SweeperFileError(f"{Path(scope_file).name} holds {shots.signals_v.shape[1]} records, {levels.path.name} "
                               f"{levels.row_values.size} steps: they are not the same sweep.")
    frequency = float(levels.column_values[0])
    span = shots.time_s[-1] - shots.time_s[0]
    if span * frequency / 2 < 8:
        raise SweeperFileError(f"{Path(scope_file).name}: a record of {span * 1e3:.3g} ms holds "
                               f"{span * frequency / 2:.1f} periods of f/2 ({frequency / 2:g} Hz); at least 8 are needed "
                               "to separate it from f (use a longer record).")
    fundamental = spectral_amplitude(shots.time_s, shots.signals_v, frequency)
    subharmonic = spectral_amplitude(shots.time_s, shots.signals_v, frequency / 2)
    return Scope(run, frequency, shots, levels.row_values * drive_m_per_v, fundamental, subharmonic,
                 subharmonic_present(fundamental, subharmonic, rule), str(scope_file))
