import json

import numpy as np
import pytest

from hertzchain.cli import main
from hertzchain.tracefile import read_trace


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
    assert "peak wall" in capsys.readouterr().out


@pytest.mark.parametrize(
    "arguments, message",
    [
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
