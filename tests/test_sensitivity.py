"""Sensitivities by automatic differentiation against finite differences, theory and the CLI."""

import json
import math

import jax.numpy as jnp
import numpy as np
import pytest
from helpers import rerun_at_the_default_xla_level

import hertzchain as hc
from hertzchain import sensitivity as S

SCALAR_OBS = (
    "contact_2_peak", "wall_peak", "contact_2_arrival", "contact_5_peak_time",
    "contact_2_duration", "speed_2_5", "force_ratio_5", "sensor_3_peak", "wall_arrival",
    "dissipated_viscous",
)
PEAK_LIKE = ("peak", "arrival", "peak_time", "duration", "speed", "force_ratio")


def _central_differences(setup, params, observables, grid, rel_step, mode="forward"):
    """Central differences of the simulator on `grid` (the values come from the same compiled
    function as the derivatives, evaluated at perturbed parameters)."""
    parsed = tuple(S.parse_observable(setup, o) for o in observables)
    v0 = {k: np.asarray(v, dtype=float) for k, v in S.parameter_values(setup, params).items()}
    fd = {}
    for p in params:
        for idx in np.ndindex(*v0[p].shape):
            h = rel_step * abs(v0[p][idx])
            values = []
            for sign in (1.0, -1.0):
                w = {k: v.copy() for k, v in v0.items()}
                w[p][idx] += sign * h
                out, valid, _ = S.jacobian_at(
                    {k: jnp.asarray(v) for k, v in w.items()}, setup, tuple(params), parsed, grid, mode
                )
                assert all(bool(valid[o]) for o in observables)
                values.append(out)
            for o in observables:
                fd[(o, p, idx)] = (np.asarray(values[0][o]) - np.asarray(values[1][o])) / (2 * h)
    return fd


def _check_against_fd(result, fd, *, rtol_smooth=1e-4, rtol_peak=1e-3):
    failures = []
    for (o, p, idx), numeric in fd.items():
        exact = np.asarray(result.derivative[o][p])
        exact = exact[(Ellipsis,) + idx] if idx else exact
        if o.startswith("trace_"):
            error = np.max(np.abs(numeric - exact)) / np.max(np.abs(exact))
            tol = rtol_smooth
        else:
            value = float(result.values[o])
            pv = float(np.asarray(result.param_values[p])[idx])
            # relative to the derivative, plus an absolute floor of 1e-8 in elasticity
            # (derivatives of 1e-100, or 1e-9 in elasticity, that finite differences of a
            # float64 simulation see as 0)
            tol = rtol_peak if any(k in o for k in PEAK_LIKE) else rtol_smooth
            error = tol * abs(numeric - exact) / (tol * abs(exact) + 1e-8 * abs(value / pv))
        if not error < tol:
            failures.append(f"{o} / {p}{list(idx) if idx else ''}: AD {exact} FD {numeric} err {error:.2e}")
    assert not failures, "\n".join(failures)


@pytest.fixture(scope="module")
def smooth_setup():
    """8 beads, viscous damping, thwarted rotation, a softer wall and an embedded sensor: contacts
    open and close (ejection at the striker end, the wall contact opens and recloses)."""
    return hc.ChainSetup(
        8, eta_s=1.0e-6, mu_star=0.03, wall_youngs_pa=45e9, sensor_beads=(3,),
        striker_velocity_m_s=0.2,
    )


@pytest.fixture(scope="module")
def smooth_grid(smooth_setup):
    return hc.choose_time_grid(smooth_setup, t_end_s=0.7e-3, sample_interval_s=2e-6, steps_per_contact=60)


PARAMS_ALL = (
    "eta_s", "mu_star", "striker_velocity_m_s", "striker_mass_kg", "wall_youngs_pa", "wall_poisson",
    "bead_radius_m", "bead_density_kg_m3", "bead_youngs_pa", "bead_poisson", "sensor_beta", "sensor_f0_hz",
)


PARAMS_DEFAULT = ("eta_s", "mu_star", "striker_velocity_m_s", "wall_youngs_pa", "bead_radius_m", "sensor_f0_hz")


def test_derivatives_match_finite_differences(smooth_setup, smooth_grid):
    observables = SCALAR_OBS + ("trace_wall",)
    result = S.sensitivity(smooth_setup, PARAMS_DEFAULT, observables, grid=smooth_grid)
    assert result.mode == "forward"  # a whole trace has more values than there are parameters
    fd = _central_differences(smooth_setup, PARAMS_DEFAULT, observables, smooth_grid, 1e-6)
    _check_against_fd(result, fd)
    # a few physical signs: damping lowers the wall peak, a stiffer wall raises it
    assert result.derivative["wall_peak"]["eta_s"] < 0
    assert result.derivative["wall_peak"]["wall_youngs_pa"] > 0
    assert abs(result.elasticity["contact_2_peak"]["wall_youngs_pa"]) < 1e-30  # before the wall is hit


@pytest.mark.slow
def test_every_parameter_matches_finite_differences(smooth_setup, smooth_grid):
    """At XLA's default optimisation level (at the suite's level 0 the central difference of a
    sensor's peak by a bead's mass, a difference of rounded peaks, came out of the wrong sign)."""
    if rerun_at_the_default_xla_level(__file__, "test_every_parameter_matches_finite_differences"):
        return
    observables = SCALAR_OBS + ("trace_wall",)
    result = S.sensitivity(smooth_setup, PARAMS_ALL, observables, grid=smooth_grid)
    fd = _central_differences(smooth_setup, PARAMS_ALL, observables, smooth_grid, 1e-6)
    _check_against_fd(result, fd)
    few = ("wall_peak", "contact_5_arrival", "sensor_3_peak", "dissipated_viscous")
    masses = S.sensitivity(smooth_setup, ("bead_masses_kg",), few, grid=smooth_grid)
    assert masses.mode == "reverse"  # 4 observables, 8 masses
    fd = _central_differences(smooth_setup, ("bead_masses_kg",), few, smooth_grid, 1e-6, "reverse")
    _check_against_fd(masses, fd)


@pytest.mark.slow
def test_reverse_mode_equals_forward_for_per_bead_masses():
    setup = hc.ChainSetup(6, eta_s=1e-6, wall_youngs_pa=45e9)
    observables = ("wall_peak", "contact_3_arrival", "dissipated_viscous")
    kwargs = dict(t_end_s=0.5e-3, sample_interval_s=2e-6, steps_per_contact=40)
    reverse = S.sensitivity(setup, ("bead_masses_kg", "eta_s"), observables, **kwargs)
    assert reverse.mode == "reverse"  # 3 observables, 7 parameter values
    forward = S.sensitivity(setup, ("bead_masses_kg", "eta_s"), observables, mode="forward", **kwargs)
    for o in observables:
        for p in ("bead_masses_kg", "eta_s"):
            np.testing.assert_allclose(reverse.derivative[o][p], forward.derivative[o][p], rtol=1e-9)
    assert reverse.derivative["wall_peak"]["bead_masses_kg"].shape == (6,)
    # a heavier bead 1 (hit by the striker) delays the pulse; the last bead barely matters
    # before the pulse has reached it (only the pulse's leading tail touches it)
    e = reverse.elasticity["contact_3_arrival"]["bead_masses_kg"]
    assert e[0] > 0 and abs(e[-1]) < 1e-3 * e[0]


@pytest.mark.slow
def test_track_friction_on_the_incident_pulse():
    """Coulomb friction (exact stick-slip): derivatives along the incident pulse."""
    setup = hc.ChainSetup(8, eta_s=1e-6, mu=0.2, striker_velocity_m_s=0.05, end="free")
    grid = hc.choose_time_grid(setup, t_end_s=0.5e-3, sample_interval_s=2e-6, steps_per_contact=60)
    params = ("mu", "eta_s", "striker_velocity_m_s")
    observables = ("contact_2_peak", "contact_5_arrival", "contact_2_duration", "dissipated_friction")
    result = S.sensitivity(setup, params, observables, grid=grid)
    fd = _central_differences(setup, params, observables, grid, 1e-7)
    _check_against_fd(result, fd, rtol_smooth=1e-3)
    assert result.derivative["dissipated_friction"]["mu"] > 0
    assert result.derivative["contact_2_peak"]["mu"] < 0


def test_scaling_symmetry_gives_exact_elasticities():
    """Dissipationless chain: F(t; lambda kappa, V) = lambda^-2 F(t; kappa, lambda^2 V) and forces
    scale as V^(6/5), times as V^(-1/5): elasticities 6/5, -1/5, 1/5 in V, and 2/5, -2/5 in the
    stiffness scale (1 + mu*)."""
    setup = hc.ChainSetup(10, mu_star=0.1, striker_velocity_m_s=0.3)
    observables = ("contact_6_peak", "wall_peak", "contact_6_arrival", "contact_6_peak_time", "speed_3_7")
    result = S.sensitivity(setup, ("striker_velocity_m_s", "mu_star"), observables,
                           t_end_s=0.6e-3, sample_interval_s=0.25e-6)
    e = result.elasticity
    stiffness = 0.1 / 1.1  # d ln(1 + mu*) / d ln mu*
    for o, (ev, ek) in {
        "contact_6_peak": (1.2, 0.4), "wall_peak": (1.2, 0.4), "contact_6_arrival": (-0.2, -0.4),
        "contact_6_peak_time": (-0.2, -0.4), "speed_3_7": (0.2, 0.4),
    }.items():
        # (sampling at 0.25 us and the interpolated peaks/crossings leave ~1e-4; a speed is a
        # ratio of a time difference, which amplifies it)
        tol = 1e-3 if o.startswith("speed") else 2e-4
        assert e[o]["striker_velocity_m_s"] == pytest.approx(ev, abs=tol), o
        assert e[o]["mu_star"] == pytest.approx(ek * stiffness, abs=1e-4), o


@pytest.mark.slow
def test_sweep_matches_single_points_and_eq5_trend():
    setup = hc.ChainSetup(8)
    sweep = {"striker_velocity_m_s": [0.1, 0.4], "wall_youngs_pa": [5e9, 2.03e11]}
    observables = ("force_ratio_4", "wall_peak")
    result = S.sensitivity_sweep(setup, ("wall_youngs_pa", "striker_velocity_m_s"), observables, sweep,
                                 t_end_s=0.9e-3, sample_interval_s=1e-6, chunk_size=3, progress=False)
    assert result.grid_shape == (2, 2)
    single = S.sensitivity(
        S.with_parameters(setup, {"striker_velocity_m_s": 0.4, "wall_youngs_pa": 5e9}),
        ("wall_youngs_pa", "striker_velocity_m_s"), observables, grid=result.time_grid,
    )
    for o in observables:
        for p in ("wall_youngs_pa", "striker_velocity_m_s"):
            assert result.derivative[o][p][1, 0] == pytest.approx(float(single.derivative[o][p]), rel=1e-9)
    # Eq. 5: F_end/F_bead ~ (1 + Y_b/Y_w)^(-2/5): its elasticity in Y_w is
    # (2/5) (Y_b/Y_w)/(1 + Y_b/Y_w): large for a soft wall, smaller for a steel one
    e = result.elasticity["force_ratio_4"]["wall_youngs_pa"]
    assert np.all(e > 0) and np.all(e[:, 0] > 2 * e[:, 1])
    assert e[:, 1] == pytest.approx(0.2 * np.ones(2), abs=0.08)
    # without dissipation the ratio is amplitude-free: no dependence on the impact velocity
    assert np.max(np.abs(result.elasticity["force_ratio_4"]["striker_velocity_m_s"])) < 2e-3
    assert result.elasticity["wall_peak"]["striker_velocity_m_s"] == pytest.approx(1.2 * np.ones((2, 2)), abs=2e-3)


@pytest.mark.slow
def test_global_sensitivity_ranks_the_impact_velocity_first():
    setup = hc.ChainSetup(8, striker_velocity_m_s=0.2)
    box = {"striker_velocity_m_s": (0.1, 0.4), "eta_s": (0.0, 2e-6)}
    result = S.global_sensitivity(setup, ("contact_4_peak",), box, n_samples=4, t_end_s=0.5e-3,
                                  sample_interval_s=2e-6, progress=False)
    assert result.ranking["contact_4_peak"] == ["striker_velocity_m_s", "eta_s"]
    samples = result.samples
    point = {p: float(samples.param_values[p][0]) for p in box}
    single = S.sensitivity(S.with_parameters(setup, point), tuple(box), ("contact_4_peak",),
                           grid=samples.time_grid)
    assert float(samples.elasticity["contact_4_peak"]["eta_s"][0]) == pytest.approx(
        float(single.elasticity["contact_4_peak"]["eta_s"]), rel=1e-9)
    # Peaks scale as V0^(6/5) without dissipation; the viscous loss grows with the amplitude,
    # so each sample's elasticity lies a little below 6/5 (1.16-1.20 here).
    mean_square = result.mean_squared_elasticity["contact_4_peak"]["striker_velocity_m_s"]
    assert 1.1**2 < mean_square < 1.2**2
    assert result.mean_abs_elasticity["contact_4_peak"]["striker_velocity_m_s"] <= math.sqrt(mean_square)


@pytest.mark.parametrize(
    ("params", "observables", "setup_kwargs", "match"),
    [
        (("etaa",), ("wall_peak",), {}, "unknown parameter 'etaa' in params; valid parameters: eta_s, mu"),
        (("eta_s",), ("wall_max",), {}, "unknown observable 'wall_max'; valid forms"),
        (("eta_s",), ("contact_12_peak",), {}, "contact 12 is not in the chain"),
        (("eta_s",), ("sensor_2_peak",), {}, "bead 2 has no embedded sensor"),
        (("wall_youngs_pa",), ("wall_peak",), {"wall_youngs_pa": np.inf}, "infinitely stiff wall"),
        (("precompression_n",), ("wall_peak",), {}, "singular at zero preload"),
        (("yield_force_n",), ("wall_peak",), {}, "plasticity=True"),
        (("eta_s",), ("speed_5_2",), {}, "needs K < L"),
    ],
)
def test_bad_names_give_clear_errors(params, observables, setup_kwargs, match):
    setup = hc.ChainSetup(8, **setup_kwargs)
    with pytest.raises(ValueError, match=match):
        S.sensitivity(setup, params, observables, t_end_s=1e-4)


def test_pulse_that_never_arrives_is_an_error():
    setup = hc.ChainSetup(8)
    with pytest.raises(ValueError, match="wall_peak: no complete pulse .* lengthen the record"):
        S.sensitivity(setup, ("eta_s",), ("wall_peak",), t_end_s=0.2e-3, sample_interval_s=2e-6,
                      steps_per_contact=40)


@pytest.mark.slow  # keeps the default suite under 10 min on 2 cores; the sensitivities themselves stay in the default suite
def test_command_line_writes_json_csv_and_plots(tmp_path):
    from hertzchain.cli import main

    out = tmp_path / "sens"
    code = main([
        "sensitivity", "--n-beads", "6", "--eta", "1us", "--mu-star", "0.03",
        "--params", "eta_s,wall_youngs_pa,mu_star", "--observables", "wall_peak,contact_2_peak,trace_wall",
        "--t-end", "0.5ms", "--sample-interval", "2us", "--out", str(out),
    ])
    assert code == 0
    data = json.loads((out / "sensitivity.json").read_text())
    assert set(data["derivative"]) == {"wall_peak", "contact_2_peak", "trace_wall"}
    setup = hc.ChainSetup(6, eta_s=1e-6, mu_star=0.03)
    api = S.sensitivity(setup, ("eta_s", "wall_youngs_pa", "mu_star"), ("wall_peak",), t_end_s=0.5e-3,
                        sample_interval_s=2e-6)
    assert data["derivative"]["wall_peak"]["eta_s"] == pytest.approx(float(api.derivative["wall_peak"]["eta_s"]), rel=1e-9)
    assert data["elasticity"]["wall_peak"]["mu_star"] == pytest.approx(
        float(api.elasticity["wall_peak"]["mu_star"]), rel=1e-9)
    assert (out / "sensitivity.csv").read_text().startswith("observable,")
    assert (out / "elasticities.png").stat().st_size > 0
    assert (out / "trace_sensitivity.csv").exists()
    assert main(["sensitivity", "--n-beads", "6", "--params", "eta_s,foo", "--observables", "wall_peak",
                 "--out", str(out)]) == 2


@pytest.mark.slow
def test_plastic_contacts_and_preload_match_finite_differences():
    """Thornton elastic-plastic contacts above the yield force, and a static preload."""
    setup = hc.ChainSetup(6, plasticity=True, striker_velocity_m_s=1.2, eta_s=0.5e-6,
                          precompression_n=2.0)
    grid = hc.choose_time_grid(setup, t_end_s=0.4e-3, sample_interval_s=1e-6, steps_per_contact=60)
    params = ("yield_force_n", "precompression_n", "eta_s")
    observables = ("wall_peak", "contact_2_peak", "contact_4_arrival", "dissipated_plastic")
    result = S.sensitivity(setup, params, observables, grid=grid)
    assert float(result.values["dissipated_plastic"]) > 0
    fd = _central_differences(setup, params, observables, grid, 1e-6)
    _check_against_fd(result, fd)
    # a higher yield force leaves more of the impact elastic: less plastic loss
    assert result.derivative["dissipated_plastic"]["yield_force_n"] < 0
