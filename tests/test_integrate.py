"""The velocity-Verlet solver against conservation laws, an independent solver, the exact
scaling symmetry of the Hertz chain, finite differences and the paper's qualitative facts."""

import warnings

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import hertzchain as hc
from hertzchain.reference import simulate_reference


def _peak(traces, channel):
    """Peak force and time, refined with a parabola through the 3 samples around the maximum."""
    force = np.asarray(traces.forces_n[channel])
    time = np.asarray(traces.time_s)
    i = int(np.argmax(force))
    left, mid, right = force[i - 1 : i + 2]
    offset = 0.5 * (left - right) / (left - 2 * mid + right)
    step = time[1] - time[0]
    return mid - 0.25 * (left - right) * offset, time[i] + offset * step


def test_dissipationless_energy_conserved_to_1e6(paper_setup):
    run = hc.simulate(paper_setup, t_end_s=2.5e-3, sample_interval_s=1e-6, dt_s=0.05e-6)
    error = np.max(np.abs(np.asarray(run.energy_error_j))) / float(run.initial_energy_j)
    assert error < 1e-6
    # the wall encounter really happened: nearly all energy was in the wall contact once
    assert np.max(np.asarray(run.wall_elastic_j)) / float(run.initial_energy_j) > 0.9


def test_momentum_conserved_until_the_wave_reaches_the_wall(paper_setup):
    run = hc.simulate(paper_setup, t_end_s=2.5e-3, sample_interval_s=1e-6)
    momentum = np.asarray(run.momentum_kg_m_s)
    p0 = float(run.initial_momentum_kg_m_s)
    before = np.asarray(run.wall_impulse_n_s) == 0.0
    assert before.sum() > 500  # the pulse needs ~1 ms to arrive
    assert np.max(np.abs(momentum[before] - p0)) < 1e-13 * p0
    # afterwards the books still balance to round-off against the wall's impulse
    assert np.max(np.abs(np.asarray(run.momentum_balance_error_kg_m_s))) < 1e-13 * p0
    assert momentum[-1] < 0  # the chain was sent back


def test_ledger_balances_with_all_dissipation_on():
    setup = hc.ChainSetup(eta_s=2e-6, mu=0.19, precompression_n=2.0)
    run = hc.simulate(setup, t_end_s=2.5e-3, sample_interval_s=1e-6, dt_s=0.05e-6)
    energy0 = float(run.initial_energy_j)
    assert np.max(np.abs(np.asarray(run.energy_error_j))) < 1e-6 * energy0
    dissipated = np.asarray(run.dissipated_j)
    assert np.all(np.diff(dissipated) >= -1e-15 * energy0)  # energy is lost monotonically
    assert np.asarray(run.dissipated_viscous_j)[-1] > 0.05 * energy0
    assert np.asarray(run.dissipated_friction_j)[-1] > 0
    p0 = float(run.initial_momentum_kg_m_s)
    assert np.max(np.abs(np.asarray(run.momentum_balance_error_kg_m_s))) < 1e-12 * p0


@pytest.mark.parametrize("eta_s", [0.0, 2e-6])
def test_second_order_convergence_in_the_time_step(eta_s):
    setup = hc.ChainSetup(8, eta_s=eta_s, striker_velocity_m_s=0.3)
    options = dict(t_end_s=0.6e-3, sample_interval_s=1.6e-6, contacts=(5,))

    def wall_force(dt):
        return np.asarray(hc.simulate(setup, dt_s=dt, **options).forces_n["wall"])

    reference = wall_force(0.05e-6)
    errors = [np.max(np.abs(wall_force(dt) - reference)) for dt in (1.6e-6, 0.8e-6, 0.4e-6)]
    slopes = np.log2(np.asarray(errors[:-1]) / np.asarray(errors[1:]))
    assert np.all(np.abs(slopes - 2.0) < 0.15), (errors, slopes)


def test_verlet_and_diffrax_agree_on_peaks_and_arrival_times():
    setup = hc.ChainSetup(eta_s=2e-6, wall_youngs_pa=5e9)
    options = dict(t_end_s=2.0e-3, sample_interval_s=0.5e-6, contacts=(3, 10, 18))
    verlet = hc.simulate(setup, dt_s=0.05e-6, **options)
    adaptive = simulate_reference(setup, **options)
    for channel in verlet.channel_names:
        force_v, time_v = _peak(verlet, channel)
        force_a, time_a = _peak(adaptive, channel)
        assert force_v == pytest.approx(force_a, rel=1e-4)
        assert time_v == pytest.approx(time_a, rel=1e-4)
    ledger_v = float(verlet.dissipated_viscous_j[-1])
    assert ledger_v == pytest.approx(float(adaptive.dissipated_viscous_j[-1]), rel=1e-4)


def test_scaling_symmetry_forces_and_times_from_5_to_500_newtons():
    """V0 -> lambda V0 scales forces by lambda^(6/5) and times by lambda^(-1/5) exactly."""
    base = hc.ChainSetup(striker_velocity_m_s=0.3)
    low, high = 0.0165 * 0.55, 0.42  # about 5 N and 500 N solitary waves
    runs = {}
    for v in (low, high):
        scale_t = (v / 0.3) ** -0.2
        setup = eqx.tree_at(lambda s: s.striker_velocity_m_s, base, jnp.asarray(v))
        runs[v] = hc.simulate(
            setup, t_end_s=2.5e-3 * scale_t, sample_interval_s=1e-6 * scale_t,
            dt_s=0.25e-6 * scale_t, contacts=(8, 15), on_yield="ignore",
        )
    lam = high / low
    force_low = np.asarray(runs[low].forces_n["contact_8"])
    force_high = np.asarray(runs[high].forces_n["contact_8"])
    assert force_high.max() > 400 and force_low.max() < 6
    np.testing.assert_allclose(force_high, force_low * lam**1.2, rtol=1e-9, atol=1e-9 * force_high.max())
    ratios = []
    for run in runs.values():
        wall = np.asarray(run.forces_n["wall"]).max()
        incident = np.asarray(run.forces_n["contact_15"]).max()
        kinetic_share = np.asarray(run.kinetic_j)[len(run.time_s) // 4] / float(run.initial_energy_j)
        (_, t8), (f15, t15) = _peak(run, "contact_8"), _peak(run, "contact_15")
        speed = 7 * 2 * 0.013 / (t15 - t8)
        ratios.append((wall / incident, kinetic_share, speed / f15 ** (1 / 6)))
    np.testing.assert_allclose(ratios[0], ratios[1], rtol=1e-6)


def test_viscous_damping_broadens_and_decays_the_pulse_along_the_chain():
    contacts = (4, 10, 16)
    options = dict(t_end_s=1.2e-3, sample_interval_s=0.5e-6, contacts=contacts)
    elastic = hc.simulate(hc.ChainSetup(), **options)
    damped = hc.simulate(hc.ChainSetup(eta_s=2e-6), **options)
    peaks = [np.asarray(damped.forces_n[f"contact_{k}"]).max() for k in contacts]
    assert peaks[0] > peaks[1] > peaks[2]
    assert peaks[2] < 0.75 * peaks[0]

    def fwhm(run, name):
        force = np.asarray(run.forces_n[name])
        first = force[: np.argmax(force) * 2]
        return np.sum(first > 0.5 * first.max()) * 0.5e-6

    def width_times_root6(run, name):  # 2 tau F^(1/6) is amplitude independent without loss
        return fwhm(run, name) * np.asarray(run.forces_n[name]).max() ** (1 / 6)

    broadening = [width_times_root6(damped, f"contact_{k}") / width_times_root6(elastic, f"contact_{k}") for k in contacts]
    assert broadening[2] > broadening[0] > 1.0
    assert broadening[2] > 1.04  # the paper's Fig. 2b: several per cent at these amplitudes


@pytest.mark.slow  # default-suite time on 2 cores; `pytest -m slow` runs it (the batched kernel's tests hold vmap to single runs too)
def test_vmapped_batch_equals_runs_one_by_one():
    setup = hc.ChainSetup(10, eta_s=1e-6)
    velocities, walls = [0.1, 0.4, 1.0], [5e9, np.inf]
    options = dict(t_end_s=0.6e-3, sample_interval_s=1e-6, contacts=(3,), dt_s=0.2e-6, on_yield="ignore")
    batch = hc.simulate_batch(setup, striker_velocity_m_s=velocities, wall_youngs_pa=walls, **options)
    assert batch.forces_n["wall"].shape == (3, 2, 600)
    for i, v in enumerate(velocities):
        for j, y in enumerate(walls):
            single = hc.simulate(
                hc.ChainSetup(10, eta_s=1e-6, striker_velocity_m_s=v, wall_youngs_pa=y), **options
            )
            for name in ("wall", "contact_3"):
                np.testing.assert_allclose(
                    np.asarray(batch.forces_n[name][i, j]), np.asarray(single.forces_n[name]),
                    rtol=1e-12, atol=1e-9,
                )


FIELDS = ("eta_s", "mu", "wall_youngs_pa")


@pytest.mark.slow  # keeps the default suite under 10 min on 2 cores; gradients against finite differences stay in the default suite in test_sensitivity and test_native
def test_gradients_match_central_differences_through_contact_opening():
    """d(loss)/d(eta, mu, Y_w), reverse and forward mode, against central differences.

    8 beads, run through the reflection: contacts open and close, beads leave the wall.
    Stick-slip friction makes the loss piecewise smooth: the steps (1e-6 relative) are small
    enough not to straddle a bead stopping; at 1e-4 they do and the difference drifts.
    """
    setup = hc.ChainSetup(8, striker_velocity_m_s=0.4, eta_s=1.5e-6, mu=0.19, wall_youngs_pa=20e9)
    grid = hc.choose_time_grid(setup, t_end_s=0.9e-3, sample_interval_s=2e-6, dt_s=0.25e-6)

    def loss(values):
        changed = eqx.tree_at(lambda s: tuple(getattr(s, f) for f in FIELDS), setup, tuple(values))
        traces = hc.solve(changed, grid, hc.Recording(contacts=(4,)))
        return jnp.sum(traces.forces_n["wall"] ** 2) + jnp.sum(traces.forces_n["contact_4"] ** 2)

    x = jnp.asarray([1.5e-6, 0.19, 20e9])
    reverse = np.asarray(jax.grad(loss)(x))
    forward = np.asarray(jax.jacfwd(loss)(x))
    loss = jax.jit(loss)
    for i, step in enumerate((1.5e-12, 1.9e-7, 2e4)):
        shift = jnp.zeros(3).at[i].set(step)
        central = (float(loss(x + shift)) - float(loss(x - shift))) / (2 * step)
        assert np.isfinite(reverse[i]) and reverse[i] != 0.0
        assert reverse[i] == pytest.approx(central, rel=1e-4), FIELDS[i]
    np.testing.assert_allclose(forward, reverse, rtol=1e-10)


@pytest.mark.slow
def test_gradient_finite_at_zero_dissipation_and_contact_onset():
    setup = hc.ChainSetup(5, striker_velocity_m_s=0.2)
    grid = hc.choose_time_grid(setup, t_end_s=0.3e-3, sample_interval_s=2e-6)
    params = {"eta_s": jnp.asarray(0.0), "mu": jnp.asarray(0.0), "mu_star": jnp.asarray(0.0)}

    def loss(p):
        changed = eqx.tree_at(lambda s: (s.eta_s, s.mu, s.mu_star), setup, (p["eta_s"], p["mu"], p["mu_star"]))
        return jnp.sum(hc.solve(changed, grid).forces_n["wall"])

    gradient = jax.grad(loss)(params)
    assert all(np.isfinite(float(g)) and float(g) != 0.0 for g in gradient.values())


def test_precompressed_chain_starts_in_equilibrium():
    setup = hc.ChainSetup(12, precompression_n=5.0, striker_velocity_m_s=0.05)
    run = hc.simulate(setup, t_end_s=0.15e-3, sample_interval_s=1e-6, contacts=(11,))
    far = np.asarray(run.forces_n["contact_11"])[:20]  # before the wave arrives
    np.testing.assert_allclose(far, 5.0, rtol=1e-9)
    np.testing.assert_allclose(np.asarray(run.forces_n["wall"])[:20], 5.0, rtol=1e-9)


def test_heterogeneous_chain_and_free_end_conserve_energy_and_momentum():
    radius = np.linspace(0.010, 0.014, 9)
    setup = hc.ChainSetup(
        9, bead_radius_m=radius, bead_mass_kg=np.full(9, 0.05), end="free",
        striker_mass_kg=0.0089, striker_velocity_m_s=0.5,
    )
    striker_volume = 4 / 3 * np.pi * float(setup.striker_radius_m) ** 3
    assert striker_volume * float(setup.bead_density_kg_m3[0]) == pytest.approx(0.0089, rel=1e-12)
    np.testing.assert_allclose(np.asarray(setup.bead_mass_kg), 0.05, rtol=1e-12)
    run = hc.simulate(setup, t_end_s=1.5e-3, sample_interval_s=1e-6, dt_s=0.02e-6, on_yield="ignore")
    p0 = float(run.initial_momentum_kg_m_s)
    np.testing.assert_allclose(np.asarray(run.momentum_kg_m_s), p0, rtol=1e-12)
    assert np.max(np.abs(np.asarray(run.energy_error_j))) < 1e-6 * float(run.initial_energy_j)


def test_plastic_contacts_dissipate_only_above_the_yield_force():
    below = hc.simulate(hc.ChainSetup(8, striker_velocity_m_s=0.2, plasticity=True), t_end_s=0.8e-3)
    assert float(np.max(np.asarray(below.max_force_n) / np.asarray(below.yield_force_n))) < 1
    assert float(below.dissipated_plastic_j[-1]) == 0.0
    above = hc.simulate(
        hc.ChainSetup(8, striker_velocity_m_s=1.0, plasticity=True), t_end_s=0.8e-3, dt_s=0.05e-6
    )  # the striker's collision alone reaches about 3.5 times the yield force
    energy0 = float(above.initial_energy_j)
    assert float(above.dissipated_plastic_j[-1]) > 0.05 * energy0
    assert np.max(np.abs(np.asarray(above.energy_error_j))) < 1e-6 * energy0
    elastic = hc.simulate(hc.ChainSetup(8, striker_velocity_m_s=1.0), t_end_s=0.8e-3, on_yield="ignore")
    assert np.asarray(above.forces_n["wall"]).max() < 0.9 * np.asarray(elastic.forces_n["wall"]).max()


def test_yield_warning_names_the_contact():
    with pytest.warns(hc.YieldWarning, match="contact 0 reached .* above its yield force"):
        hc.simulate(hc.ChainSetup(5, striker_velocity_m_s=1.2), t_end_s=0.3e-3)
    with pytest.raises(ValueError, match="yield force"):
        hc.simulate(hc.ChainSetup(5, striker_velocity_m_s=1.2), t_end_s=0.3e-3, on_yield="raise")


def test_the_reference_solver_takes_the_yield_check_its_warning_advises():
    """`simulate_reference` warns past the yield force as `simulate` does, and takes the
    `on_yield` its warning names: 'ignore' silences it, 'raise' raises, another value is
    refused before the solve."""
    setup = hc.ChainSetup(3, striker_velocity_m_s=1.2)
    with pytest.warns(hc.YieldWarning, match=r"contact 0 reached .* or set on_yield='ignore'"):
        simulate_reference(setup, t_end_s=0.1e-3, sample_interval_s=1e-6, rtol=1e-6)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        simulate_reference(setup, t_end_s=0.1e-3, sample_interval_s=1e-6, rtol=1e-6, on_yield="ignore")
    with pytest.raises(ValueError, match="yield force"):
        simulate_reference(setup, t_end_s=0.1e-3, sample_interval_s=1e-6, rtol=1e-6, on_yield="raise")
    with pytest.raises(ValueError, match="on_yield must be 'warn', 'raise' or 'ignore'"):
        simulate_reference(setup, on_yield="quiet")
