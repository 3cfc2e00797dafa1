"""Setup values checked where they enter: ranges with unit hints, the stability bound of the
step for the damping given, and the size of a run before it starts."""

import numpy as np
import pytest

import hertzchain as hc
from hertzchain.chain import LAW_ATTRIBUTES
from hertzchain.batched import solve_batched
from hertzchain.cli import main as cli_main
from hertzchain.integrate import Recording, batch_setup
from hertzchain.validation import (
    MAX_BODY_STEPS,
    RULES,
    check_plausible,
    check_run_size,
    damping_rate_1_s,
    estimate_run_size,
    yield_notice,
    yield_velocity_m_s,
)

N_BEADS = 5
DT_S = 4e-7


@pytest.mark.parametrize(
    "name, value, match",
    [
        ("eta_s", 2.0, r"eta_s = 2.0 is outside the plausible range .* viscoelastic damping .*did you mean 2us\?"),
        ("bead_radius_m", 13.0, "did you mean 13mm"),
        ("bead_youngs_pa", 203.0, "did you mean 203GPa"),
        ("bead_poisson", 0.7, r"bead_poisson must be in \(-1, 0.5\), got 0.7"),
        ("wall_poisson", -1.0, r"wall_poisson must be in \(-1, 0.5\)"),
        ("mu", -0.1, "mu must be non-negative"),
        ("dashpot_n_s_m", -5.0, "dashpot_n_s_m must be non-negative"),
        ("wall_youngs_pa", 0.0, r"wall_youngs_pa must be positive \(Pa; inf = rigid\)"),
        ("striker_velocity_m_s", -0.3, "striker_velocity_m_s must be positive"),
    ],
)
def test_ranges_name_the_field_value_and_likely_unit(name, value, match):
    with pytest.raises(ValueError, match=match):
        check_plausible(name, value)


def test_every_setup_field_has_a_rule_and_construction_applies_it():
    setup = hc.ChainSetup(3)
    # the law objects' coefficients are checked by the laws, and those ChainSetup names
    # (eta_s, dashpot_n_s_m, a power law's exponent) by RULES through its properties
    numeric = [name for name in setup.__dataclass_fields__ if name not in ("end", "sensor_beads", "contact_law",
                                                                          "dissipation")]
    assert sorted(set(numeric) - set(RULES)) == []
    assert sorted(set(LAW_ATTRIBUTES) - set(RULES)) == []
    for name in ("bead_poisson", "mu", "eta_s", "wall_youngs_pa"):
        bad = {"bead_poisson": 0.7, "mu": -0.1, "eta_s": -1e-6, "wall_youngs_pa": 0.0}[name]
        with pytest.raises(ValueError, match=name):
            hc.ChainSetup(3, **{name: bad})
    for value in (np.inf, 2e11):  # a rigid wall and a finite one are allowed
        hc.ChainSetup(3, wall_youngs_pa=value)


def _peaks_n(field, values, dt_s):
    """Largest wall force and largest force anywhere of chains with `field` = each of `values`
    (one batched run, on the sweeps' kernel), N."""
    batched, _ = batch_setup(hc.ChainSetup(N_BEADS), **{field: values})
    grid = hc.choose_time_grid(hc.ChainSetup(N_BEADS), t_end_s=0.3e-3, sample_interval_s=2e-6, dt_s=dt_s)
    out = solve_batched(batched, grid, Recording(()))
    return np.max(np.asarray(out.forces_n["wall"]), axis=1), np.max(np.asarray(out.max_force_n), axis=1)


def _dashpot_bound_n_s_m():
    # an interior bead touches two dashpots: Gershgorin row sum 4 gamma / m, stable below 1/dt
    return float(hc.ChainSetup(N_BEADS).bead_mass_kg[0]) / (4.0 * DT_S)


def test_dashpot_stability_bound_against_runs_inside_and_beyond_it():
    """The bound lambda_max dt < 1: a chain just inside it runs, one beyond it blows up; a
    step refused names the stable step."""
    bound = _dashpot_bound_n_s_m()
    np.testing.assert_allclose(damping_rate_1_s(hc.ChainSetup(N_BEADS, dashpot_n_s_m=1.0)) * DT_S,
                               1.0 / bound, rtol=1e-12)
    (inside, beyond), _ = _peaks_n("dashpot_n_s_m", [0.9 * bound, 4.0 * bound], DT_S)
    assert 100.0 < inside < 2000.0 and beyond > 1000.0 * inside
    with pytest.raises(ValueError, match=r"dashpot_n_s_m = .* beyond the stability of the time step.*dt_s <"):
        hc.simulate(hc.ChainSetup(N_BEADS, dashpot_n_s_m=1.1 * bound), t_end_s=0.1e-3, sample_interval_s=2e-6,
                    dt_s=DT_S)


@pytest.mark.slow  # two more compiled programs (a step four times smaller)
def test_dashpot_stability_bound_is_where_the_step_stops_converging():
    """Just inside the bound the wall's peak force agrees with a step four times smaller;
    at 1.5 times the bound it is off by more than 30 %."""
    values = [0.9 * _dashpot_bound_n_s_m(), 1.5 * _dashpot_bound_n_s_m()]
    coarse, fine = _peaks_n("dashpot_n_s_m", values, DT_S)[0], _peaks_n("dashpot_n_s_m", values, DT_S / 4)[0]
    error = np.abs(coarse / fine - 1)
    assert error[0] < 0.01 and error[1] > 0.3, error


def test_eta_far_beyond_the_bound_blows_up_and_is_refused_with_the_unit_hint():
    rate_per_eta = damping_rate_1_s(hc.ChainSetup(N_BEADS, eta_s=1.0))
    bound = 1.0 / (rate_per_eta * DT_S)
    _, largest = _peaks_n("eta_s", [0.9 * bound, 100 * bound], DT_S)
    assert np.isfinite(largest[0]) and not np.isfinite(largest[1])
    with pytest.raises(ValueError, match=r"eta_s = 2 s \(did you mean 2us\?\) is beyond the stability"):
        hc.simulate(hc.ChainSetup(N_BEADS, eta_s=2.0), t_end_s=0.1e-3, sample_interval_s=2e-6)


def test_size_guard_refuses_before_running_and_names_the_option():
    size = estimate_run_size(n_runs_in_memory=1, n_runs=1, n_bodies=22, n_channels=90, n_samples=10**9, n_steps=10**9)
    with pytest.raises(ValueError, match=r"GiB .* more than the .* available: shorten --t-end.* --yes"):
        check_run_size(size, memory_bytes=2**30)
    many = estimate_run_size(n_runs_in_memory=8, n_runs=10**8, n_bodies=22, n_channels=3, n_samples=2000,
                             n_steps=6000)
    assert many.body_steps > MAX_BODY_STEPS
    with pytest.raises(ValueError, match="bead-steps .* or add --yes"):
        check_run_size(many, memory_bytes=2**40)


def test_cli_refuses_implausible_and_oversized_runs(tmp_path, capsys):
    out = tmp_path / "s"
    assert cli_main(["simulate", "--n-beads", "5", "--eta", "2", "--out", str(out)]) == 2
    assert "--eta: eta_s = 2.0 is outside the plausible range" in capsys.readouterr().err
    assert cli_main(["simulate", "--n-beads", "5", "--t-end", "1e3", "--out", str(out)]) == 2
    assert "add --yes" in capsys.readouterr().err
    assert cli_main(["sweep", "--n-beads", "5", "--grid", "eta_s=-1e-6,1e-6", "--out", str(out)]) == 2
    assert "--grid: eta_s must be non-negative (s), got [-1e-06, 1e-06]" in capsys.readouterr().err
    assert cli_main(["sweep", "--n-beads", "5", "--grid", "striker_velocity_m_s=0.1:1:10000",
                     "--grid", "eta_s=0:1e-6:10000", "--out", str(out)]) == 2
    assert "add --yes" in capsys.readouterr().err  # 1e8 runs: their table alone exceeds the memory
    assert not out.exists()
    # the commands that run many shots: synth (one file a velocity) and sensitivity (tangents)
    assert cli_main(["synth", "--n-beads", "5", "--t-end", "1e3", "--out", str(out)]) == 2
    assert "add --yes" in capsys.readouterr().err
    assert cli_main(["sensitivity", "--n-beads", "5", "--params", "eta_s", "--observables", "wall_peak",
                     "--t-end", "1e3", "--out", str(out)]) == 2
    assert "add --yes" in capsys.readouterr().err
    assert not out.exists()


def test_yield_velocity_is_where_the_hertz_collision_reaches_the_yield_force():
    setup = hc.ChainSetup(3)
    v_yield = yield_velocity_m_s(setup)
    m = float(setup.bead_mass_kg[0])
    kappa = float(setup.contact_kappa()[0])
    overlap = (5.0 * (m / 2) * v_yield**2 / (4.0 * kappa)) ** 0.4  # 1/2 m* v^2 = 2/5 kappa d^5/2
    np.testing.assert_allclose(kappa * overlap**1.5, float(setup.contact_yield_force_n()[0]), rtol=1e-10)
    notice = yield_notice(setup, [0.5 * v_yield, 2.0 * v_yield], what="shots")
    assert notice.startswith(f"shots at {2 * v_yield:g} m/s exceed the yield force of contact 0")
    assert "--plasticity thornton" in notice
    assert yield_notice(setup, [0.5 * v_yield]) is None
    assert yield_notice(hc.ChainSetup(3, plasticity=True), [2.0 * v_yield]) is None
