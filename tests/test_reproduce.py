"""The reproduction of the paper (quick run): its numbers against the paper's own agreement
and against independent reference numbers (adaptive DOP853 solutions of the same chains).
"""

import json
import math

import numpy as np
import pytest

import hertzchain as hc
from hertzchain import theory
from hertzchain.cli import main
from hertzchain.paper import batch, experiments
from hertzchain.paper.reproduce import reproduce


@pytest.fixture(scope="module")
def quick(tmp_path_factory):
    out = tmp_path_factory.mktemp("reproduce")
    numbers = reproduce(out, quick=True, progress=False)
    return out, numbers


def test_writes_every_figure_its_data_and_the_tables(quick):
    out, numbers = quick
    for name in ("fig1.png", "fig2.png", "fig3.png"):
        data = (out / name).read_bytes()
        assert data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) > 20_000
    for name in ("fig1.csv", "fig2_speed_duration.csv", "fig2_restitution.csv",
                 "fig3_walls.csv", "fig3_traces.csv"):
        header = (out / name).read_text().splitlines()[0]
        assert "," in header
    on_disk = json.loads((out / "numbers.json").read_text())
    assert on_disk["C_numeric"] == pytest.approx(numbers["C_numeric"], rel=1e-12)
    for key in ("kappa_N_per_um15", "C_theory", "C_numeric", "kinetic_fraction",
                "yield_force_N", "yield_overlap_um"):
        assert isinstance(on_disk[key], float)
    names = {"plexiglass", "Mg", "Cu", "Si", "Fe", "W"}
    assert names <= set(on_disk["force_ratio"]) and names <= set(on_disk["wall_materials"])
    assert on_disk["wall_materials"]["Cu"] == {"youngs_pa": 130e9, "poisson": 0.34}
    table = (out / "numbers.md").read_text()
    for row in numbers["rows"]:
        assert row["quantity"] in table
    shortcuts = table.split("## Where the paper's approximations fail")[1].split("## Definitions")[0]
    assert "**Eq. 5**" in shortcuts and "**eta from C_v**" in shortcuts
    # fig2_speed_duration.csv: one row per (velocity, eta, mu) run.
    rows = (out / "fig2_speed_duration.csv").read_text().splitlines()
    assert len(rows) == 1 + 4 * len(experiments.QUICK_PLAN.velocities_m_s)


def test_constants_within_the_papers_agreement(quick):
    _, n = quick
    assert n["kappa_N_per_um15"] == pytest.approx(12.0, rel=0.01)
    assert n["kappa_N_per_um15"] == pytest.approx(11.9900, abs=1e-3)
    assert n["C_theory"] == pytest.approx(198.9, abs=0.05)
    # The paper: C_n = 201.5 +- 0.1; with the stated definition the discrete chain gives
    # 201.3675 (independent adaptive DOP853 solver, contacts 8-15, `pulses.incident_wave`).
    assert n["C_numeric"] == pytest.approx(201.5, rel=0.005)
    assert n["C_numeric"] == pytest.approx(201.3675, abs=0.05)
    assert n["C_numeric_fit_amplitude"] == pytest.approx(201.62, abs=0.05)
    assert n["C_numeric_exponent"] == pytest.approx(1.0 / 6.0, abs=1e-4)
    assert n["yield_force_N"] == pytest.approx(470.0, rel=0.02)
    assert n["yield_overlap_um"] == pytest.approx(11.0, rel=0.07)


def test_energy_split_of_the_travelling_wave(quick):
    _, n = quick
    assert abs(n["kinetic_fraction"] - 0.56) < 0.02  # paper: "about 56 %"
    assert n["kinetic_fraction"] == pytest.approx(5.0 / 9.0, abs=0.003)
    assert n["bead_energy_over_wave"] == pytest.approx(0.382, abs=0.005)


def test_force_ratio_follows_eq5_trend_and_eq5_lies_below(quick):
    _, n = quick
    ratio, eq5, walls = n["force_ratio"], n["force_ratio_eq5"], n["wall_materials"]
    finite = sorted((w for w in walls if walls[w]["youngs_pa"] != "inf"),
                    key=lambda w: walls[w]["youngs_pa"])
    simulated = [ratio[w] for w in finite]
    assert np.all(np.diff(simulated) > 0) and ratio["rigid"] > max(simulated)
    assert np.all(np.diff([eq5[w] for w in finite]) > 0)
    # The estimate is 10-15 % below the simulation from 3 to 211 GPa, 6 % below for W,
    # and 2.7 % above for a rigid wall.
    for w in finite:
        gap = eq5[w] / ratio[w] - 1.0
        if walls[w]["youngs_pa"] <= 211e9:
            assert -0.16 < gap < -0.10, (w, gap)
    assert eq5["W"] / ratio["W"] - 1.0 == pytest.approx(-0.061, abs=0.01)
    assert eq5["rigid"] / ratio["rigid"] - 1.0 == pytest.approx(0.027, abs=0.005)
    # Independent reference numbers (adaptive DOP853 solution), +-0.003.
    for wall, expected in (("plexiglass", 0.4979), ("soft_5GPa", 0.6001), ("Mg", 1.3560),
                           ("Cu", 1.8169), ("steel", 1.9433), ("W", 2.0844), ("rigid", 2.2377)):
        assert ratio[wall] == pytest.approx(expected, abs=0.003)
    # theory.WALL_FORCE_CORRECTION (used by fitting.start) is the steel wall's ratio.
    assert ratio["steel"] / eq5["steel"] == pytest.approx(theory.WALL_FORCE_CORRECTION, abs=0.002)


def test_secondary_waves_for_the_soft_wall_only(quick):
    _, n = quick
    secondary = n["secondary_wave"]
    assert secondary["soft_5GPa"] == pytest.approx(0.226, abs=0.005)
    assert secondary["plexiglass"] > 0.15
    for wall in ("steel", "Fe", "W", "rigid", "Cu"):
        assert secondary[wall] < 0.05


def test_momentum_at_the_wall_balances_to_two_percent(quick):
    _, n = quick
    momentum = n["momentum_ratio"]
    assert momentum["rigid"] == pytest.approx(1.0149, abs=0.003)
    assert momentum["steel"] == pytest.approx(1.0187, abs=0.003)
    assert momentum["soft_5GPa"] == pytest.approx(1.038, abs=0.004)


def test_dissipation_and_the_papers_conversions(quick):
    _, n = quick
    r = n["restitution"]
    assert r["viscous_eta2us"]["C_v"] == pytest.approx(0.0082, abs=0.0004)
    assert r["friction_mu019"]["C_s"] == pytest.approx(0.1145, abs=0.003)
    # The paper's conversions do not hold for its own model: eta = 2 us would give
    # C_v = 0.0245 (3x the fitted one), mu = 0.19 a C_s of 0.167 (1.46x).
    c_v_ratio = r["paper_conversion_C_v_for_eta2us"] / r["viscous_eta2us"]["C_v"]
    c_s_ratio = r["paper_conversion_C_s_for_mu019"] / r["friction_mu019"]["C_s"]
    assert c_v_ratio == pytest.approx(3.0, abs=0.2)
    assert c_s_ratio == pytest.approx(1.46, abs=0.05)
    # The corrections fitting.start applies to the paper's conversions.
    assert 1.0 / c_v_ratio == pytest.approx(theory.VISCOUS_CONVERSION_CORRECTION, rel=0.05)
    assert 1.0 / c_s_ratio == pytest.approx(theory.FRICTION_CONVERSION_CORRECTION, rel=0.02)
    broadening = n["duration_broadening_eta2us"]
    top = max(broadening, key=lambda key: float(key.rstrip("N")))
    assert broadening[top] == pytest.approx(1.097, abs=0.003)  # paper: about 10 %
    assert n["duration_over_theory"] == pytest.approx(0.962, abs=0.003)
    # every duration and fitted amplitude comes from a converged cos^6 fit
    assert n["cos6_fits_converged"]["converged"] == n["cos6_fits_converged"]["of"] > 0
    assert n["C_apparent_eta2us"] > n["C_numeric"] + 3.0


def test_embedded_sensor_and_its_deconvolution(quick):
    _, n = quick
    assert n["sensor_peak_ratio"] == pytest.approx(0.9217, abs=0.002)
    assert n["sensor_deconvolution_error"]["incident"] < 1e-2
    assert n["sensor_deconvolution_error"]["incident_eta2us"] < 1e-2


def test_rows_hold_ours_paper_and_relative_difference(quick):
    _, n = quick
    rows = {row["key"]: row for row in n["rows"]}
    c_n = rows["C_numeric"]
    assert c_n["paper"] == 201.5
    # against the independent reference 201.3675 (adaptive DOP853 solver)
    assert c_n["relative_difference"] == pytest.approx(201.3675 / 201.5 - 1.0, abs=2.5e-4)
    assert rows["force_ratio.Cu"]["paper"] == pytest.approx(n["force_ratio_eq5"]["Cu"])
    assert rows["secondary_wave.steel"]["relative_difference"] is None


def test_cli_prints_the_table(monkeypatch, capsys, tmp_path, quick):
    _, numbers = quick
    calls = []

    def fake(out, *, quick):
        calls.append((out, quick))
        return numbers

    monkeypatch.setattr("hertzchain.cli.reproduce.reproduce", fake)
    assert main(["reproduce", "--quick", "--out", str(tmp_path)]) == 0
    assert calls == [(tmp_path, True)]
    printed = capsys.readouterr().out
    assert "C_n, dissipationless simulation" in printed and "paper" in printed


def test_plan_and_batch_inputs_are_checked():
    with pytest.raises(ValueError, match="0.3 m/s"):
        experiments.Plan(velocities_m_s=(0.1, 0.2), wall_sweep_pa=())
    with pytest.raises(ValueError, match="n_beads, end or sensor_beads"):
        batch.stack_setups([hc.ChainSetup(5), hc.ChainSetup(6)])
    with pytest.raises(ValueError, match="empty"):
        batch.stack_setups([])


@pytest.mark.slow  # default-suite time on 2 cores; `pytest -m slow` runs it
def test_batch_of_setups_equals_single_runs():
    setups = [hc.ChainSetup(5, striker_velocity_m_s=0.2, wall_youngs_pa=5e9, wall_poisson=0.35),
              hc.ChainSetup(5, striker_velocity_m_s=0.3, eta_s=2e-6)]
    both = batch.run_setups(setups, t_end_s=4e-4, contacts=(2,))
    grid = batch.batch_time_grid(setups, t_end_s=4e-4, sample_interval_s=1e-6)
    for i, setup in enumerate(setups):
        single = hc.simulate(setup, t_end_s=4e-4, contacts=(2,), dt_s=grid.dt_s)
        np.testing.assert_allclose(np.asarray(both.forces_n["wall"][i]),
                                   np.asarray(single.forces_n["wall"]), rtol=1e-10, atol=1e-9)
        assert math.isclose(float(both.initial_energy_j[i]), float(single.initial_energy_j),
                            rel_tol=1e-12)
