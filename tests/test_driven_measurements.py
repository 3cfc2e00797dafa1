"""Measurement kinds of driven experiments: tongues, loops and scope records read from the lab's
files (onsets against the data's README), spectra against closed forms, and a file of one kind
refused as another with the reason."""

from pathlib import Path

import numpy as np
import pytest
from helpers import DRIVEN_EXPERIMENT_HEAD

from fitting.driven.experiment import DrivenExperimentError, load_driven_experiment
from hertzchain.driven.measurements import read_loop, read_scope, read_tongue, spectral_amplitude
from hertzchain.driven.sweeper_files import SweeperFileError

LYDON_2015 = Path(__file__).resolve().parents[1] / ".." / "shared" / "data" / "real" / "lydon-2015"
TONGUE = "SingleBead/BifurcationTongue/SingleBeadBif Signal Amplitude_{}2013Jul3_9h28m45s.txt"
LOOP = "SingleBead/OscilliscopeSnapshots/Data/SingleBeadSingleRun Signal Amplitude_{}2013Jul4_13h45m26s.txt"
SCOPE = "SingleBead/OscilliscopeSnapshots/Data/ScopeShots_middle2013Jul4_13h45m24s.txt.txt"
BENDING = "SingleBead/LinearToNonlinearBending/SingleBead_Bending Signal Amplitude_02013Jul3_10h29m15s.txt"
TONGUE_M_PER_V = 7.517e-7
real_data = pytest.mark.skipif(not LYDON_2015.is_dir(), reason="the Lydon 2015 measurements are not in ../shared")


def _sweeper(path: Path, row_label, rows, columns, values):
    header = "\t".join([row_label] + columns)
    lines = ["\t".join([f"{r:g}"] + [f"{v:.6g}" for v in row]) + "\t" for r, row in zip(rows, values)]
    path.write_text(header + "\n" + "\n".join(lines) + "\n")
    return path


def synthetic_tongue(folder: Path, onset_v):
    """f and f/2 files of a tongue at 7000 and 7200 Hz: f/2 0.5 x f from `onset_v` (V) on."""
    volts = np.arange(0.020, 0.0601, 0.004)
    fundamental = np.outer(volts, [1.0, 1.2])
    subharmonic = np.where(volts[:, None] >= np.asarray(onset_v) - 1e-12, 0.5, 0.002) * fundamental
    folder.mkdir(parents=True, exist_ok=True)
    names = []
    for quantity, values in (("0", fundamental), ("3", subharmonic)):
        name = f"Bif Signal Amplitude_{quantity}2013Jul3_9h28m45s.txt"
        _sweeper(folder / name, "Reference Amplitude (V)", volts, ["7000Hz", "7200Hz"], values)
        names.append(name)
    return names


def test_tongue_onsets_of_a_synthetic_sweep(tmp_path):
    names = synthetic_tongue(tmp_path, [0.032, 0.06])
    tongue = read_tongue(*(tmp_path / n for n in names), run="r", drive_m_per_v=1e-6)
    np.testing.assert_allclose(tongue.onset_m, [0.032e-6, 0.060e-6])
    assert tongue.step_m == pytest.approx(4e-9)


@real_data
def test_the_lydon_tongue_onsets_are_the_readmes_and_do_not_depend_on_the_rule():
    files = [LYDON_2015 / TONGUE.format(q) for q in "03"]
    tongue = read_tongue(*files, run="09:28", drive_m_per_v=TONGUE_M_PER_V)
    f = tongue.frequencies_hz
    onset_nm = tongue.onset_m * 1e9
    # the data's README: first at 39.8 nm at 7200 Hz; present between 6700 and 7500 Hz
    assert np.nanmin(onset_nm) == pytest.approx(39.8, abs=0.05) and f[np.nanargmin(onset_nm)] == 7200.0
    assert f[np.isfinite(onset_nm)].min() == 6700.0 and f[np.isfinite(onset_nm)].max() == 7500.0
    np.testing.assert_allclose(onset_nm[np.isin(f, [7000.0, 7200.0, 7500.0])], [51.1, 39.8, 48.9], atol=0.05)
    for rule in (0.03, 0.12):
        other = read_tongue(*files, run="09:28", drive_m_per_v=TONGUE_M_PER_V, rule=rule)
        np.testing.assert_array_equal(other.onset_m, tongue.onset_m)


@real_data
def test_the_lydon_loop_and_its_scope_records_agree():
    files = [LYDON_2015 / LOOP.format(q) for q in "03"]
    loop = read_loop(*files, run="07-04", drive_m_per_v=TONGUE_M_PER_V)
    # the README: f/2 appears at 71 nm going up and persists down to 46 nm
    assert loop.onset_up_m == pytest.approx(71.4e-9, abs=0.05e-9)
    assert loop.last_down_m == pytest.approx(45.9e-9, abs=0.05e-9)
    assert loop.gone_down_m < loop.last_down_m and loop.turn == 37
    for rule in (0.01, 0.35):
        assert read_loop(*files, run="07-04", drive_m_per_v=TONGUE_M_PER_V, rule=rule).onset_up_m == loop.onset_up_m
    scope = read_scope(LYDON_2015 / SCOPE, files[0], run="07-04", drive_m_per_v=TONGUE_M_PER_V)
    lockin_present = loop.subharmonic_v > 0.1 * loop.fundamental_v
    np.testing.assert_array_equal(scope.subharmonic_present, lockin_present)


def test_spectral_amplitude_of_two_cosines():
    t = np.arange(2048) * 9.7524e-6
    f = 6850.0
    signal = 0.3 * np.cos(2 * np.pi * f * t + 0.4) + 0.05 * np.cos(np.pi * f * t - 1.0)
    np.testing.assert_allclose(spectral_amplitude(t, np.stack([signal, 2 * signal], 1), f), [0.3, 0.6], rtol=2e-3)
    np.testing.assert_allclose(spectral_amplitude(t, signal[:, None], f / 2), [0.05], rtol=2e-2)


EXPERIMENT = DRIVEN_EXPERIMENT_HEAD + """[[measurement]]
kind = "KIND"
run = "RUN"
amplitude_file = "A"
SUB
"""


def _experiment(tmp_path, kind, amplitude, subharmonic=None, run="r"):
    sub = f'subharmonic_file = "{subharmonic}"' if subharmonic else ""
    toml = tmp_path / "e.toml"
    toml.write_text(EXPERIMENT.replace("KIND", kind).replace("RUN", run).replace('"A"', f'"{amplitude}"')
                    .replace("SUB", sub))
    return toml


def test_a_tongue_is_refused_as_a_bending_sweep_and_as_a_loop(tmp_path):
    names = synthetic_tongue(tmp_path / "data", [0.032, 0.06])
    data = tmp_path / "data"
    experiment = load_driven_experiment(_experiment(tmp_path, "tongue", *names), data)
    assert experiment.measurements[0].kind == "tongue" and experiment.sweep is None
    with pytest.raises(DrivenExperimentError, match=r"\[\[measurement\]\] 1.*sweeps the reference amplitude "
                       r"\(V, upward\) at 2 frequencies, 7000-7200 Hz: a period-doubling tongue, not a bending sweep"):
        load_driven_experiment(_experiment(tmp_path, "bending", names[0]), data)
    with pytest.raises(DrivenExperimentError, match="a period-doubling tongue, not an amplitude loop"):
        load_driven_experiment(_experiment(tmp_path, "loop", *names), data)
    with pytest.raises(DrivenExperimentError, match="holds 'Signal Amplitude_0'; this file should be the sweeper's "
                       "'Signal Amplitude_3'"):
        load_driven_experiment(_experiment(tmp_path, "tongue", names[0], names[0]), data)
    with pytest.raises(DrivenExperimentError, match="kind = 'tonge'; a measurement is one of .*did you mean 'tongue'"):
        load_driven_experiment(_experiment(tmp_path, "tonge", *names), data)


@real_data
def test_the_lydon_bending_file_is_refused_as_a_tongue_and_the_loop_as_a_tongue(tmp_path):
    with pytest.raises(DrivenExperimentError, match=r"sweeps the frequency \(Hz, upward\) at 36 columns in V: a "
                       "bending sweep, not a period-doubling tongue"):
        load_driven_experiment(_experiment(tmp_path, "tongue", BENDING, TONGUE.format(3)), LYDON_2015)
    with pytest.raises(DrivenExperimentError, match=r"\(V, up then down\) at 6850 Hz: an amplitude loop, not a "
                       "period-doubling tongue"):
        load_driven_experiment(_experiment(tmp_path, "tongue", LOOP.format(0), LOOP.format(3)), LYDON_2015)


def test_one_run_has_one_calibration(tmp_path):
    names = synthetic_tongue(tmp_path / "data", [0.032, 0.06])
    toml = _experiment(tmp_path, "tongue", *names)
    text = toml.read_text()
    second = text[text.index("[[measurement]]"):].replace('run = "r"', 'run = "r"\ndrive_calibration_m_per_v = 1e-6')
    toml.write_text(text + second)
    with pytest.raises(DrivenExperimentError, match="measurement\\]\\] 2.*run 'r' has another drive calibration"):
        load_driven_experiment(toml, tmp_path / "data")
    with pytest.raises(SweeperFileError, match="positive calibration"):
        read_tongue(*(tmp_path / "data" / n for n in names), run="r", drive_m_per_v=0.0)


def test_diagnose_and_params_refuse_a_file_of_measurements(tmp_path, capsys):
    from hertzchain.cli import main

    names = synthetic_tongue(tmp_path / "data", [0.032, 0.06])
    toml = _experiment(tmp_path, "tongue", *names)
    data = str(tmp_path / "data")
    assert main(["diagnose", str(toml), "--data-dir", data, "--out", str(tmp_path / "d")]) == 2
    assert "add a [[measurement]] of kind \"bending\"" in capsys.readouterr().err
    assert main(["fit", str(toml), "--data-dir", data, "--params", "drive_scale", "--out", str(tmp_path / "f")]) == 2
    assert "names what it fits in its [fit] table" in capsys.readouterr().err
    assert not (tmp_path / "f").exists() and not (tmp_path / "d").exists()


def test_loop_thresholds_of_a_hysteresis_loop():
    from hertzchain.driven.measurements import loop_thresholds

    drives = np.r_[1.0:6.0, 6.0, 5.0:0.0:-1.0]  # 1..5, 6, 5..1
    present = np.array([0, 0, 0, 1, 1, 1, 1, 1, 1, 0, 0], bool)
    assert loop_thresholds(drives, present) == (4.0, 3.0, 2.0)
    assert np.isnan(loop_thresholds(drives, np.zeros(11, bool))[0])
