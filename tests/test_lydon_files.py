"""Lock-in sweeper, scope and MATLAB files (hertzchain.driven.sweeper_files): on the real files
of Lydon et al. 2015, where present, and on files written here by a different writer."""

from pathlib import Path

import numpy as np
import pytest
import scipy.io

from hertzchain.driven.sweeper_files import (
    SweeperFileError,
    lockin_sweep,
    read_mat_variables,
    read_scope_shots,
    read_sweeper_table,
)

LYDON_2015 = Path(__file__).resolve().parents[2] / "shared/data/real/lydon-2015"
needs_data = pytest.mark.skipif(
    not LYDON_2015.is_dir(), reason=f"the Lydon 2015 measurements are not at {LYDON_2015} (read-only lab data)"
)
BENDING = "SingleBead/LinearToNonlinearBending"
SNAPSHOTS = "SingleBead/OscilliscopeSnapshots/Data"


def _one(pattern):
    (path,) = sorted(LYDON_2015.glob(pattern))
    return path


@needs_data
def test_bending_table_equals_the_authors_processed_mat_file():
    """The text file times 21.25 (mm/s)/V is the authors' `Velocity_Bending`; the lock-in
    volts times 6.834e-7 m/V their `Drive_Amp` (which they rounded to 4 digits)."""
    table = read_sweeper_table(_one(f"{BENDING}/*Signal Amplitude_0*.txt"))
    assert (table.run, table.quantity, table.date) == ("SingleBead_Bending", "Signal Amplitude_0", "2013Jul3_10h29m15s")
    assert (table.row_name, table.row_unit, table.column_unit) == ("Frequency", "Hz", "V")
    assert table.values.shape == (341, 36)
    np.testing.assert_allclose(table.row_values[[0, 1, -1]], [3000.0, 3005.0, 4700.0])
    np.testing.assert_allclose(table.column_values[[0, 1, -1]], [0.001, 0.00125, 0.00975])
    sweep = lockin_sweep(table, drive_m_per_v=6.834e-7, sensor_m_s_per_v=21.25e-3)
    mat = read_mat_variables(LYDON_2015 / BENDING / "Bending.mat", ["Velocity_Bending", "FrequencyHz", "Drive_Amp"])
    np.testing.assert_allclose(sweep.rms_velocity_m_s * 1e3, mat["Velocity_Bending"], rtol=1e-12)
    np.testing.assert_array_equal(sweep.frequencies_hz, mat["FrequencyHz"])
    np.testing.assert_allclose(sweep.drive_amplitudes_m, mat["Drive_Amp"], rtol=1e-4)
    # the README's numbers: peak at 3985 Hz at the lowest drive, 3690 Hz at the highest
    peaks = sweep.frequencies_hz[np.argmax(sweep.rms_velocity_m_s, axis=0)]
    assert (peaks[0], peaks[-1]) == (3985.0, 3690.0)


@needs_data
def test_scope_records_rms_equals_the_lockin_r_while_period_one():
    """Scope records and sweeper rows are the same steps: the RMS of each record is the lock-in
    R (within 2.5 %) for the first 25 steps (period-1 motion) and ~4x above it after the
    period doubling at step 26 (71 nm), in all three record lengths."""
    lockin = read_sweeper_table(_one(f"{SNAPSHOTS}/*Signal Amplitude_0*.txt"))
    assert (lockin.row_unit, lockin.column_unit, lockin.values.shape) == ("V", "Hz", (74, 1))
    for length, dt in (("short", 2.4381e-6), ("middle", 9.7524e-6), ("long", 39.01e-6)):
        shots = read_scope_shots(_one(f"{SNAPSHOTS}/ScopeShots_{length}*.txt.txt"))
        assert shots.signals_v.shape == (2048, 74)
        # the file prints times to 6 digits: single steps scatter by 0.3 %, their mean does not
        np.testing.assert_allclose((shots.time_s[-1] - shots.time_s[0]) / 2047, dt, rtol=1e-4)
        signal = shots.signals_v - shots.signals_v.mean(axis=0)
        ratio = np.sqrt(np.mean(signal**2, axis=0)) / lockin.values[:, 0]
        np.testing.assert_allclose(ratio[:25], 1.0, atol=0.025)
        assert np.all(ratio[25:30] > 3.5)


def test_files_from_another_writer(tmp_path):
    """A sweeper file with prefixed units and rows = drive (written here, not by the HF2LI),
    a scope file and a MAT file written by scipy."""
    freqs_khz = np.array([6.3, 6.35, 6.4])
    volts = np.array([0.02, 0.023])
    values = np.arange(6.0).reshape(2, 3) * 1e-3
    lines = ["Reference Amplitude (mV)\t" + "\t".join(f"{f:g}kHz" for f in freqs_khz)]
    lines += [f"{v * 1e3:g}\t" + "\t".join(f"{x:.6e}" for x in row) for v, row in zip(volts, values)]
    path = tmp_path / "MyRun Signal Amplitude_02020Jan1_1h2m3s.txt"
    path.write_text("\n".join(lines) + "\n")
    table = read_sweeper_table(path)
    assert (table.run, table.quantity, table.row_unit, table.column_unit) == ("MyRun", "Signal Amplitude_0", "V", "Hz")
    np.testing.assert_allclose(table.row_values, volts)
    sweep = lockin_sweep(table, drive_m_per_v=7.5e-7, sensor_m_s_per_v=0.02)
    np.testing.assert_allclose(sweep.frequencies_hz, freqs_khz * 1e3)
    np.testing.assert_allclose(sweep.drive_amplitudes_m, volts * 7.5e-7)
    np.testing.assert_allclose(sweep.rms_velocity_m_s, values.T * 0.02)

    scope = tmp_path / "shots.txt.txt"
    time = np.arange(5) * 1e-6
    np.savetxt(scope, np.column_stack([time, np.sin(time * 1e6), np.cos(time * 1e6)]), delimiter="\t")
    shots = read_scope_shots(scope)
    np.testing.assert_allclose(shots.signals_v[:, 1], np.cos(time * 1e6))

    mat = tmp_path / "sweep.mat"
    scipy.io.savemat(mat, {"Velocity": values, "Freq": freqs_khz[None] * 1e3})
    arrays = read_mat_variables(mat, ["Velocity", "Freq"])
    np.testing.assert_allclose(arrays["Freq"], freqs_khz * 1e3)


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("Frequency\t1Hz\n1\t2\n", "unit in brackets"),
        ("Frequency (Hz)\t0.001V\t0.002\n3000\t1\t2\n", "column 3: unit of .0.002. is not one of"),
        ("Frequency (Hz)\t0.001V\tx\n3000\t1\t2\n", "not a value with a unit"),
        ("Frequency (Hz)\t0.001V\n3000\tabc\n", "line 2, column 2"),
        ("Frequency (Hz)\t0.001V\n3000\t1\t2\n", "header names 1 columns"),
        ("Frequency (Hz)\t0.001V\t6000Hz\n3000\t1\t2\n", "mix units"),
        ("Frequency (Hz)\t0.001V\n", "no data lines"),
    ],
)
def test_bad_sweeper_files_name_the_problem(tmp_path, text, message):
    path = tmp_path / "bad.txt"
    path.write_text(text)
    with pytest.raises(SweeperFileError, match=message):
        read_sweeper_table(path)


def test_bad_inputs_name_the_fix(tmp_path):
    with pytest.raises(SweeperFileError, match="--data-dir"):
        read_sweeper_table(tmp_path / "absent.txt")
    path = tmp_path / "t.txt"
    path.write_text("Time (s)\t1s\n0\t1\n")
    with pytest.raises(SweeperFileError, match="one axis in Hz and one in V"):
        lockin_sweep(read_sweeper_table(path), drive_m_per_v=1e-7, sensor_m_s_per_v=0.02)
    path.write_text("Frequency (Hz)\t1V\n0\t1\n")
    with pytest.raises(SweeperFileError, match="drive_m_per_v"):
        lockin_sweep(read_sweeper_table(path), drive_m_per_v=-1.0, sensor_m_s_per_v=0.02)
    scope = tmp_path / "s.txt.txt"
    scope.write_text("0\t1\n1e-6\t2\n0.5e-6\t3\n")
    with pytest.raises(SweeperFileError, match="does not increase at row 3"):
        read_scope_shots(scope)
    mat = tmp_path / "m.mat"
    scipy.io.savemat(mat, {"A": np.ones(2)})
    with pytest.raises(SweeperFileError, match="no variable B; the file holds A"):
        read_mat_variables(mat, ["B"])
