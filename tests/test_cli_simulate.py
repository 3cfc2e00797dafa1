import contextlib
import json

import numpy as np
import pytest

from hertzchain.cli import main
from hertzchain.io.tracefile import read_trace


def test_simulate_writes_traces_summary_and_plot(tmp_path, capsys):
    out = tmp_path / "run"
    code = main([
        "simulate", "--n-beads", "12", "--striker-velocity", "0.2", "--eta", "2us",
        "--wall-youngs", "5GPa", "--contacts", "3,6", "--t-end", "1.5ms", "--out", str(out),
    ])
    assert code == 0
    trace = read_trace(out / "traces.csv")
    assert trace.channel_names == ("contact_3", "contact_6", "wall")
    assert trace.header["wall_youngs_pa"] == pytest.approx(5e9)
    summary = json.loads((out / "summary.json").read_text())
    assert summary["setup"]["eta_s"] == pytest.approx(2e-6)
    assert summary["kappa_n_per_um1p5"]["contacts"][1] == pytest.approx(11.99, abs=0.01)
    assert summary["peak_force_n"]["wall"] == pytest.approx(float(np.max(trace.channels["wall"])))
    assert summary["energy_balance"]["max_relative_error"] < 1e-4
    assert summary["energy_balance"]["dissipated_viscous_j"] > 0
    assert (out / "simulation.png").stat().st_size > 10_000
    first = capsys.readouterr()
    assert "peak wall" in first.out and "replaced" not in first.err
    assert main(["simulate", "--n-beads", "12", "--t-end", "0.5ms", "--out", str(out)]) == 0  # a rerun says so
    assert capsys.readouterr().err.splitlines()[-1] == f"hertzchain simulate: replaced the results of an earlier run in {out}"


@pytest.mark.slow  # default-suite time on 2 cores; each law against the reference solver stays in the default suite (tests/test_batched.py)
def test_simulate_contact_law_options(tmp_path):
    """--plasticity, --contact-exponent and --dashpot reach the chain: a fast striker on
    beads of low yield stress (the elastic model warns) dissipates plastically and loads the
    wall less; a stiffer
    exponent and a dashpot change the wall's peak; the energy books still balance."""
    from hertzchain.integrate import YieldWarning

    def run(name, *options):
        out = tmp_path / name
        # elastic contacts past the yield force: the model says it does not describe them
        elastic = "--plasticity" not in options
        with pytest.warns(YieldWarning, match="above its yield force") if elastic else contextlib.nullcontext():
            assert main(["simulate", "--n-beads", "8", "--striker-velocity", "1", "--bead-yield-stress", "0.4GPa",
                         "--t-end", "0.6ms", "--out", str(out), *options]) == 0
        return json.loads((out / "summary.json").read_text())

    hertz = run("hertz")
    plastic = run("plastic", "--plasticity", "jackson_green")
    assert plastic["setup"]["contact_law"]["class"] == "JacksonGreen"
    assert plastic["energy_balance"]["dissipated_plastic_j"] > 0.05 * plastic["energy_balance"]["initial_energy_j"]
    assert plastic["peak_force_n"]["wall"] < 0.9 * hertz["peak_force_n"]["wall"]
    other = run("other", "--contact-exponent", "1.7", "--dashpot", "5Ns/m")
    assert other["setup"]["contact_exponent"] == pytest.approx(1.7)
    assert other["setup"]["dashpot_n_s_m"] == pytest.approx(5.0)
    assert other["energy_balance"]["dissipated_viscous_j"] > 0
    assert other["peak_force_n"]["wall"] != pytest.approx(hertz["peak_force_n"]["wall"], rel=1e-3)
    for summary in (plastic, other):
        assert summary["energy_balance"]["max_relative_error"] < 1e-4


@pytest.mark.parametrize(
    "arguments, message",
    [
        (["--plasticity", "jackson_green", "--contact-exponent", "1.7"], "cannot be combined"),
        (["--bead-radius", "13"], "bead_radius_m = 13.0 is outside the plausible range"),
        (["--striker-velocity", "-1"], "striker_velocity_m_s must be positive"),
        (["--eta", "2 parsecs"], "--eta: unit 'parsecs'"),
        (["--dt", "1e-4"], "cannot resolve the shortest contact"),
        (["--contacts", "30"], "contact 30 is not in the chain"),
    ],
)
def test_simulate_bad_input_is_a_clear_error(tmp_path, capsys, arguments, message):
    assert main(["simulate", "--out", str(tmp_path), *arguments]) == 2
    assert message in capsys.readouterr().err
    assert not (tmp_path / "traces.csv").exists()
