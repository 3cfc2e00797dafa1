"""Each example in `examples/` runs at its small size and writes what it promises."""

import argparse
import runpy
from pathlib import Path

import numpy as np
import pytest

# Imported before the tests change directory: the examples run from a temporary folder.
import fitting  # noqa: F401
import hertzchain  # noqa: F401

EXAMPLES = Path(__file__).resolve().parent.parent / "examples"


@pytest.fixture
def small(monkeypatch, tmp_path):
    monkeypatch.setenv("HERTZCHAIN_EXAMPLE_SMALL", "1")
    monkeypatch.setenv("HERTZCHAIN_EXAMPLE_OUT", str(tmp_path))
    monkeypatch.chdir(tmp_path)
    return tmp_path


def _run(name):
    return runpy.run_path(str(EXAMPLES / name), run_name="__main__")


def test_01_simulate_paper_chain(small):
    namespace = _run("01_simulate_paper_chain.py")
    assert (small / "01_paper_chain.png").stat().st_size > 20_000
    from hertzchain.io.tracefile import read_trace

    trace = read_trace(small / "01_paper_chain.csv")
    assert trace.channel_names == ("contact_5", "contact_10", "wall")
    # eta = 2 us: the wave has lost amplitude by contact 10 (230.5 N against 333.4 N).
    assert trace.channels["contact_10"].max() == pytest.approx(230.5, abs=0.5)
    assert namespace["energy_error"] < 1e-4


@pytest.mark.slow  # default-suite time on 2 cores; the first example stays in the default suite; sweeps are tested in tests/test_sweep.py
def test_02_sweep_velocity_wall(small):
    namespace = _run("02_sweep_velocity_wall.py")
    assert (small / "02_force_ratio.png").stat().st_size > 20_000
    ratio = namespace["ratio"]
    assert ratio.shape == (2, 3)
    np.testing.assert_allclose(ratio[0], ratio[1], rtol=1e-4)  # amplitude independent
    assert np.all(np.diff(ratio[0]) > 0)
    # The paper's Eq. 5 lies 6-15 % below the simulated ratio for these walls.
    gap = namespace["estimate"] / ratio[0] - 1.0
    assert np.all((gap < -0.05) & (gap > -0.16))
    rows = (small / "02_force_ratio.csv").read_text().splitlines()
    assert len(rows) == 1 + 6


@pytest.mark.slow  # one fit through the simulator: about 40 s of CPU at the small size
def test_03_fit_traces(small):
    namespace = _run("03_fit_traces.py")
    result = namespace["result"]
    assert result.converged
    assert result.reduced_chi2 == pytest.approx(1.0, abs=0.1)
    for label, true in (("eta_s", 1.7e-6), ("mu", 0.12)):
        assert abs(result.values[label] - true) < 4 * result.stderr[label]
    assert result.values["C"] == pytest.approx(201.385, abs=0.1)
    assert (small / "03_fit" / "fit.json").exists()


@pytest.mark.slow  # a diagnosis through the simulator: about 2 min of CPU at the small size
def test_04_diagnose(small):
    namespace = _run("04_diagnose.py")
    diagnosis = namespace["diagnosis"]
    assert diagnosis.missing_effects == ["wall_compliance"]
    assert not diagnosis.misspecification
    assert (small / "04_diagnosis").is_dir() and any((small / "04_diagnosis").iterdir())


@pytest.mark.slow  # a fit and a diagnosis through the simulator: about 2 min of CPU at the small size
def test_06_scope_files(small):
    namespace = _run("06_scope_files.py")
    result, truth = namespace["result"], namespace["truth"]
    assert result.converged and result.reduced_chi2 == pytest.approx(1.0, abs=0.15)
    # the stick-slip loss has kinks: mu's local standard error understates its scatter
    assert result.values["eta_s"] == pytest.approx(truth["eta_s"], rel=0.02)
    assert result.values["mu"] == pytest.approx(truth["mu"], rel=0.05)
    diagnosis = namespace["diagnosis"]
    assert set(diagnosis.missing_effects) == {"viscous_damping", "track_friction"}
    assert (small / "06_scope_files" / "fit" / "fit.json").exists()
    assert (small / "06_scope_files" / "diagnosis").is_dir()


def test_lydon_reproduce_refuses_an_unknown_part(capsys):
    """`reproduce.py --only` names the parts it knows when given another (before any run)."""
    reproduce = runpy.run_path(str(EXAMPLES / "lydon2015" / "reproduce.py"))
    with pytest.raises(SystemExit) as stop:
        reproduce["main"](["--data-root", "nowhere", "--only", "two_beads_diagnosis"])
    assert stop.value.code == 2
    err = capsys.readouterr().err
    assert "unknown two_beads_diagnosis" in err and "two_bead_bending_diagnosis" in err and "lydon2014_band_edge" in err


def test_lydon_reproduce_builds_command_lines_its_scripts_parse(monkeypatch, capsys, tmp_path):
    """`reproduce.py --dry-run` runs nothing, and each lab script's parser takes the command line
    built for it (stopped right after parsing)."""
    folder = EXAMPLES / "lydon2015"
    monkeypatch.syspath_prepend(str(folder))
    reproduce = runpy.run_path(str(folder / "reproduce.py"))
    commands = reproduce["main"](["--data-root", "data", "--out", str(tmp_path), "--dry-run"])["commands"]
    assert set(reproduce["SCRIPTS"]) <= set(commands) and not any(tmp_path.iterdir())
    for name in ("two_bead_end_compliance", "tongue_drive_transfer", "micro_slip_floquet_tongue"):
        script, *arguments = commands[name]
        assert arguments[arguments.index("--out") + 1] == str(tmp_path / name)
        parsed = []
        original = argparse.ArgumentParser.parse_args

        def stop(parser, args=None, namespace=None, parsed=parsed, original=original):
            parsed.append(original(parser, args, namespace))
            raise RuntimeError("parsed")

        monkeypatch.setattr(argparse.ArgumentParser, "parse_args", stop)
        with pytest.raises(RuntimeError, match="parsed"):
            runpy.run_path(script)["main"](arguments)
        monkeypatch.setattr(argparse.ArgumentParser, "parse_args", original)
        assert parsed[0].out == str(tmp_path / name) and parsed[0].data_dir == str(Path("data") / "lydon-2015")
