"""Inputs of fit, import, contact and diagnose checked where they enter: labels and paths kept
in the folders the user named, a measurement of one kind refused as another, fit options that
cannot be run, file-system and parse errors as one line with exit status 2, and output folders
written as a whole. Nothing here runs a fit: every case is refused before the work starts."""

import os
import textwrap
from pathlib import Path

import numpy as np
import pytest

import hertzchain as hc
from fitting.data import FitInputError, load_experiments
from fitting.driven.experiment import DrivenExperimentError, is_driven_experiment, load_driven_experiment
from fitting.priors import PriorError, parse_prior
from hertzchain.io.atomic import FOLDER_MARKER, file_stem, output_folder
from hertzchain.cli import main
from hertzchain.cli.errors import input_error_text
from hertzchain.io.importer import ExperimentFileError, load_experiment
from hertzchain.io.tracefile import TraceFile, TraceFileError, read_trace, setup_header, write_trace
from helpers import DRIVEN_EXPERIMENT_HEAD

LYDON_2015 = Path(__file__).resolve().parents[1] / ".." / "shared" / "data" / "real" / "lydon-2015"
TONGUE = "SingleBead/BifurcationTongue/SingleBeadBif Signal Amplitude_02013Jul3_9h28m45s.txt"


def _trace(path, noise_std_n=0.5, seed=0):
    """A trace file of a 5-bead chain: one wall pulse (cos^6, 40 us wide, 100 N) in white noise,
    written without a simulation."""
    time = np.arange(1, 401) * 1e-6
    pulse = 100.0 * np.cos(np.clip((time - 2e-4) / 4e-5, -0.5, 0.5) * np.pi) ** 6
    wall = pulse + np.random.default_rng(seed).normal(0.0, 0.5, time.size)
    header = setup_header(hc.ChainSetup(5, striker_velocity_m_s=0.2)) | {"noise_std_n": noise_std_n}
    write_trace(path, TraceFile(header=header, time_s=time, channels={"wall": wall}))
    return str(path)


@pytest.fixture
def trace(tmp_path):
    return _trace(tmp_path / "shot.csv")


def _refused(argv, capsys, *messages):
    """Run the command; it must exit 2 with one line on stderr holding every message."""
    assert main(argv) == 2, argv
    error = capsys.readouterr().err.strip()
    assert "\n" not in error and "Traceback" not in error, error
    for message in messages:
        assert message in error, (message, error)
    return error


# --- labels and paths stay in the folders the user named ---------------------------------------
def test_one_label_rule_keeps_file_names_in_their_folder():
    assert [file_stem(label) for label in ("../escaped", "/etc/passwd", "shot 1", ".hidden", "run_2")] == \
        ["escaped", "etc_passwd", "shot_1", "hidden", "run_2"]


def _shot_experiment(folder, shots):
    folder.mkdir(exist_ok=True)
    (folder / "experiment.toml").write_text(textwrap.dedent("""\
        [chain]
        n_beads = 5
        bead_radius_m = "13mm"
        bead_density_kg_m3 = 7780
        bead_youngs_pa = "203GPa"
        bead_poisson = 0.3
        wall_youngs_pa = "203GPa"
        wall_poisson = 0.3
        striker_mass_kg = 0.0716
        [scope]
        format = "csv"
        [[channel]]
        source = "CH1"
        measures = "wall"
        sensitivity_v_per_n = 0.01
        coupling = "dc"
        """) + shots)
    return folder / "experiment.toml"


def _scope_file(path, peak_v=1.0, seed=0):
    """A generic-CSV scope record: 100 samples before the trigger, a 40 us pulse after it."""
    time = np.arange(-100, 400) * 1e-6
    volts = peak_v * np.cos(np.clip((time - 1.5e-4) / 4e-5, -0.5, 0.5) * np.pi) ** 6
    volts = volts + np.random.default_rng(seed).normal(0.0, 0.004, time.size)
    path.write_text("time (s),CH1 (V)\n" + "".join(f"{t:.9g},{v:.6g}\n" for t, v in zip(time, volts)))


@pytest.mark.parametrize("label", ["../escaped", "/tmp/escaped", "..", ".hidden"])
def test_import_refuses_a_label_that_names_a_path(tmp_path, capsys, label):
    experiment = _shot_experiment(tmp_path / "lab", f'[[shot]]\nfiles = ["s.csv"]\nlabel = "{label}"\n')
    _scope_file(tmp_path / "lab" / "s.csv")
    _refused(["import", str(experiment), "--out", str(tmp_path / "lab" / "out")], capsys,
             f"label = {label!r} names a path")
    assert sorted(p.name for p in tmp_path.rglob("*")) == ["experiment.toml", "lab", "s.csv"]


def test_content_of_a_file_outside_the_experiments_folder_is_not_shown(tmp_path, capsys):
    secret = tmp_path / "private" / "notes.csv"
    secret.parent.mkdir()
    secret.write_text("time (s),CH1 (V)\n0,hunter2\n1e-6,0\n")
    experiment = _shot_experiment(tmp_path / "lab", f'[[shot]]\nfiles = ["{secret}"]\n')
    error = _refused(["import", str(experiment), "--out", str(tmp_path / "out")], capsys,
                     "outside the experiment's folder", "content is not shown")
    assert "hunter2" not in error
    inside = tmp_path / "lab" / "notes.csv"  # the same file inside: the reader says what is wrong with it
    inside.write_text(secret.read_text())
    _shot_experiment(tmp_path / "lab", '[[shot]]\nfiles = ["notes.csv"]\n')
    assert "'hunter2' is not a number" in _refused(["import", str(experiment), "--out", str(tmp_path / "out")], capsys)


# --- a measurement of one kind is not read as another ------------------------------------------
DRIVEN = DRIVEN_EXPERIMENT_HEAD + """[sweep]
amplitude_file = "FILE"
"""


def _tongue_files(folder):
    """A period-doubling tongue as the sweeper writes it: rows = drive volts (swept fastest at
    each frequency), columns = fixed frequencies; beside it the lock-in at f/2."""
    folder.mkdir()
    volts = np.arange(0.02, 0.128, 0.003)
    head = "Reference Amplitude (V)\t" + "\t".join(f"{f:g}Hz" for f in range(6300, 8001, 50)) + "\t\n"
    body = "".join(f"{v:g}\t" + "\t".join(f"{0.05 * v:.6g}" for _ in range(6300, 8001, 50)) + "\t\n" for v in volts)
    for quantity in ("Signal Amplitude_0", "Signal Amplitude_3"):
        (folder / f"Bif {quantity}2013Jul3_9h28m45s.txt").write_text(head + body)
    return "Bif Signal Amplitude_02013Jul3_9h28m45s.txt"


def test_a_tongue_file_is_refused_as_a_bending_sweep(tmp_path, capsys):
    name = _tongue_files(tmp_path / "data")
    toml = tmp_path / "tongue.toml"
    toml.write_text(DRIVEN.replace("FILE", name))
    with pytest.raises(DrivenExperimentError, match=r"sweeps the reference amplitude \(V\) at 35 fixed "
                       r"frequencies, 6300 to 8000 Hz \(beside it: Bif Signal Amplitude_3.*period-doubling tongue, "
                       r"not a bending sweep"):
        load_driven_experiment(toml, tmp_path / "data")
    _refused(["fit", str(toml), "--data-dir", str(tmp_path / "data"), "--out", str(tmp_path / "out")], capsys,
             "not a bending sweep")
    assert not (tmp_path / "out").exists()
    # the file's name says what it holds: a phase is not an amplitude, whatever its axes
    phase = tmp_path / "data" / "Run Signal Phase_02013Jul3_10h29m15s.txt"
    phase.write_text("Frequency (Hz)\t0.001V\n" + "".join(f"{3000 + 5 * i}\t0.5\n" for i in range(20)))
    toml.write_text(DRIVEN.replace("FILE", phase.name))
    with pytest.raises(DrivenExperimentError, match=r"holds 'Signal Phase_0' \(the lock-in phase"):
        load_driven_experiment(toml, tmp_path / "data")


@pytest.mark.skipif(not LYDON_2015.is_dir(), reason="the Lydon 2015 measurements are not in ../shared/data/real")
def test_the_lydon_tongue_file_is_refused_as_a_bending_sweep(tmp_path):
    toml = tmp_path / "tongue.toml"
    toml.write_text(DRIVEN.replace("FILE", TONGUE))
    with pytest.raises(DrivenExperimentError, match="period-doubling tongue, not a bending sweep"):
        load_driven_experiment(toml, LYDON_2015)


def test_a_misspelt_kind_suggests_the_closest(tmp_path, capsys):
    toml = tmp_path / "e.toml"
    toml.write_text(DRIVEN.replace('kind = "driven"', 'kind = "drivn"'))
    with pytest.raises(DrivenExperimentError, match='kind = \'drivn\' is not a kind of experiment; did you mean '
                       'kind = "driven"'):
        is_driven_experiment(toml)
    _refused(["import", str(toml), "--out", str(tmp_path / "out")], capsys, "kind = 'drivn'", "no kind key")


# --- fit options that cannot be run ---------------------------------------------------------------
@pytest.mark.parametrize(("options", "messages"), [
    (["--noise-std", "0"], ["--noise-std 0: the noise sigma must be positive (N)"]),
    (["--noise-std", "-1"], ["--noise-std -1: the noise sigma must be positive"]),
    (["--steps-per-contact", "5"], ["steps_per_contact = 5", "at least 20"]),
    (["--steps-per-contact", "0"], ["steps_per_contact = 0", "at least 20"]),
    (["--steps-per-contact", "-3"], ["steps_per_contact = -3"]),
    (["--max-steps", "0"], ["--max-steps 0: give a positive integer"]),
])
def test_fit_refuses_options_that_cannot_run(trace, tmp_path, capsys, options, messages):
    _refused(["fit", trace, "--out", str(tmp_path / "out"), *options], capsys, *messages)
    assert not (tmp_path / "out").exists()


def test_diagnose_refuses_too_few_steps_per_contact(trace, tmp_path, capsys):
    _refused(["diagnose", trace, "--out", str(tmp_path / "out"), "--steps-per-contact", "5"], capsys,
             "steps_per_contact = 5")


def test_a_file_given_twice_is_refused(trace, tmp_path, capsys):
    _refused(["fit", trace, trace, "--out", str(tmp_path / "out")], capsys, "the same file as", "given twice")
    copy = tmp_path / "copy.csv"
    copy.write_bytes(Path(trace).read_bytes())
    with pytest.raises(FitInputError, match="the same content as .*shot.csv, given twice"):
        load_experiments([trace, str(copy)])
    assert len(load_experiments([trace, _trace(tmp_path / "other.csv", seed=1)])) == 2


def test_a_noise_sigma_of_zero_in_a_header_is_refused(tmp_path):
    with pytest.raises(FitInputError, match=r"header noise_std_n = 0.0: a noise sigma must be positive"):
        load_experiments([_trace(tmp_path / "zero.csv", noise_std_n=0.0)])


def test_fixed_values_outside_their_range_are_refused(trace, tmp_path, capsys):
    _refused(["fit", trace, "--params", "eta_s,C", "--fixed", "mu=-1", "--out", str(tmp_path / "out"), "--quiet"],
             capsys, "fixed mu = -1 is outside its range (0 to 3)")


def test_a_prior_width_takes_the_unit_of_its_value():
    """`203GPa+-4` is 4 GPa (not 4 Pa); a bare width with no value beside it must carry a unit."""
    assert parse_prior("bead_youngs_pa=203GPa+-4").sd == pytest.approx(4e9)
    assert parse_prior("bead_youngs_pa=203e9+-4e9").sd == pytest.approx(4e9)
    prior = parse_prior("eta_s=0..10us")
    assert (prior.low, prior.high) == (0.0, pytest.approx(1e-5))
    assert parse_prior("bead_radius_m=+-62.5um").sd == pytest.approx(62.5e-6)
    with pytest.raises(PriorError, match=r"the width '4' has no unit; .*\(e.g. \+-4GPa\) or relative"):
        parse_prior("bead_youngs_pa=+-4")


# --- every file-system and parse error as one line, exit status 2 ----------------------------------
def test_an_output_path_that_is_a_file_is_refused_before_the_work(trace, tmp_path, capsys):
    _refused(["fit", trace, "--out", trace], capsys, "is a file, not a folder")
    _refused(["fit", trace, "--out", str(Path(trace) / "sub")], capsys, "is a file, not a folder")
    mine = tmp_path / "mine"
    mine.mkdir()
    (mine / "thesis.tex").write_text("mine")
    _refused(["fit", trace, "--out", str(mine)], capsys, "holds files that hertzchain did not write")
    assert (mine / "thesis.tex").read_text() == "mine"


def test_file_system_errors_are_one_line(tmp_path, capsys):
    full = OSError(28, "No space left on device")
    full.filename = str(tmp_path / "out" / "fit.json")
    assert input_error_text(full) == f"{full.filename}: No space left on device; the disk is full: free space or " \
                                     "choose another --out."
    denied = PermissionError(13, "Permission denied", str(tmp_path / "out"))
    assert "Permission denied; check its permissions" in input_error_text(denied)


@pytest.mark.parametrize(("edit", "message"), [
    (lambda t: t.replace("n_beads = 5", "n_beads = 1e400"), "header n_beads must be an integer, got '1e400'"),
    (lambda t: t.replace(",", ";"), "the columns are separated by ';'"),
    (lambda t: "\n".join(line if line.startswith(("#", "time")) else line.replace(".", ",")
                         for line in t.splitlines()), "is ',' the decimal point?"),
    (lambda t: t.replace("bead_radius_m = 0.013", "bead_radius_m = 0,013"), "(write decimals with '.')"),
])
def test_trace_file_parse_errors_name_the_file_and_the_fix(trace, tmp_path, capsys, edit, message):
    bad = tmp_path / "bad.csv"
    bad.write_text(edit(Path(trace).read_text()))
    _refused(["fit", str(bad), "--out", str(tmp_path / "out")], capsys, str(bad), message)


def test_trace_file_encodings(trace, tmp_path):
    text = Path(trace).read_text()
    bom = tmp_path / "bom.csv"
    bom.write_text("\ufeff" + text)  # an editor's byte-order mark hides nothing
    assert read_trace(bom).header == read_trace(trace).header
    latin = tmp_path / "latin.csv"
    latin.write_bytes(text.replace("# noise_std_n", "# x_note = caf\u00e9\n# noise_std_n").encode("latin-1"))
    with pytest.raises(TraceFileError, match=r"latin.csv: line \d+: not UTF-8 text .*save it as UTF-8"):
        read_trace(latin)


def _contact(tmp_path, name, text):
    path = tmp_path / name
    path.write_bytes(text) if isinstance(text, bytes) else path.write_text(text)
    return ["contact", str(path), "--material", "steel_440C", "--radius", "3.175mm", "--out",
            str(tmp_path / "out")]


@pytest.mark.parametrize(("name", "text", "message"), [
    ("fake.mat", b"this is not a MATLAB file" * 8, "not a MATLAB file scipy.io can read"),
    ("short.csv", "approach_m,force_n\n0,0\n1e-6\n", "line 3 has 1 cells for the 2 columns approach_m,force_n."),
    ("long.csv", "approach_m,force_n\n0,0\n1,5e-6,2,5\n", "line 3 has 4 cells for the 2 columns approach_m,force_n "
                                                           "(is ',' the decimal point?"),
    ("semi.csv", "approach_m;force_n\n0;0\n", "separated by ';'"),
    ("text.csv", "approach_m,force_n\n0,zero\n", "line 2, column force_n: 'zero' is not a number"),
])
def test_contact_file_errors_are_one_line(tmp_path, capsys, name, text, message):
    _refused(_contact(tmp_path, name, text), capsys, name, message)
    assert not (tmp_path / "out").exists()


def test_contact_radius_without_unit_is_refused_before_anything_is_written(tmp_path, capsys):
    argv = _contact(tmp_path, "c.csv", "approach_m,force_n\n" + "".join(f"{k}e-6,{k}\n" for k in range(20)))
    argv[argv.index("3.175mm")] = "13"
    _refused(argv, capsys, "--radius 13: 13 m is not a sphere's radius", "did you mean 13mm?")
    assert not (tmp_path / "out").exists()


# --- output folders are written as a whole ---------------------------------------------------------
def test_output_folder_is_replaced_whole(tmp_path, capsys):
    out = tmp_path / "out"
    with output_folder(out, "test", "fit.json") as folder:
        (folder / "residuals_shot1.csv").write_text("first run")
        (folder / "plot.png").write_text("first run")
    assert sorted(p.name for p in out.iterdir()) == [FOLDER_MARKER, "plot.png", "residuals_shot1.csv"]
    assert capsys.readouterr().err == ""  # a new folder: nothing replaced
    with output_folder(out, "test", "fit.json") as folder:
        assert sorted(p.name for p in folder.iterdir()) == [FOLDER_MARKER]
        (folder / "plot.png").write_text("second run")
    assert capsys.readouterr().err == f"hertzchain test: replaced the results of an earlier run in {out}\n"
    assert sorted(p.name for p in out.iterdir()) == [FOLDER_MARKER, "plot.png"]  # no stale residuals
    assert (out / "plot.png").read_text() == "second run"
    with pytest.raises(RuntimeError), output_folder(out, "test", "fit.json") as folder:  # a failed run changes nothing
        (folder / "plot.png").write_text("failed run")
        raise RuntimeError
    assert (out / "plot.png").read_text() == "second run"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]


def test_temporaries_of_killed_runs_are_removed_on_the_next_run(tmp_path):
    dead = os.getpid() + 1
    while True:  # a process number no process has
        try:
            os.kill(dead, 0)
            dead += 1
        except ProcessLookupError:
            break
    orphan = tmp_path / f".out.new-{dead}-abc"
    orphan.mkdir()
    (orphan / "fit.json").write_text("{}")
    alive = tmp_path / f".out.new-{os.getpid()}-xyz"  # a run still going: left alone
    alive.mkdir()
    with output_folder(tmp_path / "out", "test", "fit.json"):
        pass
    assert sorted(p.name for p in tmp_path.iterdir()) == [alive.name, "out"]


def test_import_writes_its_folder_whole(tmp_path, capsys):
    lab = tmp_path / "lab"
    experiment = _shot_experiment(lab, '[[shot]]\nfiles = ["a.csv"]\n[[shot]]\nfiles = ["b.csv"]\nlabel = "b 2"\n')
    _scope_file(lab / "a.csv")
    _scope_file(lab / "b.csv", peak_v=0.8, seed=1)
    out = tmp_path / "out"
    assert main(["import", str(experiment), "--out", str(out), "--no-plots"]) == 0
    assert sorted(p.name for p in out.iterdir()) == [FOLDER_MARKER, "a.csv", "b_2.csv", "import.json"]
    first = read_trace(out / "a.csv")
    assert first.header["x_shot"] == "a" and np.max(first.channels["wall"]) == pytest.approx(100.0, rel=0.05)
    _shot_experiment(lab, '[[shot]]\nfiles = ["b.csv"]\n')
    assert main(["import", str(experiment), "--out", str(out), "--no-plots"]) == 0
    assert sorted(p.name for p in out.iterdir()) == [FOLDER_MARKER, "b.csv", "import.json"]
    capsys.readouterr()


def test_load_experiment_refuses_a_file_that_is_not_utf8(tmp_path):
    path = tmp_path / "e.toml"
    path.write_bytes("[chain]\n# caf\u00e9\n".encode("latin-1"))
    with pytest.raises(ExperimentFileError, match="e.toml: not UTF-8 text"):
        load_experiment(path)


def test_content_of_a_sweep_file_outside_the_data_dir_is_not_shown(tmp_path):
    (tmp_path / "data").mkdir()
    (tmp_path / "private.txt").write_text("hunter2\t1\n")
    toml = tmp_path / "e.toml"
    toml.write_text(DRIVEN.replace("FILE", "../private.txt"))
    with pytest.raises(DrivenExperimentError, match="outside --data-dir") as refused:
        load_driven_experiment(toml, tmp_path / "data")
    assert "hunter2" not in str(refused.value)
